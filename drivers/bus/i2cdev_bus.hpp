// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The MPU-6000 on a Linux i2c-dev node (/dev/i2c-N) at address 0x68 (AD0 low) or 0x69 (AD0 high).
//
// Two transfer modes, chosen at open from the adapter's I2C_FUNCS:
//  - I2C_RDWR (adapter has I2C_FUNC_I2C, the normal case for SoC controllers): a read is one
//    combined transaction, write(register) + repeated start + read(n), so a burst of any length
//    (FIFO included) is atomic;
//  - SMBus (adapter is SMBus-only, e.g. PC SMBus controllers and the kernel's i2c-stub): reads
//    are "I2C block read" transactions of at most 32 bytes each, writes are "write byte data".
//    A longer burst is split; the continuation starts at reg + offset, except for the FIFO
//    register, whose reads do not advance the address. A split burst is not atomic, so the
//    sensor block (14 bytes) must not be split - it is not, it fits one transaction.
// Errors are values; failures are counted per cause in counters(). Not thread-safe.

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "core/result.hpp"
#include "drivers/bus/device_io.hpp"
#include "drivers/bus/register_bus.hpp"

namespace imucal::drivers {

enum class I2cTransferMode {
  kAuto,     // I2C_RDWR when the adapter can, else SMBus
  kI2cRdwr,  // require I2C_RDWR combined transactions
  kSmbus,    // require SMBus transactions
};

const char* i2c_transfer_mode_name(I2cTransferMode mode);

struct I2cDevOptions {
  std::uint8_t address = 0x68;
  I2cTransferMode mode = I2cTransferMode::kAuto;
  /// Register whose reads do not advance the address (MPU-6000 FIFO_R_W).
  std::uint8_t fifo_register = 0x74;
};

class I2cDevBus final : public RegisterBus {
 public:
  /// Bytes per SMBus I2C-block transaction (I2C_SMBUS_BLOCK_MAX).
  static constexpr std::size_t kSmbusBlockBytes = 32;
  /// Bytes per I2C_RDWR message accepted by i2c-dev.
  static constexpr std::size_t kMaxRdwrBytes = 8192;

  /// Opens `device` ("/dev/i2c-1" or "i2c-1"), checks the adapter's functionality and claims
  /// the address. A missing device, missing permissions, an adapter that cannot serve the
  /// MPU-6000 or an address held by a kernel driver give an error that says what to check.
  /// `io` makes the system calls (system_device_io() when null): open(2), close(2) and the
  /// ioctls I2C_FUNCS, I2C_SLAVE, I2C_RDWR and I2C_SMBUS.
  [[nodiscard]] static Result<std::unique_ptr<I2cDevBus>> open(const std::string& device,
                                                               const I2cDevOptions& options = {},
                                                               std::unique_ptr<DeviceIo> io = nullptr);
  ~I2cDevBus() override;
  I2cDevBus(const I2cDevBus&) = delete;
  I2cDevBus& operator=(const I2cDevBus&) = delete;

  [[nodiscard]] Status read(std::uint8_t reg, std::span<std::uint8_t> out) override;
  [[nodiscard]] Status write(std::uint8_t reg, std::uint8_t value) override;

  /// Closes the device and opens it again (recovery after repeated transfer errors).
  [[nodiscard]] Status reopen();

  /// The mode in use (never kAuto once open).
  I2cTransferMode mode() const { return mode_; }
  /// The adapter's I2C_FUNCS bits.
  unsigned long functionality() const { return funcs_; }

  std::string name() const override { return name_; }
  const std::string& path() const { return file_.path(); }
  const BusCounters& counters() const override { return counters_; }

 private:
  I2cDevBus(std::string path, const I2cDevOptions& options, std::unique_ptr<DeviceIo> io);
  [[nodiscard]] Status open_and_check();
  [[nodiscard]] Status read_rdwr(std::uint8_t reg, std::span<std::uint8_t> out);
  [[nodiscard]] Status read_smbus(std::uint8_t reg, std::span<std::uint8_t> out);
  [[nodiscard]] Error transfer_error(const char* what, std::uint8_t reg, int r);

  DeviceFile file_;
  std::string name_;
  I2cDevOptions options_;
  unsigned long funcs_ = 0;
  I2cTransferMode mode_ = I2cTransferMode::kAuto;
  BusCounters counters_;
};

}  // namespace imucal::drivers
