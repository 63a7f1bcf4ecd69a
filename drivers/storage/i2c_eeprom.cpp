// SPDX-License-Identifier: BSD-3-Clause
// The i2c-eeprom backend of storage_device.hpp: a 24Cxx EEPROM through i2c-dev.

#include <linux/i2c-dev.h>
#include <linux/i2c.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <thread>

#include "drivers/storage/storage_device.hpp"

namespace imucal::drivers {
namespace {

// A chip busy with its write cycle does not acknowledge its address: the adapter reports one of
// these (i2c-designware ENXIO/EREMOTEIO, others EIO or EAGAIN).
bool is_nack(int err) {
  return err == ENXIO || err == EREMOTEIO || err == EIO || err == EAGAIN || err == ETIMEDOUT;
}

class I2cEepromStorage final : public StorageDevice {
 public:
  I2cEepromStorage(const std::string& device, const I2cEepromOptions& o, std::unique_ptr<DeviceIo> io)
      : file_(device, std::move(io)),
        o_(o),
        name_("i2c-eeprom " + file_.path() + "@" + format_hex(o.address, 2)) {}

  Status open() {
    if (int err = file_.open(); err < 0) return open_error(-err);
    unsigned long funcs = 0;
    if (int r = file_.ioctl(I2C_FUNCS, &funcs); r < 0) {
      return make_error(Errc::kDevice, name_ + ": I2C_FUNCS failed: " + std::strerror(-r) +
                                           ". This node is not an i2c-dev adapter; check storage.i2c_device");
    }
    rdwr_ = (funcs & I2C_FUNC_I2C) != 0;
    quick_ = (funcs & I2C_FUNC_SMBUS_QUICK) != 0;
    const unsigned long smbus_needed = I2C_FUNC_SMBUS_READ_I2C_BLOCK | I2C_FUNC_SMBUS_WRITE_I2C_BLOCK;
    if (!rdwr_ && (o_.address_bytes != 1 || (funcs & smbus_needed) != smbus_needed)) {
      return make_error(Errc::kDevice,
                        name_ + ": the adapter can only do SMBus transfers (functionality " +
                            format_hex(funcs, 8) +
                            "), which serve 1-byte-addressed EEPROMs (24c01..24c16) with I2C-block reads and "
                            "writes; this configuration needs " +
                            (o_.address_bytes != 1 ? std::string("2-byte addressing")
                                                   : std::string("I2C-block transfers the adapter lacks")) +
                            ". Use the nvmem backend (at24) or another bus");
    }
    // I2C_SLAVE (not _FORCE) fails with EBUSY when a kernel driver owns the address: at24 would
    // otherwise write the same chip behind our back.
    return select(o_.address);
  }

  std::uint64_t size() const override { return o_.size_bytes; }
  std::string name() const override { return name_; }
  Status sync() override { return {}; }  // every write waited for the chip's write cycle

  Status read(std::uint64_t offset, std::span<std::uint8_t> out) override {
    IMUCAL_TRY(check_range(name_, o_.size_bytes, offset, out.size()));
    std::size_t done = 0;
    while (done < out.size()) {
      const std::uint64_t at = offset + done;
      std::size_t n = std::min<std::size_t>(out.size() - done, rdwr_ ? 8192 : I2C_SMBUS_BLOCK_MAX);
      if (o_.address_bytes == 1) n = std::min<std::size_t>(n, 256 - at % 256);  // stay in one block
      IMUCAL_TRY(rdwr_ ? read_rdwr(at, out.subspan(done, n)) : read_smbus(at, out.subspan(done, n)));
      done += n;
    }
    return {};
  }

  Status write(std::uint64_t offset, std::span<const std::uint8_t> data) override {
    IMUCAL_TRY(check_range(name_, o_.size_bytes, offset, data.size()));
    std::size_t done = 0;
    while (done < data.size()) {
      const std::uint64_t at = offset + done;
      // Never across a page: the chip's address counter wraps inside the page and would
      // overwrite the page's start.
      std::size_t n = std::min<std::size_t>(data.size() - done, o_.page_bytes - at % o_.page_bytes);
      if (!rdwr_) n = std::min<std::size_t>(n, I2C_SMBUS_BLOCK_MAX);
      IMUCAL_TRY(rdwr_ ? write_rdwr(at, data.subspan(done, n)) : write_smbus(at, data.subspan(done, n)));
      IMUCAL_TRY(wait_ready(chip_address(at)));
      done += n;
    }
    return {};
  }

 private:
  std::uint16_t chip_address(std::uint64_t at) const {
    return static_cast<std::uint16_t>(o_.address_bytes == 1 ? o_.address + (at >> 8) : o_.address);
  }

