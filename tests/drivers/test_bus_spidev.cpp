// SPDX-License-Identifier: BSD-3-Clause
// SpidevBus: the transfers it builds (read bit, per-transfer clock, mode 3, 8-bit words), its
// errors and counters. A fake spidev stands in for the kernel (no SPI controller here); the
// open/ioctl error paths also run against real device nodes.

#include <gtest/gtest.h>
#include <linux/spi/spidev.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <memory>
#include <vector>

#include "drivers/bus/device_io.hpp"
#include "drivers/bus/spidev_bus.hpp"

namespace imucal::drivers {
namespace {

struct SpiTransferRecord {
  std::vector<std::uint8_t> tx;
  std::uint32_t speed_hz = 0;
  std::uint8_t bits_per_word = 0;
};

// A spidev node with an MPU-6000-like register file behind it: reads (bit 7 set) auto-increment.
struct FakeSpidev {
  std::string path = "/dev/spidev0.0";
  std::array<std::uint8_t, 256> regs{};
  std::uint8_t mode = 0;
  std::uint8_t mode_kept_mask = 0xFF;  // bits of the mode the "controller" keeps
  std::uint8_t bits = 0;
  std::uint32_t max_speed_hz = 0;
  int open_errno = 0;
  int fail_mode_errno = 0;
  int fail_message_errno = 0;
  int short_by = 0;
  int opens = 0;
  int closes = 0;
  std::vector<SpiTransferRecord> transfers;
};

class FakeSpidevIo final : public DeviceIo {
 public:
  explicit FakeSpidevIo(std::shared_ptr<FakeSpidev> dev) : dev_(std::move(dev)) {}
  int open(const std::string& path) override {
    if (dev_->open_errno != 0) return -dev_->open_errno;
    if (path != dev_->path) return -ENOENT;
    ++dev_->opens;
    return 7;
  }
  void close(int fd) override {
    EXPECT_EQ(fd, 7);
    ++dev_->closes;
  }
  int ioctl(int fd, unsigned long request, void* arg) override {
    EXPECT_EQ(fd, 7);
    if (request == SPI_IOC_WR_MODE) {
      if (dev_->fail_mode_errno != 0) return -dev_->fail_mode_errno;
      dev_->mode = *static_cast<std::uint8_t*>(arg) & dev_->mode_kept_mask;
      return 0;
    }
    if (request == SPI_IOC_RD_MODE) {
      *static_cast<std::uint8_t*>(arg) = dev_->mode;
      return 0;
    }
    if (request == SPI_IOC_WR_BITS_PER_WORD) {
      dev_->bits = *static_cast<std::uint8_t*>(arg);
      return 0;
    }
    if (request == SPI_IOC_WR_MAX_SPEED_HZ) {
      dev_->max_speed_hz = *static_cast<std::uint32_t*>(arg);
      return 0;
    }
    if (request == SPI_IOC_MESSAGE(1)) {
      if (dev_->fail_message_errno != 0) return -dev_->fail_message_errno;
      auto* x = static_cast<spi_ioc_transfer*>(arg);
      const auto* tx = reinterpret_cast<const std::uint8_t*>(static_cast<std::uintptr_t>(x->tx_buf));
      auto* rx = reinterpret_cast<std::uint8_t*>(static_cast<std::uintptr_t>(x->rx_buf));
      dev_->transfers.push_back({std::vector<std::uint8_t>(tx, tx + x->len), x->speed_hz, x->bits_per_word});
      const std::uint8_t addr = tx[0] & 0x7F;
      if (tx[0] & 0x80) {
        for (std::uint32_t i = 1; i < x->len; ++i) rx[i] = dev_->regs[(addr + i - 1) & 0xFF];
      } else if (x->len >= 2) {
        dev_->regs[addr] = tx[1];
      }
      return static_cast<int>(x->len) - dev_->short_by;
    }
    ADD_FAILURE() << "unexpected ioctl " << request;
    return -EINVAL;
  }

