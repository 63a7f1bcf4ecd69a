// SPDX-License-Identifier: BSD-3-Clause
// Runs inside the QEMU guest (tests/qemu/run-in-qemu.sh) with i2c-stub (chip_addr=0x50), i2c-dev
// and at24: the calibration store on a real kernel I2C stack, through both EEPROM backends.
//
// i2c-stub is an SMBus-only adapter with a 256-byte register file at 0x50 and 8-bit register
// addresses, which is what a 24c02 looks like to at24 (SMBus I2C-block reads and writes). So:
//  1. raw i2c-eeprom backend on /dev/i2c-0 (SMBus path, 1-byte addressing, 8-byte pages): two
//     records, alternating slots; then writes cut after k bytes (the first k bytes of a record
//     written, nothing else) leave the previous record readable;
//  2. `24c02 0x50` instantiated through sysfs new_device: at24 binds and an nvmem device appears;
//     the nvmem backend reads the record the raw backend wrote, and writes the next one; the raw
//     backend is now refused (EBUSY: at24 owns the address);
//  3. the at24 device deleted: the raw backend reads what at24 wrote.
// The stub has no write cycle, so ACK polling returns at once here (its timeout path is tested
// against a fake kernel in tests/drivers). Prints one line per check, exits 0 only when all pass.

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/record.hpp"
#include "drivers/storage/storage_device.hpp"

