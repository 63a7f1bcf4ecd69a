// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/bus/spidev_bus.hpp"

#include <linux/spi/spidev.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace imucal::drivers {
namespace {

constexpr std::uint8_t kReadFlag = 0x80;
constexpr std::uint32_t kMinSpeedHz = 1'000;

Error open_error(const std::string& path, int err) {
  std::string what = "cannot open SPI device " + path + ": " + std::strerror(err);
  switch (err) {
    case ENOENT:
    case ENODEV:
    case ENXIO:
      return make_error(Errc::kNotFound,
                        what +
                            ". Check that the spidev driver is loaded and bound to this bus and chip "
                            "select (device tree overlay or `modprobe spidev`; `ls /dev/spidev*` lists "
                            "the nodes) and that the rig configuration key imu.device names it.");
    case EACCES:
    case EPERM:
      return make_error(Errc::kIo, what +
                                       ". Run as a user that may open it (the group owning the node, "
                                       "see `ls -l " +
                                       path + "`) or add a udev rule.");
    case EBUSY:
      return make_error(Errc::kIo, what + ". Another process holds the device; stop it first.");
    default:
      return make_error(Errc::kIo, what);
  }
}

}  // namespace

Result<std::unique_ptr<SpidevBus>> SpidevBus::open(const std::string& device, const SpidevOptions& options,
                                                   std::unique_ptr<DeviceIo> io) {
  if (device.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no SPI device given; set imu.device in the rig configuration (e.g. "
                      "/dev/spidev0.0)");
  }
  if (options.config_speed_hz < kMinSpeedHz || options.max_speed_hz < options.config_speed_hz) {
    return make_error(Errc::kInvalidArgument,
                      "SPI clocks out of range: config_speed_hz=" + std::to_string(options.config_speed_hz) +
                          ", max_speed_hz=" + std::to_string(options.max_speed_hz) +
                          " (need 1 kHz <= config <= max; the MPU-6000 allows 1 MHz and 20 MHz)");
  }
  std::unique_ptr<SpidevBus> bus(new SpidevBus(device, options, std::move(io)));
  IMUCAL_TRY(bus->open_and_configure());
  return bus;
}

SpidevBus::SpidevBus(std::string path, const SpidevOptions& options, std::unique_ptr<DeviceIo> io)
    : file_(std::move(path), std::move(io)),
      name_(file_.node_name()),
      options_(options),
      speed_hz_(options.config_speed_hz) {}

SpidevBus::~SpidevBus() = default;

Status SpidevBus::open_and_configure() {
  if (int err = file_.open(); err < 0) {
    ++counters_.open_errors;
    return open_error(file_.path(), -err);
  }

  auto config_error = [&](const char* what, int r) -> Error {
    ++counters_.open_errors;
    file_.close();
    std::string msg = file_.path() + ": " + what + " failed: " + std::strerror(-r);
    if (-r == ENOTTY || -r == EINVAL) {
      msg +=
          ". This node is not a spidev device, or its controller does not support SPI mode 3 "
          "with 8-bit words; check the rig configuration key imu.device.";
    }
    return make_error(Errc::kDevice, msg);
  };

  // MPU-6000: CPOL=1, CPHA=1 (mode 3), MSB first, 8-bit words.
  std::uint8_t mode = SPI_MODE_3;
  if (int r = file_.ioctl(SPI_IOC_WR_MODE, &mode); r < 0) return config_error("SPI_IOC_WR_MODE", r);
  std::uint8_t mode_back = 0;
  if (int r = file_.ioctl(SPI_IOC_RD_MODE, &mode_back); r < 0) return config_error("SPI_IOC_RD_MODE", r);
  if ((mode_back & (SPI_CPHA | SPI_CPOL)) != SPI_MODE_3) {
    ++counters_.open_errors;
    file_.close();
    return make_error(Errc::kDevice, file_.path() + ": the controller kept SPI mode " +
                                         std::to_string(mode_back & 3) +
                                         " instead of mode 3; the MPU-6000 needs mode 3");
  }
  std::uint8_t bits = 8;
  if (int r = file_.ioctl(SPI_IOC_WR_BITS_PER_WORD, &bits); r < 0) {
    return config_error("SPI_IOC_WR_BITS_PER_WORD", r);
  }
  // The device default clock; every transfer still names its own.
  std::uint32_t max_hz = options_.max_speed_hz;
  if (int r = file_.ioctl(SPI_IOC_WR_MAX_SPEED_HZ, &max_hz); r < 0) {
    return config_error("SPI_IOC_WR_MAX_SPEED_HZ", r);
  }
  return {};
}

Status SpidevBus::reopen() {
  file_.close();
  return open_and_configure();
}

void SpidevBus::set_speed_hz(std::uint32_t hz) {
  speed_hz_ = hz == 0 ? options_.config_speed_hz : std::clamp(hz, kMinSpeedHz, options_.max_speed_hz);
}

Status SpidevBus::read(std::uint8_t reg, std::span<std::uint8_t> out) {
  if (out.empty()) return {};
  const std::size_t len = out.size() + 1;
  if (len > kMaxTransferBytes) {
    return make_error(Errc::kInvalidArgument, name_ + ": read of " + std::to_string(out.size()) +
                                                  " bytes exceeds one spidev transfer (" +
                                                  std::to_string(kMaxTransferBytes - 1) + " bytes)");
  }
  tx_.assign(len, 0);
  tx_[0] = static_cast<std::uint8_t>(reg | kReadFlag);
  IMUCAL_TRY(transfer(reg, len, speed_hz_));
  std::copy(rx_.begin() + 1, rx_.begin() + static_cast<std::ptrdiff_t>(len), out.begin());
  return {};
}

Status SpidevBus::write(std::uint8_t reg, std::uint8_t value) {
  tx_.assign({static_cast<std::uint8_t>(reg & ~kReadFlag), value});
  return transfer(reg, 2, std::min(speed_hz_, options_.config_speed_hz));
}

Status SpidevBus::transfer(std::uint8_t reg, std::size_t len, std::uint32_t speed_hz) {
  if (!file_.is_open()) {
    ++counters_.transfer_errors;
    return make_error(Errc::kIo, name_ + ": device is closed after a failed reopen; reopen() it");
  }
  rx_.assign(len, 0);
  spi_ioc_transfer xfer{};
  xfer.tx_buf = reinterpret_cast<std::uintptr_t>(tx_.data());
  xfer.rx_buf = reinterpret_cast<std::uintptr_t>(rx_.data());
  xfer.len = static_cast<std::uint32_t>(len);
  xfer.speed_hz = speed_hz;
  xfer.bits_per_word = 8;
  ++counters_.transfers;
  int r = file_.ioctl(SPI_IOC_MESSAGE(1), &xfer);
  if (r < 0) {
    ++counters_.transfer_errors;
    std::string msg = name_ + ": SPI transfer of " + std::to_string(len) + " bytes at register " +
                      format_hex(reg, 2) + " (" + std::to_string(speed_hz) +
                      " Hz) failed: " + std::strerror(-r);
    if (-r == EMSGSIZE) msg += " (larger than the spidev buffer, module parameter spidev.bufsiz)";
    return make_error(Errc::kIo, msg);
  }
  if (static_cast<std::size_t>(r) != len) {
    ++counters_.short_transfers;
    return make_error(Errc::kDevice, name_ + ": short SPI transfer at register " + format_hex(reg, 2) + ": " +
                                         std::to_string(r) + " of " + std::to_string(len) + " bytes");
  }
  return {};
}

}  // namespace imucal::drivers