 private:
  std::shared_ptr<FakeSpidev> dev_;
};

std::unique_ptr<SpidevBus> open_fake(const std::shared_ptr<FakeSpidev>& dev, SpidevOptions options = {}) {
  auto bus = SpidevBus::open("spidev0.0", options, std::make_unique<FakeSpidevIo>(dev));
  EXPECT_TRUE(bus.ok()) << (bus.ok() ? "" : bus.error().message);
  return bus.ok() ? std::move(bus).value() : nullptr;
}

TEST(BusSpidev, MissingDeviceSaysWhatToCheck) {
  auto bus = SpidevBus::open("/dev/spidev-imucal-test9.9");
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kNotFound);
  const std::string& msg = bus.error().message;
  EXPECT_NE(msg.find("/dev/spidev-imucal-test9.9"), std::string::npos) << msg;
  EXPECT_NE(msg.find("spidev driver is loaded"), std::string::npos) << msg;
  EXPECT_NE(msg.find("imu.device"), std::string::npos) << msg;
}

TEST(BusSpidev, NodeThatIsNotSpidevIsRejected) {
  auto bus = SpidevBus::open("/dev/null");
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kDevice);
  EXPECT_NE(bus.error().message.find("SPI_IOC_WR_MODE"), std::string::npos) << bus.error().message;
  EXPECT_NE(bus.error().message.find("not a spidev device"), std::string::npos) << bus.error().message;
}

TEST(BusSpidev, PermissionDeniedSaysSo) {
  auto dev = std::make_shared<FakeSpidev>();
  dev->open_errno = EACCES;
  auto bus = SpidevBus::open("/dev/spidev0.0", {}, std::make_unique<FakeSpidevIo>(dev));
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kIo);
  EXPECT_NE(bus.error().message.find("Permission denied"), std::string::npos) << bus.error().message;
  EXPECT_NE(bus.error().message.find("ls -l /dev/spidev0.0"), std::string::npos) << bus.error().message;
}

TEST(BusSpidev, EmptyDeviceOrBadClocksAreInvalid) {
  EXPECT_EQ(SpidevBus::open("").error().code, Errc::kInvalidArgument);
  SpidevOptions options;
  options.config_speed_hz = 2'000'000;
  options.max_speed_hz = 1'000'000;
  EXPECT_EQ(SpidevBus::open("/dev/spidev0.0", options).error().code, Errc::kInvalidArgument);
}

TEST(BusSpidev, ConfiguresMode3EightBits) {
  auto dev = std::make_shared<FakeSpidev>();
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus);
  EXPECT_EQ(dev->mode, SPI_MODE_3);
  EXPECT_EQ(dev->bits, 8);
  EXPECT_EQ(dev->max_speed_hz, 20'000'000u);
  EXPECT_EQ(bus->name(), "spidev0.0");
  EXPECT_EQ(bus->path(), "/dev/spidev0.0");
}

TEST(BusSpidev, ControllerThatDropsMode3IsRejected) {
  auto dev = std::make_shared<FakeSpidev>();
  dev->mode_kept_mask = static_cast<std::uint8_t>(~SPI_CPOL);
  auto bus = SpidevBus::open("/dev/spidev0.0", {}, std::make_unique<FakeSpidevIo>(dev));
  ASSERT_FALSE(bus.ok());
  EXPECT_EQ(bus.error().code, Errc::kDevice);
  EXPECT_NE(bus.error().message.find("mode 3"), std::string::npos) << bus.error().message;
  EXPECT_EQ(dev->closes, 1);
}

TEST(BusSpidev, ReadSetsReadBitAndReturnsTheRegister) {
  auto dev = std::make_shared<FakeSpidev>();
  dev->regs[0x75] = 0x68;
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus);
  auto who = bus->read_u8(0x75);
  ASSERT_TRUE(who.ok());
  EXPECT_EQ(*who, 0x68);
  ASSERT_EQ(dev->transfers.size(), 1u);
  EXPECT_EQ(dev->transfers[0].tx, (std::vector<std::uint8_t>{0xF5, 0x00}));
  EXPECT_EQ(dev->transfers[0].bits_per_word, 8);
  EXPECT_EQ(bus->counters().transfers, 1u);
}

TEST(BusSpidev, BurstReadReturnsConsecutiveRegisters) {
  auto dev = std::make_shared<FakeSpidev>();
  for (int i = 0; i < 14; ++i) dev->regs[0x3B + i] = static_cast<std::uint8_t>(0xA0 + i);
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus);
  std::array<std::uint8_t, 14> out{};
  ASSERT_TRUE(bus->read(0x3B, out).ok());
  for (int i = 0; i < 14; ++i) EXPECT_EQ(out[i], 0xA0 + i) << i;
  ASSERT_EQ(dev->transfers.size(), 1u);
  EXPECT_EQ(dev->transfers[0].tx.size(), 15u);
  EXPECT_EQ(dev->transfers[0].tx[0], 0x3B | 0x80);
}

