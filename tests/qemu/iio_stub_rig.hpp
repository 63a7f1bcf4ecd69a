// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The rig of the QEMU tests that meet the kernel's inv-mpu6050 driver (tests/qemu/iio_guest.cpp):
// an i2c-stub chip at 0x68 on /dev/i2c-0 whose registers are prepared so that the driver binds
// and reads one frame per interrupt, the client made with an interrupt by imucal-irq-i2c
// (tests/qemu/kmod/), and data-ready pulses raised through that module at the sample rate.

#include <fcntl.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/time.hpp"

namespace imucal::qemu {

inline constexpr const char* kBus = "/dev/i2c-0";
inline constexpr int kAddr = 0x68;
inline constexpr const char* kParams = "/sys/module/imucal_irq_i2c/parameters";
inline constexpr const char* kAdapter = "/sys/bus/i2c/devices/i2c-0";
// The frame the stub returns from FIFO_R_W on: registers 0x74..0x81 (0x75 is WHO_AM_I, 0x68).
inline constexpr std::uint8_t kFrame[14] = {0x01, 0x68, 0xfe, 0x0c, 0x40, 0x00, 0xf0,
                                            0x00, 0x00, 0x7b, 0xff, 0x85, 0x7f, 0xff};

inline std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  std::string s = ss.str();
  while (!s.empty() && (s.back() == '\n' || s.back() == '\0')) s.pop_back();  // some end in a NUL too
  return s;
}

inline bool write_text(const std::string& path, const std::string& value) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::write(fd, value.data(), value.size()) == static_cast<ssize_t>(value.size());
  ::close(fd);
  return ok;
}

// Register writes behind the kernel driver's back (I2C_SLAVE_FORCE: the address is bound).
inline bool poke(std::uint8_t reg, std::uint8_t value) {
  const int fd = ::open(kBus, O_RDWR | O_CLOEXEC);
  if (fd < 0) return false;
  bool ok = ::ioctl(fd, I2C_SLAVE_FORCE, kAddr) == 0;
  if (ok) {
    i2c_smbus_data data{};
    data.byte = value;
    i2c_smbus_ioctl_data args{I2C_SMBUS_WRITE, reg, I2C_SMBUS_BYTE_DATA, &data};
    ok = ::ioctl(fd, I2C_SMBUS, &args) == 0;
  }
  ::close(fd);
  return ok;
}

// Debian's 6.1 inv-mpu6050 (6.1.192) reads the interrupt status from st->reg->int_status, which
// its MPU-6050/6000 register map leaves 0: it reads register 0x00 (XG_OFFS_TC on the chip; bit 0
// is OTP_BNK_VLD) and drops the interrupt's data unless bit 0 is set. The stub sets it, as a chip
// with that OTP bit set reads (docs/mpu6000.md); 0x3A is the real INT_STATUS, for kernels that
// read it.
inline bool prepare_stub() {
  bool ok = poke(0x75, 0x68) && poke(0x00, 0x01) && poke(0x3a, 0x01) && poke(0x72, 0x00) && poke(0x73, 14);
  for (int i = 0; i < 14; ++i)
    if (i != 1) ok = ok && poke(static_cast<std::uint8_t>(0x74 + i), kFrame[i]);
  return ok;
}

inline bool wait_for(const std::string& path, bool present, int ms = 5000) {
  for (int i = 0; i < ms / 10; ++i) {
    if (std::filesystem::exists(path) == present) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

// Data-ready pulses from a thread on an absolute schedule; each write to `fire` is bracketed by
// CLOCK_MONOTONIC reads (the kernel stamps inside it).
class Pulses {
 public:
  explicit Pulses(double rate_hz) : period_ns_(static_cast<TimeNs>(1e9 / rate_hz)) {
    fd_ = ::open((std::string(kParams) + "/fire").c_str(), O_WRONLY | O_CLOEXEC);
  }
  ~Pulses() {
    stop();
    if (fd_ >= 0) ::close(fd_);
  }
  bool ok() const { return fd_ >= 0; }
  void start(int count) {
    stop();
    done_ = false;
    fired_ = 0;
    thread_ = std::thread([this, count] {
      TimeNs next = monotonic_now_ns() + period_ns_;
      for (int i = 0; i < count && !quit_; ++i) {
        timespec ts{static_cast<time_t>(next / 1'000'000'000), static_cast<long>(next % 1'000'000'000)};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
        }
        if (before_pulse) before_pulse(i);
        const TimeNs before = monotonic_now_ns();
        const bool w = ::pwrite(fd_, "1", 1, 0) == 1;
        const TimeNs after = monotonic_now_ns();
        if (w) {
          before_.push_back(before);
          after_.push_back(after);
          ++fired_;
        } else {
          ++failed_;
        }
        next += period_ns_;
      }
      done_ = true;
    });
  }
  void stop() {
    if (thread_.joinable()) {
      quit_ = true;
      thread_.join();
      quit_ = false;
    }
  }
  bool done() const { return done_; }
  /// Pulses raised since start() (readable while they come).
  int fired() const { return fired_; }
  /// Waits until `n` pulses were raised or the sequence ended.
  void wait_fired(int n) const {
    while (fired_ < n && !done_) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  /// Called in the pulse thread before pulse i (0-based) is raised, on its schedule: for register
  /// changes that must fall between two given pulses. Set it before start().
  std::function<void(int)> before_pulse;
  // Read after stop(): the CLOCK_MONOTONIC time before and after each pulse's write.
  std::vector<TimeNs> before_, after_;
  int failed_ = 0;

 private:
  TimeNs period_ns_;
  int fd_ = -1;
  std::thread thread_;
  std::atomic<bool> quit_{false};
  std::atomic<bool> done_{true};
  std::atomic<int> fired_{0};
};

/// Creates (true) or removes (false) the client with the interrupt and waits for iio:device0.
inline bool attach(bool on) {
  if (!write_text(std::string(kParams) + "/attach", on ? "1" : "0")) return false;
  return wait_for("/sys/bus/iio/devices/iio:device0", on);
}

}  // namespace imucal::qemu
