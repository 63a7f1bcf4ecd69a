// SPDX-License-Identifier: BSD-3-Clause
// The storage backends (drivers/storage/storage_device.hpp): the file backend on real files, the
// nvmem backend on a regular file standing in for the sysfs attribute, and the i2c-eeprom
// backend against a fake kernel (DeviceIo) that behaves like a 24Cxx on an adapter: page
// wrap-around, busy (no acknowledge) during the write cycle, an address owned by at24.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <vector>

#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/storage_device.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes pattern(std::size_t n, std::uint8_t start) {
  Bytes p(n);
  std::iota(p.begin(), p.end(), start);
  return p;
}

TEST(StorageFile, CreatesTheFileAtItsSizeAndRoundTrips) {
  const std::string path = test::scratch_dir() + "/calibration.bin";
  auto dev = open_file_storage(path, 1024, StorageAccess::kWrite);
  ASSERT_TRUE(dev.ok()) << dev.error().message;
  EXPECT_EQ(std::filesystem::file_size(path), 1024u);
  EXPECT_EQ((*dev)->size(), 1024u);
  {
    auto store = CalibrationStore::open(**dev, 0, 1024);
    ASSERT_TRUE(store.ok());
    ASSERT_TRUE(store->write(pattern(300, 1)).ok());
    ASSERT_TRUE(store->write(pattern(200, 2)).ok());
  }
  dev->reset();
  // A new process sees what was written.
  auto again = open_file_storage(path, 1024, StorageAccess::kRead);
  ASSERT_TRUE(again.ok()) << again.error().message;
  auto store = CalibrationStore::open(**again, 0, 1024);
  ASSERT_TRUE(store.ok());
  auto latest = store->read_latest();
  ASSERT_TRUE(latest.ok() && latest->record);
  EXPECT_EQ(latest->record->sequence, 2u);
  EXPECT_EQ(latest->record->payload, pattern(200, 2));
  EXPECT_EQ(latest->slot, 1);
}

TEST(StorageFile, ReadingNeverCreatesAndMissingIsNotFound) {
  const std::string path = test::scratch_dir() + "/none.bin";
  auto dev = open_file_storage(path, 512, StorageAccess::kRead);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.error().code, Errc::kNotFound);
  EXPECT_NE(dev.error().message.find("store write"), std::string::npos) << dev.error().message;
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(StorageFile, AShortFileIsRefusedNotGrown) {
  const std::string path = test::scratch_dir() + "/short.bin";
  std::ofstream(path) << std::string(100, 'x');
  auto dev = open_file_storage(path, 512, StorageAccess::kWrite);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.error().code, Errc::kInvalidArgument);
  EXPECT_NE(dev.error().message.find("100 bytes"), std::string::npos) << dev.error().message;
  EXPECT_EQ(std::filesystem::file_size(path), 100u);
}

// A loop of symbolic links at storage.path is the configuration's to fix (exit 2 at the CLI), as a
// FIFO there is; before: an I/O error (exit 7). Reading or writing, nothing is created.
TEST(StorageFile, ALoopOfSymbolicLinksIsAPathToFix) {
  const std::string dir = test::scratch_dir();
  std::filesystem::create_symlink(dir + "/b.bin", dir + "/a.bin");
  std::filesystem::create_symlink(dir + "/a.bin", dir + "/b.bin");
  for (const StorageAccess access : {StorageAccess::kRead, StorageAccess::kWrite}) {
    auto dev = open_file_storage(dir + "/a.bin", 512, access);
    ASSERT_FALSE(dev.ok());
    EXPECT_EQ(dev.error().code, Errc::kInvalidArgument) << dev.error().message;
    EXPECT_NE(dev.error().message.find("fix storage.path"), std::string::npos) << dev.error().message;
  }
  EXPECT_TRUE(std::filesystem::is_symlink(dir + "/a.bin"));
}

TEST(StorageFile, AMissingFolderSaysSo) {
  auto dev = open_file_storage(test::scratch_dir() + "/no/such/dir/c.bin", 512, StorageAccess::kWrite);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.error().code, Errc::kNotFound);
  EXPECT_NE(dev.error().message.find("does not exist"), std::string::npos) << dev.error().message;
}