TEST(BusSpidev, WritesUseTheConfigClockReadsTheChosenClock) {
  auto dev = std::make_shared<FakeSpidev>();
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus);
  EXPECT_EQ(bus->speed_hz(), 1'000'000u);
  bus->set_speed_hz(20'000'000);
  ASSERT_TRUE(bus->write(0xEB, 0x80).ok());  // bit 7 must be cleared on writes
  std::array<std::uint8_t, 2> fifo_count{};
  ASSERT_TRUE(bus->read(0x72, fifo_count).ok());
  ASSERT_EQ(dev->transfers.size(), 2u);
  EXPECT_EQ(dev->transfers[0].tx, (std::vector<std::uint8_t>{0x6B, 0x80}));
  EXPECT_EQ(dev->transfers[0].speed_hz, 1'000'000u);
  EXPECT_EQ(dev->regs[0x6B], 0x80);
  EXPECT_EQ(dev->transfers[1].speed_hz, 20'000'000u);
}

TEST(BusSpidev, SpeedIsClampedToTheConfiguredRange) {
  auto dev = std::make_shared<FakeSpidev>();
  SpidevOptions options;
  options.config_speed_hz = 500'000;
  options.max_speed_hz = 10'000'000;
  auto bus = open_fake(dev, options);
  ASSERT_TRUE(bus);
  bus->set_speed_hz(50'000'000);
  EXPECT_EQ(bus->speed_hz(), 10'000'000u);
  bus->set_speed_hz(10);
  EXPECT_EQ(bus->speed_hz(), 1'000u);
  bus->set_speed_hz(0);
  EXPECT_EQ(bus->speed_hz(), 500'000u);
  bus->set_speed_hz(4'000'000);
  ASSERT_TRUE(bus->write(0x19, 1).ok());
  ASSERT_TRUE(bus->read_u8(0x19).ok());
  EXPECT_EQ(dev->transfers[0].speed_hz, 500'000u);
  EXPECT_EQ(dev->transfers[1].speed_hz, 4'000'000u);
}

TEST(BusSpidev, FailuresAreCountedPerCause) {
  auto dev = std::make_shared<FakeSpidev>();
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus);

  dev->fail_message_errno = EIO;
  auto failed = bus->read_u8(0x75);
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.error().code, Errc::kIo);
  EXPECT_NE(failed.error().message.find("0x75"), std::string::npos) << failed.error().message;
  EXPECT_EQ(bus->counters().transfer_errors, 1u);

  dev->fail_message_errno = 0;
  dev->short_by = 1;
  auto s = bus->write(0x6B, 0);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kDevice);
  EXPECT_NE(s.error().message.find("short"), std::string::npos) << s.error().message;
  EXPECT_EQ(bus->counters().short_transfers, 1u);

  dev->short_by = 0;
  dev->open_errno = ENOENT;
  auto r = bus->reopen();
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kNotFound);
  EXPECT_EQ(bus->counters().open_errors, 1u);
  // Closed after the failed reopen: transfers fail cleanly until a reopen succeeds.
  EXPECT_FALSE(bus->read_u8(0x75).ok());
  EXPECT_EQ(bus->counters().transfer_errors, 2u);
  dev->open_errno = 0;
  ASSERT_TRUE(bus->reopen().ok());
  EXPECT_TRUE(bus->read_u8(0x75).ok());
  EXPECT_EQ(bus->counters().transfers, 3u);
}

TEST(BusSpidev, OversizedReadIsRefusedBeforeTheKernel) {
  auto dev = std::make_shared<FakeSpidev>();
  auto bus = open_fake(dev);
  ASSERT_TRUE(bus);
  std::vector<std::uint8_t> out(SpidevBus::kMaxTransferBytes);
  auto s = bus->read(0x74, out);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kInvalidArgument);
  EXPECT_TRUE(dev->transfers.empty());
  std::vector<std::uint8_t> fifo(1024);
  EXPECT_TRUE(bus->read(0x74, fifo).ok());
}

}  // namespace
}  // namespace imucal::drivers
