// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The MPU-6000 on a Linux spidev node (/dev/spidevB.C): SPI mode 3, 8-bit words, MSB first.
// A read sends the register address with bit 7 set (reg | 0x80) and clocks out the data in the
// same full-duplex transfer; a write sends (reg & 0x7F, value). Every transfer carries its own
// clock (spi_ioc_transfer.speed_hz): register writes never exceed the configuration clock
// (the MPU-6000 product specification allows 1 MHz "for communicating with all registers"),
// reads use the clock chosen with set_speed_hz(), up to 20 MHz (allowed "for reading sensor
// and interrupt registers", which includes FIFO_R_W).
//
// Errors are values; failures are counted per cause in counters(). Not thread-safe: one owner
// (the driver's thread) uses the bus.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "drivers/bus/device_io.hpp"
#include "drivers/bus/register_bus.hpp"

namespace imucal::drivers {

struct SpidevOptions {
  /// Clock for register writes and for reads until set_speed_hz() is called.
  std::uint32_t config_speed_hz = 1'000'000;
  /// Highest clock set_speed_hz() accepts (sensor and FIFO reads).
  std::uint32_t max_speed_hz = 20'000'000;
};

class SpidevBus final : public RegisterBus {
 public:
  /// Largest transfer spidev accepts by default (module parameter spidev.bufsiz = 4096),
  /// including the address byte.
  static constexpr std::size_t kMaxTransferBytes = 4096;

  /// Opens and configures `device` ("/dev/spidev0.0" or "spidev0.0"). A missing device,
  /// missing permissions or a node that is not spidev give an error that says what to check.
  /// `io` makes the system calls (system_device_io() when null): open(2), close(2) and the
  /// ioctls SPI_IOC_WR_MODE, SPI_IOC_RD_MODE, SPI_IOC_WR_BITS_PER_WORD, SPI_IOC_WR_MAX_SPEED_HZ
  /// and SPI_IOC_MESSAGE(1).
  [[nodiscard]] static Result<std::unique_ptr<SpidevBus>> open(const std::string& device,
                                                               const SpidevOptions& options = {},
                                                               std::unique_ptr<DeviceIo> io = nullptr);
  ~SpidevBus() override;
  SpidevBus(const SpidevBus&) = delete;
  SpidevBus& operator=(const SpidevBus&) = delete;

  [[nodiscard]] Status read(std::uint8_t reg, std::span<std::uint8_t> out) override;
  [[nodiscard]] Status write(std::uint8_t reg, std::uint8_t value) override;

  /// Clock for the following reads, clamped to [1 kHz, max_speed_hz]; 0 restores the
  /// configuration clock. Writes always use min(this, config_speed_hz).
  void set_speed_hz(std::uint32_t hz) override;
  std::uint32_t speed_hz() const { return speed_hz_; }

  /// Closes the device and opens it again (recovery after repeated transfer errors).
  [[nodiscard]] Status reopen();

  std::string name() const override { return name_; }
  const std::string& path() const { return file_.path(); }
  const BusCounters& counters() const override { return counters_; }

 private:
  SpidevBus(std::string path, const SpidevOptions& options, std::unique_ptr<DeviceIo> io);
  [[nodiscard]] Status open_and_configure();
  [[nodiscard]] Status transfer(std::uint8_t reg, std::size_t len, std::uint32_t speed_hz);

  DeviceFile file_;
  std::string name_;
  SpidevOptions options_;
  std::uint32_t speed_hz_ = 0;
  BusCounters counters_;
  std::vector<std::uint8_t> tx_;
  std::vector<std::uint8_t> rx_;
};

}  // namespace imucal::drivers
