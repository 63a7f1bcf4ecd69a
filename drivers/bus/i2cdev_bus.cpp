// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/bus/i2cdev_bus.hpp"

#include <linux/i2c-dev.h>
#include <linux/i2c.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace imucal::drivers {
namespace {

constexpr unsigned long kSmbusNeeded = I2C_FUNC_SMBUS_READ_I2C_BLOCK | I2C_FUNC_SMBUS_WRITE_BYTE_DATA;

Error open_error(const std::string& path, int err) {
  std::string what = "cannot open I2C device " + path + ": " + std::strerror(err);
  switch (err) {
    case ENOENT:
    case ENODEV:
    case ENXIO:
      return make_error(Errc::kNotFound,
                        what +
                            ". Check that the i2c-dev driver is loaded (`modprobe i2c-dev`), that the bus "
                            "exists (`ls /dev/i2c-*`, `i2cdetect -l`) and that the rig configuration key "
                            "imu.device names it.");
    case EACCES:
    case EPERM:
      return make_error(Errc::kIo, what +
                                       ". Run as a user that may open it (usually the group i2c, see "
                                       "`ls -l " +
                                       path + "`) or add a udev rule.");
    default:
      return make_error(Errc::kIo, what);
  }
}

}  // namespace

const char* i2c_transfer_mode_name(I2cTransferMode mode) {
  switch (mode) {
    case I2cTransferMode::kAuto:
      return "auto";
    case I2cTransferMode::kI2cRdwr:
      return "i2c-rdwr";
    case I2cTransferMode::kSmbus:
      return "smbus";
  }
  return "?";
}

Result<std::unique_ptr<I2cDevBus>> I2cDevBus::open(const std::string& device, const I2cDevOptions& options,
                                                   std::unique_ptr<DeviceIo> io) {
  if (device.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no I2C device given; set imu.device in the rig configuration (e.g. /dev/i2c-1)");
  }
  if (options.address != 0x68 && options.address != 0x69) {
    return make_error(Errc::kInvalidArgument,
                      "I2C address " + format_hex(options.address, 2) +
                          " is not an MPU-6000 address: it answers at 0x68 (AD0 low) or 0x69 (AD0 high); "
                          "check imu.i2c_address in the rig configuration");
  }
  std::unique_ptr<I2cDevBus> bus(new I2cDevBus(device, options, std::move(io)));
  IMUCAL_TRY(bus->open_and_check());
  return bus;
}

I2cDevBus::I2cDevBus(std::string path, const I2cDevOptions& options, std::unique_ptr<DeviceIo> io)
    : file_(std::move(path), std::move(io)),
      name_(file_.node_name() + "@" + format_hex(options.address, 2)),
      options_(options) {}

I2cDevBus::~I2cDevBus() = default;

Status I2cDevBus::open_and_check() {
  if (int err = file_.open(); err < 0) {
    ++counters_.open_errors;
    return open_error(file_.path(), -err);
  }
  auto fail = [&](Errc code, std::string msg) -> Error {
    ++counters_.open_errors;
    file_.close();
    return make_error(code, std::move(msg));
  };

  unsigned long funcs = 0;
  if (int r = file_.ioctl(I2C_FUNCS, &funcs); r < 0) {
    return fail(Errc::kDevice, file_.path() + ": I2C_FUNCS failed: " + std::strerror(-r) +
                                   ". This node is not an i2c-dev adapter; check the rig configuration key "
                                   "imu.device.");
  }
  funcs_ = funcs;
  const bool can_rdwr = (funcs & I2C_FUNC_I2C) != 0;
  const bool can_smbus = (funcs & kSmbusNeeded) == kSmbusNeeded;
  switch (options_.mode) {
    case I2cTransferMode::kAuto:
      if (!can_rdwr && !can_smbus) {
        return fail(Errc::kUnsupported,
                    file_.path() +
                        ": the adapter supports neither plain I2C transfers (I2C_FUNC_I2C) nor SMBus "
                        "I2C-block reads with byte writes (functionality " +
                        format_hex(funcs, 8) + "); the MPU-6000 needs one of them. Use another I2C bus.");
      }
      mode_ = can_rdwr ? I2cTransferMode::kI2cRdwr : I2cTransferMode::kSmbus;
      break;
    case I2cTransferMode::kI2cRdwr:
      if (!can_rdwr) {
        return fail(Errc::kUnsupported, file_.path() +
                                            ": the adapter cannot do plain I2C transfers (I2C_RDWR; "
                                            "functionality " +
                                            format_hex(funcs, 8) +
                                            "), it is SMBus-only; use the SMBus or auto transfer mode.");
      }
      mode_ = options_.mode;
      break;
    case I2cTransferMode::kSmbus:
      if (!can_smbus) {
        return fail(Errc::kUnsupported, file_.path() +
                                            ": the adapter lacks SMBus I2C-block reads or byte writes "
                                            "(functionality " +
                                            format_hex(funcs, 8) +
                                            "); use the I2C_RDWR or auto transfer mode.");
      }
      mode_ = options_.mode;
      break;
  }

  // I2C_SLAVE (not _FORCE) fails with EBUSY when a kernel driver owns the address, which would
  // otherwise fight us for the chip.
  if (int r = file_.ioctl(I2C_SLAVE, reinterpret_cast<void*>(static_cast<unsigned long>(options_.address)));
      r < 0) {
    std::string msg =
        file_.path() + ": cannot use address " + format_hex(options_.address, 2) + ": " + std::strerror(-r);
    if (-r == EBUSY) {
      msg +=
          ". A kernel driver (likely inv-mpu6050) is bound to it: read the chip through it with "
          "imu.driver: iio (or auto), or unbind it (see /sys/bus/i2c/devices/*/driver).";
    }
    return fail(Errc::kDevice, msg);
  }
  return {};
}