  std::size_t word_address(std::uint64_t at, std::uint8_t* out) const {
    if (o_.address_bytes == 1) {
      out[0] = static_cast<std::uint8_t>(at);
      return 1;
    }
    out[0] = static_cast<std::uint8_t>(at >> 8);
    out[1] = static_cast<std::uint8_t>(at);
    return 2;
  }

  Error open_error(int err) const {
    std::string msg = "cannot open " + file_.path() + ": " + std::strerror(err);
    if (err == ENOENT || err == ENODEV || err == ENXIO) {
      msg +=
          ". Check that i2c-dev is loaded (`modprobe i2c-dev`), that the bus exists (`i2cdetect -l`) and "
          "storage.i2c_device";
    } else if (err == EACCES || err == EPERM) {
      msg += ". Run as a user that may open it (usually the group i2c, see `ls -l " + file_.path() + "`)";
    }
    return make_error(Errc::kDevice, msg);
  }

  Error transfer_error(const char* what, std::uint64_t at, int err) const {
    std::string msg =
        name_ + ": " + what + " at byte " + std::to_string(at) + " failed: " + std::strerror(err);
    if (is_nack(err))
      msg += " (no acknowledge: check the EEPROM's wiring, power, address pins and storage.i2c_address)";
    return make_error(err == ETIMEDOUT ? Errc::kTimeout : Errc::kDevice, msg);
  }

  Status select(std::uint16_t address) {
    if (address == selected_) return {};
    if (int r = file_.ioctl(I2C_SLAVE, reinterpret_cast<void*>(static_cast<unsigned long>(address))); r < 0) {
      std::string msg = name_ + ": cannot use address " + format_hex(address, 2) + ": " + std::strerror(-r);
      if (-r == EBUSY) {
        msg +=
            ". A kernel driver (at24) is bound to it: use storage.backend nvmem with its "
            "/sys/bus/nvmem/devices/*/nvmem file, or unbind it (echo " +
            format_hex(address, 2) + " > /sys/bus/i2c/devices/i2c-N/delete_device)";
      }
      return make_error(Errc::kDevice, msg);
    }
    selected_ = address;
    return {};
  }

  Status read_rdwr(std::uint64_t at, std::span<std::uint8_t> out) {
    std::uint8_t addr[2];
    i2c_msg msgs[2]{};
    msgs[0].addr = chip_address(at);
    msgs[0].len = static_cast<std::uint16_t>(word_address(at, addr));
    msgs[0].buf = addr;
    msgs[1].addr = chip_address(at);
    msgs[1].flags = I2C_M_RD;
    msgs[1].len = static_cast<std::uint16_t>(out.size());
    msgs[1].buf = out.data();
    i2c_rdwr_ioctl_data data{msgs, 2};
    if (int r = file_.ioctl(I2C_RDWR, &data); r < 0) return transfer_error("read", at, -r);
    return {};
  }

  Status write_rdwr(std::uint64_t at, std::span<const std::uint8_t> bytes) {
    std::uint8_t buf[2 + 256];
    const std::size_t head = word_address(at, buf);
    std::copy(bytes.begin(), bytes.end(), buf + head);
    i2c_msg msg{};
    msg.addr = chip_address(at);
    msg.len = static_cast<std::uint16_t>(head + bytes.size());
    msg.buf = buf;
    i2c_rdwr_ioctl_data data{&msg, 1};
    if (int r = file_.ioctl(I2C_RDWR, &data); r < 0) return transfer_error("page write", at, -r);
    return {};
  }

  int smbus(char read_write, std::uint8_t command, int size, i2c_smbus_data* data) {
    i2c_smbus_ioctl_data args{};
    args.read_write = read_write;
    args.command = command;
    args.size = size;
    args.data = data;
    return file_.ioctl(I2C_SMBUS, &args);
  }

  Status read_smbus(std::uint64_t at, std::span<std::uint8_t> out) {
    IMUCAL_TRY(select(chip_address(at)));
    i2c_smbus_data block{};
    block.block[0] = static_cast<std::uint8_t>(out.size());
    if (int r = smbus(I2C_SMBUS_READ, static_cast<std::uint8_t>(at), I2C_SMBUS_I2C_BLOCK_DATA, &block); r < 0)
      return transfer_error("SMBus block read", at, -r);
    if (block.block[0] != out.size()) {
      return make_error(Errc::kDevice, name_ + ": short SMBus block read at byte " + std::to_string(at) +
                                           ": " + std::to_string(block.block[0]) + " of " +
                                           std::to_string(out.size()));
    }
    std::copy_n(block.block + 1, out.size(), out.begin());
    return {};
  }

