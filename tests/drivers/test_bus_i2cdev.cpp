// SPDX-License-Identifier: BSD-3-Clause
// I2cDevBus: functionality check and mode choice at open, the I2C_RDWR and SMBus transactions
// it builds, its errors and counters. A fake i2c-dev stands in for the kernel here; the real
// kernel path (i2c-stub, SMBus mode) runs in tests/qemu.

#include <gtest/gtest.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>

#include <array>
#include <cerrno>
#include <memory>
#include <vector>

#include "drivers/bus/device_io.hpp"
#include "drivers/bus/i2cdev_bus.hpp"

namespace imucal::drivers {
namespace {

constexpr unsigned long kStubFuncs = I2C_FUNC_SMBUS_QUICK | I2C_FUNC_SMBUS_BYTE | I2C_FUNC_SMBUS_BYTE_DATA |
                                     I2C_FUNC_SMBUS_WORD_DATA | I2C_FUNC_SMBUS_I2C_BLOCK;
constexpr unsigned long kSocFuncs = I2C_FUNC_I2C | kStubFuncs;

struct I2cRecord {
  bool rdwr = false;
  bool read = false;
  std::uint16_t addr = 0;
  std::uint8_t reg = 0;
  std::size_t len = 0;
};

// An i2c-dev adapter with one register file behind it (a chip at `chip_addr`).
struct FakeI2c {
  unsigned long funcs = kSocFuncs;
  std::uint16_t chip_addr = 0x68;
  std::array<std::uint8_t, 256> regs{};
  unsigned long slave = 0;
  int slave_errno = 0;
  int xfer_errno = 0;
  int short_by = 0;
  std::vector<I2cRecord> log;
};

class FakeI2cDevIo final : public DeviceIo {
 public:
  explicit FakeI2cDevIo(std::shared_ptr<FakeI2c> dev) : dev_(std::move(dev)) {}
  int open(const std::string& path) override { return path == "/dev/i2c-1" ? 5 : -ENOENT; }
  void close(int) override {}
  int ioctl(int, unsigned long request, void* arg) override {
    if (request == I2C_FUNCS) {
      *static_cast<unsigned long*>(arg) = dev_->funcs;
      return 0;
    }
    if (request == I2C_SLAVE) {
      if (dev_->slave_errno != 0) return -dev_->slave_errno;
      dev_->slave = reinterpret_cast<unsigned long>(arg);
      return 0;
    }
    if (dev_->xfer_errno != 0) return -dev_->xfer_errno;
    if (request == I2C_RDWR) {
      EXPECT_TRUE(dev_->funcs & I2C_FUNC_I2C) << "I2C_RDWR on an SMBus-only adapter";
      auto* data = static_cast<i2c_rdwr_ioctl_data*>(arg);
      i2c_msg* m = data->msgs;
      if (m[0].addr != dev_->chip_addr) return -ENXIO;
      if (data->nmsgs == 2) {
        EXPECT_EQ(m[0].flags, 0);
        EXPECT_EQ(m[0].len, 1);
        EXPECT_EQ(m[1].flags, I2C_M_RD);
        EXPECT_EQ(m[1].addr, m[0].addr);
        const std::uint8_t reg = m[0].buf[0];
        for (std::uint16_t i = 0; i < m[1].len; ++i) m[1].buf[i] = dev_->regs[(reg + i) & 0xFF];
        dev_->log.push_back({true, true, m[0].addr, reg, m[1].len});
      } else {
        EXPECT_EQ(data->nmsgs, 1u);
        EXPECT_EQ(m[0].len, 2);
        dev_->regs[m[0].buf[0]] = m[0].buf[1];
        dev_->log.push_back({true, false, m[0].addr, m[0].buf[0], 1});
      }
      return static_cast<int>(data->nmsgs) - dev_->short_by;
    }
    if (request == I2C_SMBUS) {
      auto* a = static_cast<i2c_smbus_ioctl_data*>(arg);
      if (dev_->slave != dev_->chip_addr) return -ENXIO;
      if (a->read_write == I2C_SMBUS_READ) {
        EXPECT_EQ(a->size, static_cast<std::uint32_t>(I2C_SMBUS_I2C_BLOCK_DATA));
        const std::uint8_t n = a->data->block[0];
        EXPECT_LE(n, I2C_SMBUS_BLOCK_MAX);
        for (std::uint8_t i = 0; i < n; ++i) a->data->block[1 + i] = dev_->regs[(a->command + i) & 0xFF];
        a->data->block[0] = static_cast<std::uint8_t>(n - dev_->short_by);
        dev_->log.push_back({false, true, static_cast<std::uint16_t>(dev_->slave), a->command, n});
      } else {
        EXPECT_EQ(a->size, static_cast<std::uint32_t>(I2C_SMBUS_BYTE_DATA));
        dev_->regs[a->command] = a->data->byte;
        dev_->log.push_back({false, false, static_cast<std::uint16_t>(dev_->slave), a->command, 1});
      }
      return 0;
    }
    ADD_FAILURE() << "unexpected ioctl " << request;
    return -EINVAL;
  }

