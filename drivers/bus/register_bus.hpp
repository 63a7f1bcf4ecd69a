// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Register access to a sensor, independent of the bus. Implementations: SpidevBus, I2cDevBus
// (real devices), and the MPU-6000 emulator in drivers/sim. Errors are values, never exceptions.

#include <cstdint>
#include <span>
#include <string>

#include "core/result.hpp"

namespace imucal::drivers {

/// Failure counters per cause, shown in status output.
struct BusCounters {
  std::uint64_t transfers = 0;
  std::uint64_t transfer_errors = 0;  // ioctl/read failed
  std::uint64_t timeouts = 0;
  std::uint64_t open_errors = 0;      // the device node could not be opened or configured
  std::uint64_t short_transfers = 0;  // the kernel moved fewer bytes than asked
};

class RegisterBus {
 public:
  virtual ~RegisterBus() = default;

  /// Reads `out.size()` bytes starting at `reg` (burst, auto-increment; FIFO_R_W reads the FIFO).
  [[nodiscard]] virtual Status read(std::uint8_t reg, std::span<std::uint8_t> out) = 0;
  /// Writes one register.
  [[nodiscard]] virtual Status write(std::uint8_t reg, std::uint8_t value) = 0;

  /// Bus clock for the next transfers: slow for configuration, fast for sensor/FIFO reads (SPI).
  /// Buses without a per-transfer clock ignore it.
  virtual void set_speed_hz(std::uint32_t hz) { (void)hz; }

  /// Human-readable name: "spidev0.0", "i2c-1@0x68", "sim".
  virtual std::string name() const = 0;
  virtual const BusCounters& counters() const = 0;

  [[nodiscard]] Result<std::uint8_t> read_u8(std::uint8_t reg) {
    std::uint8_t v = 0;
    auto s = read(reg, std::span<std::uint8_t>(&v, 1));
    if (!s.ok()) return s.error();
    return v;
  }
};

}  // namespace imucal::drivers