  Status write_smbus(std::uint64_t at, std::span<const std::uint8_t> bytes) {
    IMUCAL_TRY(select(chip_address(at)));
    i2c_smbus_data block{};
    block.block[0] = static_cast<std::uint8_t>(bytes.size());
    std::copy(bytes.begin(), bytes.end(), block.block + 1);
    if (int r = smbus(I2C_SMBUS_WRITE, static_cast<std::uint8_t>(at), I2C_SMBUS_I2C_BLOCK_DATA, &block);
        r < 0)
      return transfer_error("SMBus block write", at, -r);
    return {};
  }

  // One transfer that a chip in its write cycle does not acknowledge and that changes nothing:
  // the word address alone (I2C_RDWR), an SMBus quick write, or a byte read.
  int probe(std::uint16_t address) {
    if (rdwr_) {
      std::uint8_t addr[2];
      i2c_msg msg{};
      msg.addr = address;
      msg.len = static_cast<std::uint16_t>(
          word_address(static_cast<std::uint64_t>(address - o_.address) << 8, addr));
      msg.buf = addr;
      i2c_rdwr_ioctl_data data{&msg, 1};
      return file_.ioctl(I2C_RDWR, &data);
    }
    if (!select(address).ok()) return -EBUSY;
    if (quick_) return smbus(I2C_SMBUS_WRITE, 0, I2C_SMBUS_QUICK, nullptr);
    i2c_smbus_data byte{};
    return smbus(I2C_SMBUS_READ, 0, I2C_SMBUS_BYTE, &byte);
  }

  // ACK polling (24Cxx datasheets, "Acknowledge polling"): the chip is busy for up to its write
  // cycle time (5 ms typical) after a page write and ignores its address meanwhile.
  Status wait_ready(std::uint16_t address) {
    const auto deadline = std::chrono::steady_clock::now() + o_.write_timeout;
    int polls = 0;
    for (;;) {
      const int r = probe(address);
      ++polls;
      if (r >= 0) return {};
      if (!is_nack(-r)) return transfer_error("write-cycle poll", 0, -r);
      if (std::chrono::steady_clock::now() > deadline) {
        return make_error(Errc::kTimeout,
                          name_ + ": the EEPROM did not finish its write cycle within " +
                              std::to_string(o_.write_timeout.count()) + " ms (" + std::to_string(polls) +
                              " polls): check its write-protect pin, power and storage.page_bytes");
      }
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  }

  DeviceFile file_;
  I2cEepromOptions o_;
  std::string name_;
  bool rdwr_ = false;
  bool quick_ = false;
  int selected_ = -1;
};

}  // namespace

Result<std::unique_ptr<StorageDevice>> open_i2c_eeprom_storage(const std::string& device,
                                                               const I2cEepromOptions& o,
                                                               std::unique_ptr<DeviceIo> io) {
  if (device.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no I2C device given; set storage.i2c_device (e.g. /dev/i2c-1)");
  }
  if (o.address < 0x50 || o.address > 0x57) {
    return make_error(Errc::kInvalidArgument, "I2C address " + format_hex(o.address, 2) +
                                                  " is not a 24Cxx EEPROM address (0x50..0x57); check "
                                                  "storage.i2c_address");
  }
  if (o.page_bytes == 0 || o.page_bytes > 256 || (o.page_bytes & (o.page_bytes - 1)) != 0) {
    return make_error(Errc::kInvalidArgument,
                      "storage.page_bytes must be a power of two 1..256 (see the datasheet)");
  }
  if (o.address_bytes != 1 && o.address_bytes != 2) {
    return make_error(Errc::kInvalidArgument, "storage.address_bytes must be 1 or 2");
  }
  const std::uint64_t addressable = o.address_bytes == 1 ? 256ull * (0x58 - o.address) : 65536;
  if (o.size_bytes == 0 || o.size_bytes > addressable) {
    return make_error(Errc::kInvalidArgument,
                      "the storage region ends at byte " + std::to_string(o.size_bytes) + ", but " +
                          std::to_string(o.address_bytes) + "-byte addressing from " +
                          format_hex(o.address, 2) + " reaches " + std::to_string(addressable) +
                          " bytes: fix storage.address_bytes, size_bytes or offset_bytes");
  }
  auto dev = std::make_unique<I2cEepromStorage>(device, o, std::move(io));
  IMUCAL_TRY(dev->open());
  return std::unique_ptr<StorageDevice>(std::move(dev));
}

}  // namespace imucal::drivers