TEST(StorageFile, AReadOnlyFileCanBeReadButNotOpenedForWriting) {
  const std::string path = test::scratch_dir() + "/ro.bin";
  std::ofstream(path) << std::string(512, '\0');
  ::chmod(path.c_str(), 0444);
  auto reader = open_file_storage(path, 512, StorageAccess::kRead);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  Bytes head(24);
  EXPECT_TRUE((*reader)->read(0, head).ok());
  if (::geteuid() == 0) GTEST_SKIP() << "running as root: file permissions do not refuse writing";
  auto dev = open_file_storage(path, 512, StorageAccess::kWrite);
  ASSERT_FALSE(dev.ok());
  EXPECT_NE(dev.error().message.find("may write"), std::string::npos) << dev.error().message;
}

TEST(StorageFile, TheConfigurationPicksTheBackend) {
  StorageConfig c;
  c.backend = StorageBackend::kFile;
  c.path = test::scratch_dir() + "/cfg.bin";
  c.size_bytes = 256;
  c.offset_bytes = 64;
  EXPECT_EQ(open_storage_device(c, StorageAccess::kRead).error().code, Errc::kNotFound);
  auto dev = open_storage_device(c, StorageAccess::kWrite);
  ASSERT_TRUE(dev.ok()) << dev.error().message;
  EXPECT_EQ((*dev)->size(), 320u);
  c.backend = StorageBackend::kNvmem;
  c.path = test::scratch_dir() + "/no-nvmem";
  auto nv = open_storage_device(c, StorageAccess::kWrite);
  ASSERT_FALSE(nv.ok());
  EXPECT_EQ(nv.error().code, Errc::kDevice);
  EXPECT_NE(nv.error().message.find("at24"), std::string::npos) << nv.error().message;
  EXPECT_FALSE(std::filesystem::exists(c.path));
}

TEST(StorageNvmem, WritesInChunksAndRefusesASmallDevice) {
  const std::string path = test::scratch_dir() + "/nvmem";
  std::ofstream(path, std::ios::binary) << std::string(256, '\xff');
  EXPECT_EQ(open_nvmem_storage(path, 512, StorageAccess::kRead).error().code, Errc::kInvalidArgument);
  auto dev = open_nvmem_storage(path, 256, StorageAccess::kWrite,
                                7);  // odd chunks: every piece boundary lands mid-record
  ASSERT_TRUE(dev.ok()) << dev.error().message;
  const Bytes data = pattern(200, 3);
  ASSERT_TRUE((*dev)->write(20, data).ok());
  ASSERT_TRUE((*dev)->sync().ok());
  Bytes back(200);
  ASSERT_TRUE((*dev)->read(20, back).ok());
  EXPECT_EQ(back, data);
  EXPECT_FALSE((*dev)->write(100, data).ok());  // past the end
}

// --- i2c-eeprom against a fake kernel ---------------------------------------------------------

struct FakeEeprom {
  Bytes memory;
  std::size_t page = 8;
  int address_bytes = 1;
  std::uint16_t base = 0x50;
  unsigned long funcs = I2C_FUNC_I2C | I2C_FUNC_SMBUS_QUICK | I2C_FUNC_SMBUS_I2C_BLOCK;
  bool at24_bound = false;
  int busy_polls = 2;  // NACKs after each write, as during the write cycle
  bool stuck_busy = false;
  // Observed.
  int busy_left = 0;
  std::size_t pointer = 0;
  int slave = -1;
  int page_writes = 0;
  int nacks = 0;
};

class FakeEepromIo final : public DeviceIo {
 public:
  explicit FakeEepromIo(FakeEeprom& chip) : chip_(chip) {}
  int open(const std::string&) override { return 3; }
  void close(int) override {}
  int ioctl(int, unsigned long request, void* arg) override {
    switch (request) {
      case I2C_FUNCS:
        *static_cast<unsigned long*>(arg) = chip_.funcs;
        return 0;
      case I2C_SLAVE:
        if (chip_.at24_bound) return -EBUSY;
        chip_.slave = static_cast<int>(reinterpret_cast<unsigned long>(arg));
        return 0;
      case I2C_RDWR:
        return rdwr(*static_cast<i2c_rdwr_ioctl_data*>(arg));
      case I2C_SMBUS:
        return smbus(*static_cast<i2c_smbus_ioctl_data*>(arg));
      default:
        return -ENOTTY;
    }
  }

