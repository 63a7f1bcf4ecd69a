// SPDX-License-Identifier: BSD-3-Clause
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

DeviceFile::DeviceFile(std::string path, std::unique_ptr<DeviceIo> io)
    : path_(path.empty() || path.front() == '/' ? std::move(path) : "/dev/" + path),
      io_(io ? std::move(io) : system_device_io()) {}

int DeviceFile::open() {
  close();
  const int fd = io_->open(path_);
  if (fd < 0) return fd;
  fd_ = fd;
  return 0;
}

void DeviceFile::close() {
  if (fd_ >= 0) io_->close(fd_);
  fd_ = -1;
}

int DeviceFile::ioctl(unsigned long request, void* arg) {
  return fd_ < 0 ? -EBADF : io_->ioctl(fd_, request, arg);
}

std::string DeviceFile::node_name() const {
  const auto slash = path_.find_last_of('/');
  return slash == std::string::npos ? path_ : path_.substr(slash + 1);
}

}  // namespace imucal::drivers