 private:
  std::shared_ptr<FakeI2c> dev_;
};

Result<std::unique_ptr<I2cDevBus>> open_fake(const std::shared_ptr<FakeI2c>& dev,
                                             I2cDevOptions options = {}) {
  return I2cDevBus::open("i2c-1", options, std::make_unique<FakeI2cDevIo>(dev));
}

TEST(BusI2cDev, MissingDeviceSaysWhatToCheck) {
  auto bus = I2cDevBus::open("/dev/i2c-imucal-test-99");
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kNotFound);
  const std::string& msg = bus.error().message;
  EXPECT_NE(msg.find("/dev/i2c-imucal-test-99"), std::string::npos) << msg;
  EXPECT_NE(msg.find("modprobe i2c-dev"), std::string::npos) << msg;
  EXPECT_NE(msg.find("imu.device"), std::string::npos) << msg;
}

TEST(BusI2cDev, NodeThatIsNotI2cDevIsRejected) {
  auto bus = I2cDevBus::open("/dev/null");
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kDevice);
  EXPECT_NE(bus.error().message.find("I2C_FUNCS"), std::string::npos) << bus.error().message;
}

TEST(BusI2cDev, OnlyMpu6000AddressesAreAccepted) {
  auto dev = std::make_shared<FakeI2c>();
  I2cDevOptions options;
  options.address = 0x50;
  auto bus = open_fake(dev, options);
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kInvalidArgument);
  EXPECT_NE(bus.error().message.find("0x68"), std::string::npos) << bus.error().message;
  EXPECT_NE(bus.error().message.find("0x69"), std::string::npos) << bus.error().message;
}

TEST(BusI2cDev, PlainI2cAdapterUsesCombinedRdwrTransactions) {
  auto dev = std::make_shared<FakeI2c>();
  dev->chip_addr = 0x69;
  for (int i = 0; i < 14; ++i) dev->regs[0x3B + i] = static_cast<std::uint8_t>(i * 7);
  I2cDevOptions options;
  options.address = 0x69;
  auto bus = open_fake(dev, options);
  ASSERT_TRUE(bus.ok()) << bus.error().message;
  EXPECT_EQ((*bus)->mode(), I2cTransferMode::kI2cRdwr);
  EXPECT_EQ((*bus)->name(), "i2c-1@0x69");
  EXPECT_EQ(dev->slave, 0x69u);

  std::vector<std::uint8_t> out(14);
  ASSERT_TRUE((*bus)->read(0x3B, out).ok());
  for (int i = 0; i < 14; ++i) EXPECT_EQ(out[i], i * 7) << i;
  // A FIFO burst larger than one SMBus block is still one transaction.
  std::vector<std::uint8_t> fifo(840);
  ASSERT_TRUE((*bus)->read(0x74, fifo).ok());
  ASSERT_TRUE((*bus)->write(0x6B, 0x01).ok());
  EXPECT_EQ(dev->regs[0x6B], 0x01);
  ASSERT_EQ(dev->log.size(), 3u);
  EXPECT_TRUE(dev->log[0].rdwr && dev->log[0].read);
  EXPECT_EQ(dev->log[0].addr, 0x69);
  EXPECT_EQ(dev->log[1].len, 840u);
  EXPECT_TRUE(dev->log[2].rdwr && !dev->log[2].read);
  EXPECT_EQ((*bus)->counters().transfers, 3u);
}