namespace {

namespace fs = std::filesystem;
using imucal::drivers::CalibrationStore;
using imucal::drivers::StorageDevice;
using Bytes = std::vector<std::uint8_t>;

int failures = 0;

bool check(bool ok, const std::string& what, const std::string& detail = "") {
  std::printf("%s - %s%s%s\n", ok ? "ok" : "FAIL", what.c_str(), detail.empty() ? "" : ": ", detail.c_str());
  if (!ok) ++failures;
  return ok;
}

Bytes payload(std::uint8_t tag, std::size_t n) {
  Bytes p(n);
  std::iota(p.begin(), p.end(), tag);
  return p;
}

std::unique_ptr<StorageDevice> open_raw(const std::string& device) {
  imucal::drivers::I2cEepromOptions o;
  o.address = 0x50;
  o.size_bytes = 256;
  o.page_bytes = 8;
  o.address_bytes = 1;
  auto dev = imucal::drivers::open_i2c_eeprom_storage(device, o);
  if (!check(dev.ok(), "open raw i2c-eeprom " + device, dev.ok() ? (*dev)->name() : dev.error().message))
    return nullptr;
  return std::move(dev).value();
}

// Reads the newest record and checks its sequence and payload.
void expect_latest(StorageDevice& dev, std::uint32_t sequence, const Bytes& p, const std::string& what) {
  auto store = CalibrationStore::open(dev, 0, 256);
  auto latest = store->read_latest();
  if (!check(latest.ok(), what + ": read", latest.ok() ? "" : latest.error().message)) return;
  const bool ok = latest->record && latest->record->sequence == sequence && latest->record->payload == p;
  check(ok, what + ": newest record is sequence " + std::to_string(sequence),
        latest->record ? "slot " + std::string(imucal::drivers::slot_name(latest->slot)) + ", sequence " +
                             std::to_string(latest->record->sequence)
                       : "none");
}

void raw_checks(StorageDevice& dev, const Bytes& p1, const Bytes& p2) {
  auto store = CalibrationStore::open(dev, 0, 256);
  check(store.ok(), "store on 256 bytes (slots of 128)");
  auto w1 = store->write(p1);
  check(w1.ok() && w1->slot == 0 && w1->sequence == 1, "raw write 1 -> slot A",
        w1.ok() ? "" : w1.error().message);
  auto w2 = store->write(p2);
  check(w2.ok() && w2->slot == 1 && w2->sequence == 2, "raw write 2 -> slot B",
        w2.ok() ? "" : w2.error().message);
  expect_latest(dev, 2, p2, "raw");
  // Power cuts at the kernel level: only the first k bytes of record 3 reach slot A.
  const Bytes p3 = payload(77, 90);
  const Bytes rec = imucal::drivers::encode_record(3, p3);
  int kept_old = 0, tried = 0;
  for (std::size_t k :
       {std::size_t{1}, std::size_t{9}, std::size_t{23}, std::size_t{24}, std::size_t{60}, rec.size() - 1}) {
    if (!dev.write(0, std::span<const std::uint8_t>(rec).first(k)).ok()) continue;
    ++tried;
    auto latest = store->read_latest();
    if (latest.ok() && latest->record && latest->record->sequence == 2 && latest->record->payload == p2)
      ++kept_old;
  }
  check(tried == 6 && kept_old == 6, "writes cut after 1, 9, 23, 24, 60, n-1 bytes leave sequence 2 readable",
        std::to_string(kept_old) + " of " + std::to_string(tried));
  auto w3 = store->write(p3);
  check(w3.ok() && w3->slot == 0 && w3->sequence == 3, "after the cuts, write 3 -> slot A");
  auto w4 = store->write(p2);
  check(w4.ok() && w4->slot == 1 && w4->sequence == 4, "write 4 -> slot B");
}

bool write_sysfs(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
  f.flush();
  return static_cast<bool>(f);
}

std::string find_nvmem() {
  for (int i = 0; i < 50; ++i) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator("/sys/bus/nvmem/devices", ec)) {
      if (e.path().filename().string().rfind("0-0050", 0) == 0) return (e.path() / "nvmem").string();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return {};
}

void nvmem_checks(const std::string& bus, const Bytes& p2) {
  if (!check(write_sysfs("/sys/bus/i2c/devices/" + bus + "/new_device", "24c02 0x50"),
             "bind at24 as 24c02 at 0x50"))
    return;
  const std::string nvmem = find_nvmem();
  if (!check(!nvmem.empty(), "nvmem device appears", nvmem)) return;
  imucal::StorageConfig c;
  c.backend = imucal::StorageBackend::kNvmem;
  c.path = nvmem;
  c.size_bytes = 256;
  auto dev = imucal::drivers::open_storage_device(c, imucal::drivers::StorageAccess::kWrite);
  if (!check(dev.ok(), "open nvmem " + nvmem, dev.ok() ? "" : dev.error().message)) return;
  check((*dev)->size() == 256, "nvmem size is the 24c02's 256 bytes", std::to_string((*dev)->size()));
  expect_latest(**dev, 4, p2, "nvmem reads what the raw backend wrote");
  auto store = CalibrationStore::open(**dev, 0, 256);
  const Bytes p5 = payload(150, 100);
  auto w5 = store->write(p5);
  check(w5.ok() && w5->slot == 0 && w5->sequence == 5, "nvmem write 5 -> slot A (synced, read back)",
        w5.ok() ? "" : w5.error().message);
  c.size_bytes = 512;
  auto big = imucal::drivers::open_storage_device(c, imucal::drivers::StorageAccess::kRead);
  check(!big.ok() && big.error().message.find("256 bytes") != std::string::npos,
        "a region larger than the EEPROM is refused", big.ok() ? "accepted" : big.error().message);
  auto raw = imucal::drivers::open_i2c_eeprom_storage("/dev/" + bus,
                                                      {0x50, 256, 8, 1, std::chrono::milliseconds(25)});
  check(!raw.ok() && raw.error().message.find("at24") != std::string::npos,
        "raw backend refused while at24 is bound", raw.ok() ? "opened" : raw.error().message);
  dev->reset();
  check(write_sysfs("/sys/bus/i2c/devices/" + bus + "/delete_device", "0x50"), "unbind at24");
}

}  // namespace

int main(int argc, char** argv) {
  if (std::getenv("IMUCAL_IN_QEMU") == nullptr) {
    std::printf(
        "SKIP: runs inside the QEMU guest only (tests/qemu/run-in-qemu.sh); it binds at24 through sysfs\n");
    return 77;
  }
  const std::string device = argc > 1 ? argv[1] : "/dev/i2c-0";
  const std::string bus = fs::path(device).filename().string();
  const Bytes p1 = payload(1, 100), p2 = payload(50, 104);  // 104 = the most a 128-byte slot holds
  {
    auto raw = open_raw(device);
    if (!raw) return 1;
    raw_checks(*raw, p1, p2);
  }
  nvmem_checks(bus, p2);
  if (auto raw = open_raw(device)) expect_latest(*raw, 5, payload(150, 100), "raw reads what at24 wrote");
  std::printf("%s: %d failed check(s)\n", failures == 0 ? "PASS" : "FAIL", failures);
  return failures == 0 ? 0 : 1;
}