Status I2cDevBus::reopen() {
  file_.close();
  return open_and_check();
}

Error I2cDevBus::transfer_error(const char* what, std::uint8_t reg, int r) {
  ++counters_.transfer_errors;
  if (-r == ETIMEDOUT) ++counters_.timeouts;
  std::string msg =
      name_ + ": " + what + " at register " + format_hex(reg, 2) + " failed: " + std::strerror(-r);
  if (-r == ENXIO || -r == EREMOTEIO || -r == EIO || -r == ENODEV) {
    msg += " (no acknowledge: check wiring, power and the AD0 level: 0x68 low, 0x69 high)";
  }
  return make_error(-r == ETIMEDOUT ? Errc::kTimeout : Errc::kIo, msg);
}

Status I2cDevBus::read(std::uint8_t reg, std::span<std::uint8_t> out) {
  if (out.empty()) return {};
  if (!file_.is_open()) {
    ++counters_.transfer_errors;
    return make_error(Errc::kIo, name_ + ": device is closed after a failed reopen; reopen() it");
  }
  return mode_ == I2cTransferMode::kI2cRdwr ? read_rdwr(reg, out) : read_smbus(reg, out);
}

Status I2cDevBus::read_rdwr(std::uint8_t reg, std::span<std::uint8_t> out) {
  if (out.size() > kMaxRdwrBytes) {
    return make_error(Errc::kInvalidArgument, name_ + ": read of " + std::to_string(out.size()) +
                                                  " bytes exceeds one I2C_RDWR message (" +
                                                  std::to_string(kMaxRdwrBytes) + " bytes)");
  }
  std::uint8_t reg_byte = reg;
  i2c_msg msgs[2]{};
  msgs[0].addr = options_.address;
  msgs[0].flags = 0;
  msgs[0].len = 1;
  msgs[0].buf = &reg_byte;
  msgs[1].addr = options_.address;
  msgs[1].flags = I2C_M_RD;
  msgs[1].len = static_cast<std::uint16_t>(out.size());
  msgs[1].buf = out.data();
  i2c_rdwr_ioctl_data data{msgs, 2};
  ++counters_.transfers;
  int r = file_.ioctl(I2C_RDWR, &data);
  if (r < 0) return transfer_error("I2C_RDWR read", reg, r);
  if (r != 2) {
    ++counters_.short_transfers;
    return make_error(Errc::kDevice, name_ + ": short I2C_RDWR read at register " + format_hex(reg, 2) +
                                         ": " + std::to_string(r) + " of 2 messages");
  }
  return {};
}

Status I2cDevBus::read_smbus(std::uint8_t reg, std::span<std::uint8_t> out) {
  const bool fifo = reg == options_.fifo_register;
  if (!fifo && static_cast<std::size_t>(reg) + out.size() > 0x100) {
    return make_error(Errc::kInvalidArgument, name_ + ": read of " + std::to_string(out.size()) +
                                                  " bytes from register " + format_hex(reg, 2) +
                                                  " runs past register 0xFF");
  }
  std::size_t done = 0;
  while (done < out.size()) {
    const std::size_t n = std::min(kSmbusBlockBytes, out.size() - done);
    const auto chunk_reg = static_cast<std::uint8_t>(fifo ? reg : reg + done);
    i2c_smbus_data block{};
    block.block[0] = static_cast<std::uint8_t>(n);
    i2c_smbus_ioctl_data args{};
    args.read_write = I2C_SMBUS_READ;
    args.command = chunk_reg;
    args.size = I2C_SMBUS_I2C_BLOCK_DATA;
    args.data = &block;
    ++counters_.transfers;
    int r = file_.ioctl(I2C_SMBUS, &args);
    if (r < 0) return transfer_error("SMBus I2C-block read", chunk_reg, r);
    if (block.block[0] != n) {
      ++counters_.short_transfers;
      return make_error(Errc::kDevice, name_ + ": short SMBus block read at register " +
                                           format_hex(chunk_reg, 2) + ": " + std::to_string(block.block[0]) +
                                           " of " + std::to_string(n) + " bytes");
    }
    std::copy_n(block.block + 1, n, out.begin() + static_cast<std::ptrdiff_t>(done));
    done += n;
  }
  return {};
}

Status I2cDevBus::write(std::uint8_t reg, std::uint8_t value) {
  if (!file_.is_open()) {
    ++counters_.transfer_errors;
    return make_error(Errc::kIo, name_ + ": device is closed after a failed reopen; reopen() it");
  }
  ++counters_.transfers;
  if (mode_ == I2cTransferMode::kI2cRdwr) {
    std::uint8_t buf[2] = {reg, value};
    i2c_msg msg{};
    msg.addr = options_.address;
    msg.flags = 0;
    msg.len = 2;
    msg.buf = buf;
    i2c_rdwr_ioctl_data data{&msg, 1};
    int r = file_.ioctl(I2C_RDWR, &data);
    if (r < 0) return transfer_error("I2C_RDWR write", reg, r);
    if (r != 1) {
      ++counters_.short_transfers;
      return make_error(Errc::kDevice, name_ + ": short I2C_RDWR write at register " + format_hex(reg, 2));
    }
    return {};
  }
  i2c_smbus_data byte{};
  byte.byte = value;
  i2c_smbus_ioctl_data args{};
  args.read_write = I2C_SMBUS_WRITE;
  args.command = reg;
  args.size = I2C_SMBUS_BYTE_DATA;
  args.data = &byte;
  int r = file_.ioctl(I2C_SMBUS, &args);
  if (r < 0) return transfer_error("SMBus byte write", reg, r);
  return {};
}

}  // namespace imucal::drivers