 private:
  bool busy() {
    if (chip_.stuck_busy || chip_.busy_left > 0) {
      --chip_.busy_left;
      ++chip_.nacks;
      return true;
    }
    return false;
  }
  std::size_t block_of(std::uint16_t addr) const { return static_cast<std::size_t>(addr - chip_.base) * 256; }
  void store(std::span<const std::uint8_t> data) {
    // A page write wraps inside its page, as the chip's address counter does.
    const std::size_t page_start = chip_.pointer - chip_.pointer % chip_.page;
    std::size_t in_page = chip_.pointer % chip_.page;
    for (std::uint8_t b : data) {
      chip_.memory[page_start + in_page] = b;
      in_page = (in_page + 1) % chip_.page;
    }
    ++chip_.page_writes;
    chip_.busy_left = chip_.busy_polls;
  }
  void load(std::span<std::uint8_t> out) {
    for (auto& b : out) b = chip_.memory[chip_.pointer++ % chip_.memory.size()];
  }
  int rdwr(i2c_rdwr_ioctl_data& d) {
    if (busy()) return -ENXIO;
    std::span<i2c_msg> msgs(d.msgs, d.nmsgs);
    const i2c_msg& w = msgs[0];
    if (w.flags & I2C_M_RD || w.len < chip_.address_bytes) return -EINVAL;
    chip_.pointer =
        block_of(w.addr) +
        (chip_.address_bytes == 1 ? w.buf[0] : static_cast<std::size_t>(w.buf[0] << 8 | w.buf[1]));
    if (w.len > chip_.address_bytes) {
      store({w.buf + chip_.address_bytes, static_cast<std::size_t>(w.len - chip_.address_bytes)});
    }
    if (msgs.size() == 2) load({msgs[1].buf, msgs[1].len});
    return static_cast<int>(msgs.size());
  }
  int smbus(i2c_smbus_ioctl_data& a) {
    if (busy()) return -ENXIO;
    if (a.size == I2C_SMBUS_QUICK) return 0;
    if (a.size != I2C_SMBUS_I2C_BLOCK_DATA) return -EINVAL;
    chip_.pointer = block_of(static_cast<std::uint16_t>(chip_.slave)) + a.command;
    if (a.read_write == I2C_SMBUS_WRITE) {
      store({a.data->block + 1, a.data->block[0]});
    } else {
      load({a.data->block + 1, a.data->block[0]});
    }
    return 0;
  }
  FakeEeprom& chip_;
};

// The fake counts busy polls, not time: a generous timeout keeps a loaded machine (a sleep that
// overshoots) from turning a busy chip into a timeout; the timeout test passes a short one.
Result<std::unique_ptr<StorageDevice>> open_fake(
    FakeEeprom& chip, std::uint64_t size, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
  I2cEepromOptions o;
  o.size_bytes = size;
  o.page_bytes = chip.page;
  o.address_bytes = chip.address_bytes;
  o.write_timeout = timeout;
  return open_i2c_eeprom_storage("/dev/i2c-9", o, std::make_unique<FakeEepromIo>(chip));
}

void round_trip(FakeEeprom& chip, std::uint64_t size) {
  chip.memory.assign(size, 0xFF);
  auto dev = open_fake(chip, size);
  ASSERT_TRUE(dev.ok()) << dev.error().message;
  auto store = CalibrationStore::open(**dev, 0, size);
  ASSERT_TRUE(store.ok());
  const Bytes a = pattern(static_cast<std::size_t>(size / 2 - 40), 5), b = pattern(77, 9);
  auto wa = store->write(a);
  ASSERT_TRUE(wa.ok()) << wa.error().message;
  auto wb = store->write(b);
  ASSERT_TRUE(wb.ok()) << wb.error().message;
  auto latest = store->read_latest();
  ASSERT_TRUE(latest.ok() && latest->record) << (latest.ok() ? "" : latest.error().message);
  EXPECT_EQ(latest->record->payload, b);
  EXPECT_EQ(latest->record->sequence, 2u);
  // Slot A still holds `a`, byte for byte (pages were never crossed, or the wrap would show).
  auto slots = store->inspect();
  ASSERT_TRUE(slots.ok());
  EXPECT_TRUE((*slots)[0].valid) << (*slots)[0].reason;
  EXPECT_EQ((*slots)[0].payload_bytes, a.size());
  EXPECT_GT(chip.nacks, 0);  // the write cycle was waited for
}

TEST(StorageI2cEeprom, OneByteAddressingOverI2cRdwr) {
  FakeEeprom chip;
  round_trip(chip, 256);
  EXPECT_GE(chip.page_writes, 2 * 20 / 8);
}

TEST(StorageI2cEeprom, OneByteAddressingAcrossBlocksOnAnSmbusAdapter) {
  FakeEeprom chip;  // a 24c08: 1 KiB in four 256-byte blocks at 0x50..0x53
  chip.funcs = I2C_FUNC_SMBUS_QUICK | I2C_FUNC_SMBUS_I2C_BLOCK;
  chip.page = 16;
  round_trip(chip, 1024);
  EXPECT_EQ(chip.slave, 0x52);  // slot B starts at byte 512
}

