#include "drivers/bus/device_io.hpp"

#include <fcntl.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>

namespace imucal::drivers {
namespace {

class SystemDeviceIo final : public DeviceIo {
 public:
  int open(const std::string& path) override {
    int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
    return fd < 0 ? -errno : fd;
  }
  void close(int fd) override { ::close(fd); }
  int ioctl(int fd, unsigned long request, void* arg) override {
    int r = ::ioctl(fd, request, arg);
    return r < 0 ? -errno : r;
  }
};

}  // namespace

std::unique_ptr<DeviceIo> system_device_io() { return std::make_unique<SystemDeviceIo>(); }

std::string format_hex(unsigned long value, int digits) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "0x%0*lX", digits, value);
  return buf;
}

}  // namespace imucal::drivers