TEST(BusI2cDev, SmbusOnlyAdapterSplitsBurstsIntoBlocks) {
  auto dev = std::make_shared<FakeI2c>();
  dev->funcs = kStubFuncs;
  for (int i = 0; i < 256; ++i) dev->regs[i] = static_cast<std::uint8_t>(255 - i);
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus.ok()) << bus.error().message;
  EXPECT_EQ((*bus)->mode(), I2cTransferMode::kSmbus);

  std::vector<std::uint8_t> out(40);
  ASSERT_TRUE((*bus)->read(0x10, out).ok());
  for (int i = 0; i < 40; ++i) EXPECT_EQ(out[i], 255 - (0x10 + i)) << i;
  ASSERT_EQ(dev->log.size(), 2u);
  EXPECT_EQ(dev->log[0].reg, 0x10);
  EXPECT_EQ(dev->log[0].len, 32u);
  EXPECT_EQ(dev->log[1].reg, 0x30);
  EXPECT_EQ(dev->log[1].len, 8u);

  // FIFO_R_W does not advance: every block is read from 0x74.
  dev->log.clear();
  std::vector<std::uint8_t> fifo(70);
  ASSERT_TRUE((*bus)->read(0x74, fifo).ok());
  ASSERT_EQ(dev->log.size(), 3u);
  for (const auto& rec : dev->log) EXPECT_EQ(rec.reg, 0x74);

  // Past the last register is refused (except for the FIFO).
  std::vector<std::uint8_t> too_far(16);
  EXPECT_EQ((*bus)->read(0xF8, too_far).error().code, Errc::kInvalidArgument);

  ASSERT_TRUE((*bus)->write(0x1A, 0x03).ok());
  EXPECT_EQ(dev->regs[0x1A], 0x03);
}

TEST(BusI2cDev, AdapterThatCannotServeTheChipIsRejected) {
  auto dev = std::make_shared<FakeI2c>();
  dev->funcs = I2C_FUNC_SMBUS_QUICK | I2C_FUNC_SMBUS_BYTE_DATA;  // no block reads, no plain I2C
  auto bus = open_fake(dev);
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kUnsupported);
  EXPECT_NE(bus.error().message.find("I2C_FUNC_I2C"), std::string::npos) << bus.error().message;
  EXPECT_NE(bus.error().message.find("0x00190000"), std::string::npos) << bus.error().message;

  dev->funcs = kStubFuncs;
  I2cDevOptions forced;
  forced.mode = I2cTransferMode::kI2cRdwr;
  auto rdwr = open_fake(dev, forced);
  ASSERT_FALSE(rdwr.ok());
  EXPECT_EQ(rdwr.error().code, Errc::kUnsupported);
  EXPECT_NE(rdwr.error().message.find("SMBus-only"), std::string::npos) << rdwr.error().message;

  // A plain-I2C adapter can still be driven with SMBus transactions when asked.
  dev->funcs = kSocFuncs;
  forced.mode = I2cTransferMode::kSmbus;
  auto smbus = open_fake(dev, forced);
  ASSERT_TRUE(smbus.ok());
  EXPECT_EQ((*smbus)->mode(), I2cTransferMode::kSmbus);
}

TEST(BusI2cDev, AddressHeldByKernelDriverIsExplained) {
  auto dev = std::make_shared<FakeI2c>();
  dev->slave_errno = EBUSY;
  auto bus = open_fake(dev);
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kDevice);
  EXPECT_NE(bus.error().message.find("kernel driver"), std::string::npos) << bus.error().message;
}

TEST(BusI2cDev, FailuresAreCountedPerCause) {
  auto dev = std::make_shared<FakeI2c>();
  dev->chip_addr = 0x69;  // nothing answers at 0x68
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus.ok());
  auto who = (*bus)->read_u8(0x75);
  ASSERT_FALSE(who.ok());
  EXPECT_EQ(who.error().code, Errc::kIo);
  EXPECT_NE(who.error().message.find("AD0"), std::string::npos) << who.error().message;
  EXPECT_EQ((*bus)->counters().transfer_errors, 1u);

  dev->chip_addr = 0x68;
  dev->xfer_errno = ETIMEDOUT;
  auto t = (*bus)->write(0x6B, 0);
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.error().code, Errc::kTimeout);
  EXPECT_EQ((*bus)->counters().timeouts, 1u);
  EXPECT_EQ((*bus)->counters().transfer_errors, 2u);

  dev->xfer_errno = 0;
  dev->short_by = 1;
  auto s = (*bus)->read_u8(0x75);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kDevice);
  EXPECT_EQ((*bus)->counters().short_transfers, 1u);
  EXPECT_EQ((*bus)->counters().transfers, 3u);
}

TEST(BusI2cDev, ShortSmbusBlockIsCounted) {
  auto dev = std::make_shared<FakeI2c>();
  dev->funcs = kStubFuncs;
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus.ok());
  dev->short_by = 2;
  std::vector<std::uint8_t> out(14);
  auto s = (*bus)->read(0x3B, out);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("12 of 14"), std::string::npos) << s.error().message;
  EXPECT_EQ((*bus)->counters().short_transfers, 1u);
}

}  // namespace
}  // namespace imucal::drivers