TEST(StorageI2cEeprom, TwoByteAddressingWithLargePages) {
  FakeEeprom chip;  // a 24c32
  chip.address_bytes = 2;
  chip.page = 32;
  round_trip(chip, 4096);
}

TEST(StorageI2cEeprom, TwoByteAddressingOnAnSmbusAdapterIsUnsupported) {
  FakeEeprom chip;
  chip.funcs = I2C_FUNC_SMBUS_QUICK | I2C_FUNC_SMBUS_I2C_BLOCK;
  chip.address_bytes = 2;
  chip.memory.assign(4096, 0xFF);
  auto dev = open_fake(chip, 4096);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.error().code, Errc::kDevice);
  EXPECT_NE(dev.error().message.find("nvmem"), std::string::npos) << dev.error().message;
}

TEST(StorageI2cEeprom, AnAddressOwnedByAt24IsRefusedWithTheWayOut) {
  FakeEeprom chip;
  chip.at24_bound = true;
  chip.memory.assign(256, 0xFF);
  auto dev = open_fake(chip, 256);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.error().code, Errc::kDevice);
  EXPECT_NE(dev.error().message.find("at24"), std::string::npos) << dev.error().message;
}

TEST(StorageI2cEeprom, AChipThatNeverFinishesItsWriteCycleTimesOut) {
  FakeEeprom chip;
  chip.memory.assign(256, 0xFF);
  auto dev = open_fake(chip, 256, std::chrono::milliseconds(5));
  ASSERT_TRUE(dev.ok());
  chip.busy_polls = 0;
  ASSERT_TRUE((*dev)->write(0, pattern(4, 0)).ok());
  chip.stuck_busy = true;
  auto st = (*dev)->write(8, pattern(4, 0));
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, Errc::kDevice);  // the page write itself is not acknowledged
  chip.stuck_busy = false;
  chip.busy_polls = 1000000;
  st = (*dev)->write(8, pattern(4, 0));
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, Errc::kTimeout);
  EXPECT_NE(st.error().message.find("write cycle"), std::string::npos) << st.error().message;
}

TEST(StorageI2cEeprom, OptionsAreChecked) {
  FakeEeprom chip;
  chip.memory.assign(256, 0xFF);
  EXPECT_EQ(open_fake(chip, 4096).error().code, Errc::kInvalidArgument);  // 1-byte addressing reaches 2 KiB
  I2cEepromOptions o;
  o.size_bytes = 256;
  o.page_bytes = 12;
  EXPECT_EQ(open_i2c_eeprom_storage("/dev/i2c-9", o, std::make_unique<FakeEepromIo>(chip)).error().code,
            Errc::kInvalidArgument);
  o.page_bytes = 8;
  o.address = 0x68;
  EXPECT_EQ(open_i2c_eeprom_storage("/dev/i2c-9", o, std::make_unique<FakeEepromIo>(chip)).error().code,
            Errc::kInvalidArgument);
}

}  // namespace
}  // namespace imucal::drivers

namespace imucal::drivers {
namespace {

TEST(StorageConfigKeys, EepromGeometryIsParsedCheckedAndUsed) {
  const std::string base =
      "name: r\nimu:\n  bus: sim\nstorage:\n  backend: i2c-eeprom\n  i2c_device: /dev/i2c-99\n";
  auto ok = parse_rig_config(base + "  page_bytes: 8\n  address_bytes: 1\n  size_bytes: 256\n");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->storage.page_bytes, 8);
  EXPECT_EQ(ok->storage.address_bytes, 1);
  EXPECT_NE(rig_config_to_yaml(*ok).find("page_bytes: 8"), std::string::npos);
  auto again = parse_rig_config(rig_config_to_yaml(*ok));
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(again->storage.address_bytes, 1);
  auto dev = open_storage_device(ok->storage, StorageAccess::kRead);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.error().code, Errc::kDevice);
  EXPECT_NE(dev.error().message.find("i2c-dev"), std::string::npos) << dev.error().message;

  EXPECT_FALSE(parse_rig_config(base + "  page_bytes: 12\n").ok());
  EXPECT_FALSE(parse_rig_config(base + "  address_bytes: 3\n").ok());
  EXPECT_FALSE(parse_rig_config("imu:\n  bus: sim\nstorage:\n  backend: file\n  page_bytes: 8\n").ok());
}

}  // namespace
}  // namespace imucal::drivers
