// SPDX-License-Identifier: BSD-3-Clause
// Runs inside the QEMU guest (tests/qemu/run-in-qemu.sh) against the kernel's i2c-stub
// (chip_addr=0x68,0x50) through i2c-dev: I2cDevBus and the MPU-6000 driver on a real kernel
// I2C stack.
//
// i2c-stub is an SMBus-only adapter (no I2C_FUNC_I2C) holding a plain 256-byte register file
// per address: it stores what is written and returns it, with no chip behind it. So:
//  - the bus must choose SMBus transfers there, and bursts longer than 32 bytes are split;
//  - the MPU-6000's self-clearing DEVICE_RESET bit stays set: the driver must refuse the chip
//    (its "did not come up" error) rather than configure it;
//  - to check the configuration writes, one chip behaviour is emulated above the kernel
//    (ResetCompletingBus): writing DEVICE_RESET stores PWR_MGMT_1's after-reset value 0x40,
//    as the chip does once its reset is over. Every other access goes to the stub unchanged;
//  - the FIFO is a register file here: FIFO_COUNT and the frames are pre-seeded, and the
//    stub returns consecutive registers for a block read at FIFO_R_W (0x74).
// Prints one line per check, exits 0 only when all pass.

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string>
#include <vector>

#include "drivers/bus/i2cdev_bus.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "drivers/mpu6000/registers.hpp"

namespace {

using imucal::Errc;
using imucal::TimeNs;
using imucal::drivers::I2cDevBus;
using imucal::drivers::I2cDevOptions;
using imucal::drivers::I2cTransferMode;
using imucal::drivers::RegisterBus;
namespace mpu = imucal::drivers::mpu6000;

int failures = 0;

void check(bool ok, const std::string& what, const std::string& detail = "") {
  std::printf("%s - %s%s%s\n", ok ? "ok" : "FAIL", what.c_str(), detail.empty() ? "" : ": ", detail.c_str());
  if (!ok) ++failures;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

constexpr std::uint8_t reg(mpu::Register r) { return static_cast<std::uint8_t>(r); }

// Completes the chip reset the stub cannot perform; passes everything else through.
class ResetCompletingBus final : public RegisterBus {
 public:
  explicit ResetCompletingBus(RegisterBus& bus) : bus_(bus) {}
  imucal::Status read(std::uint8_t r, std::span<std::uint8_t> out) override { return bus_.read(r, out); }
  imucal::Status write(std::uint8_t r, std::uint8_t value) override {
    if (r == reg(mpu::Register::PWR_MGMT_1) && (value & mpu::DEVICE_RESET)) {
      ++resets;
      return bus_.write(r, mpu::kPwrMgmt1ResetValue);
    }
    return bus_.write(r, value);
  }
  void set_speed_hz(std::uint32_t hz) override { bus_.set_speed_hz(hz); }
  std::string name() const override { return bus_.name(); }
  const imucal::drivers::BusCounters& counters() const override { return bus_.counters(); }
  int resets = 0;

 private:
  RegisterBus& bus_;
};

bool seed(RegisterBus& bus, const std::vector<std::pair<std::uint8_t, std::uint8_t>>& values) {
  for (auto [r, v] : values) {
    if (!bus.write(r, v).ok()) return false;
  }
  return true;
}

// Runs the driver on a virtual clock until it streams, fails, or `max_polls` pass.
imucal::Status run_until_stream(mpu::Mpu6000& driver, TimeNs& now_ns, int max_polls) {
  for (int i = 0; i < max_polls && driver.state() != mpu::State::kStream; ++i) {
    auto r = driver.poll(now_ns);
    if (!r.ok()) return r.error();
    now_ns = std::max(now_ns + 1, r->next_poll_ns);
  }
  return {};
}

void bus_checks(I2cDevBus& bus) {
  check(bus.mode() == I2cTransferMode::kSmbus, "i2c-stub is driven with SMBus transfers",
        std::string("mode ") + imucal::drivers::i2c_transfer_mode_name(bus.mode()));
  check((bus.functionality() & 0x1) == 0, "i2c-stub reports no I2C_FUNC_I2C");

  // Every register: write a pattern byte by byte, read it back one by one and in bursts.
  bool writes_ok = true;
  for (int r = 0; r < 256; ++r)
    writes_ok &= bus.write(static_cast<std::uint8_t>(r), static_cast<std::uint8_t>(r ^ 0x5A)).ok();
  check(writes_ok, "256 byte writes");
  int mismatches = 0;
  for (int r = 0; r < 256; ++r) {
    auto v = bus.read_u8(static_cast<std::uint8_t>(r));
    if (!v.ok() || *v != (r ^ 0x5A)) ++mismatches;
  }
  check(mismatches == 0, "256 single-byte reads return what was written",
        std::to_string(mismatches) + " mismatches");

  std::array<std::uint8_t, 14> sensor{};
  bool ok = bus.read(0x3B, sensor).ok();
  for (int i = 0; i < 14 && ok; ++i) ok = sensor[i] == ((0x3B + i) ^ 0x5A);
  check(ok, "14-byte sensor burst at 0x3B");

  std::vector<std::uint8_t> long_burst(100);
  const auto before = bus.counters().transfers;
  ok = bus.read(0x10, long_burst).ok();
  for (int i = 0; i < 100 && ok; ++i) ok = long_burst[i] == ((0x10 + i) ^ 0x5A);
  check(ok, "100-byte burst at 0x10 split into SMBus blocks");
  check(bus.counters().transfers - before == 4, "100-byte burst took 4 block transfers",
        std::to_string(bus.counters().transfers - before));

  // FIFO_R_W does not advance between blocks: the second block starts at 0x74 again.
  std::vector<std::uint8_t> fifo(40);
  ok = bus.read(0x74, fifo).ok();
  for (int i = 0; i < 40 && ok; ++i) ok = fifo[i] == ((0x74 + (i % 32)) ^ 0x5A);
  check(ok, "40-byte FIFO_R_W read restarts each block at 0x74");

  check(bus.counters().transfer_errors == 0 && bus.counters().short_transfers == 0,
        "no transfer errors counted");
}

void error_checks() {
  auto missing = I2cDevBus::open("/dev/i2c-9");
  check(!missing.ok() && missing.error().code == Errc::kNotFound &&
            contains(missing.error().message, "/dev/i2c-9"),
        "missing adapter: kNotFound naming the device", missing.ok() ? "opened" : missing.error().message);

  I2cDevOptions rdwr;
  rdwr.mode = I2cTransferMode::kI2cRdwr;
  auto forced = I2cDevBus::open("/dev/i2c-0", rdwr);
  check(!forced.ok() && forced.error().code == Errc::kUnsupported,
        "I2C_RDWR mode refused on the SMBus-only adapter", forced.ok() ? "opened" : forced.error().message);

  I2cDevOptions other;
  other.address = 0x69;  // no stub chip there
  auto absent = I2cDevBus::open("/dev/i2c-0", other);
  check(absent.ok(), "open at 0x69 (nothing there yet: i2c-dev cannot tell)");
  if (absent.ok()) {
    auto v = (*absent)->read_u8(0x75);
    check(!v.ok() && contains(v.error().message, "AD0"), "read at an empty address fails and names AD0",
          v.ok() ? "read succeeded" : v.error().message);
    check((*absent)->counters().transfer_errors == 1, "the failure is counted");
  }
}

/// A FIFO read through i2c-dev, from a driver that streams: frames decoded, the newest kept back.
void fifo_read_checks(I2cDevBus& bus, mpu::Mpu6000& driver, const mpu::Settings& settings, TimeNs now_ns,
                      std::int16_t temp_raw) {
  // FIFO: three frames behind FIFO_COUNT = 42; the driver reads all but the newest, which it
  // leaves in the FIFO (docs/mpu6000.md). The stub returns registers 0x74.. for the block read,
  // so the frames are seeded there. Byte 1 lands on WHO_AM_I (0x75): the first sample's accel x
  // (0x1068) keeps it at 0x68. The stub's FIFO_COUNT does not go down after the read, which the
  // driver takes for frames that arrived meanwhile.
  std::array<std::uint8_t, 42> frames{};
  for (int f = 0; f < 3; ++f) {
    std::uint8_t* p = frames.data() + 14 * f;
    const std::int16_t values[7] = {static_cast<std::int16_t>(0x1068 + f),
                                    static_cast<std::int16_t>(-200 - f),
                                    4096,
                                    temp_raw,
                                    static_cast<std::int16_t>(10 + f),
                                    -20,
                                    static_cast<std::int16_t>(300 * (f + 1))};
    for (int i = 0; i < 7; ++i) {
      p[2 * i] = static_cast<std::uint8_t>(static_cast<std::uint16_t>(values[i]) >> 8);
      p[2 * i + 1] = static_cast<std::uint8_t>(static_cast<std::uint16_t>(values[i]) & 0xFF);
    }
  }
  std::vector<std::pair<std::uint8_t, std::uint8_t>> fifo_seed{{reg(mpu::Register::FIFO_COUNTH), 0},
                                                               {reg(mpu::Register::FIFO_COUNTH) + 1, 42}};
  for (int i = 0; i < 42; ++i) fifo_seed.emplace_back(static_cast<std::uint8_t>(0x74 + i), frames[i]);
  check(seed(bus, fifo_seed), "seed FIFO_COUNT = 42 and three frames");
  auto polled = driver.poll(now_ns + settings.read_interval_ns);
  const bool got = polled.ok() && polled->batch && polled->batch->samples.size() == 2;
  check(got, "one FIFO read yields two samples, the newest frame stays in the FIFO",
        polled.ok()
            ? (polled->batch ? std::to_string(polled->batch->samples.size()) + " samples" : "no batch")
            : polled.error().message);
  if (got) {
    const auto& a = polled->batch->samples[0];
    const auto& b = polled->batch->samples[1];
    check(a.accel[0] == 0x1068 && a.accel[1] == -200 && a.accel[2] == 4096 && a.temp == temp_raw &&
              a.gyro[0] == 10 && a.gyro[1] == -20 && a.gyro[2] == 300,
          "first sample decoded from the FIFO bytes");
    check(b.accel[0] == 0x1069 && b.accel[1] == -201 && b.gyro[0] == 11 && b.gyro[2] == 600,
          "second sample decoded from the FIFO bytes");
    check((a.flags & imucal::kImuFlagDeviceReset) != 0, "first sample after configuration flagged as reset");
  }
  check(driver.counters().bad_transfers == 0, "driver counted no bad transfers",
        std::to_string(driver.counters().bad_transfers));
}

void driver_checks(I2cDevBus& bus) {
  mpu::Settings settings;
  settings.bus = mpu::BusKind::kI2c;
  settings.accel_range = mpu::AccelRange::k8g;
  settings.gyro_range = mpu::GyroRange::k1000dps;
  settings.dlpf_cfg = 2;
  settings.smplrt_div = 4;  // 200 Hz
  settings.read_interval_ns = 5'000'000;
  const imucal::Status valid = settings.validate();
  check(valid.ok(), "driver settings valid", valid.ok() ? "" : valid.error().message);

  // Probe: WHO_AM_I.
  check(seed(bus, {{reg(mpu::Register::WHO_AM_I), 0x70}}), "seed WHO_AM_I = 0x70");
  {
    mpu::Mpu6000 driver(bus, settings);
    auto p = driver.probe();
    check(!p.ok() && p.error().code == Errc::kDevice && contains(p.error().message, "0x70"),
          "probe refuses WHO_AM_I 0x70", p.ok() ? "accepted" : p.error().message);
  }
  std::vector<std::pair<std::uint8_t, std::uint8_t>> chip;
  for (int r = 0; r < 256; ++r) chip.emplace_back(static_cast<std::uint8_t>(r), 0);
  chip[reg(mpu::Register::WHO_AM_I)].second = mpu::WHOAMI;
  chip[reg(mpu::Register::PWR_MGMT_1)].second = mpu::kPwrMgmt1ResetValue;
  check(seed(bus, chip), "seed a power-on register file (WHO_AM_I 0x68, PWR_MGMT_1 0x40)");
  {
    mpu::Mpu6000 driver(bus, settings);
    auto p = driver.probe();
    check(p.ok(), "probe accepts WHO_AM_I 0x68", p.ok() ? "" : p.error().message);
  }

  // Reset on the bare stub: DEVICE_RESET never clears, the driver must give up with an error.
  {
    mpu::Mpu6000 driver(bus, settings);
    TimeNs now_ns = 1'000'000'000;
    auto s = run_until_stream(driver, now_ns, 10'000);
    check(!s.ok() && s.error().code == Errc::kDevice && contains(s.error().message, "did not come up") &&
              contains(s.error().message, "PWR_MGMT_1 reads 0x80"),
          "reset bit that never clears: driver reports the chip did not come up",
          s.ok() ? "no error" : s.error().message);
    check(driver.state() != mpu::State::kStream, "driver did not stream");
    auto pwr = bus.read_u8(reg(mpu::Register::PWR_MGMT_1));
    check(pwr.ok() && *pwr == mpu::DEVICE_RESET, "the stub holds the DEVICE_RESET write (0x80)");
  }

  // With the reset completed above the kernel: configuration goes through i2c-dev and reads back.
  check(seed(bus, chip), "re-seed the power-on register file");
  const std::int16_t temp_raw = -3920;  // 25 deg C: (25 - 36.53) * 340
  const auto t_hi = static_cast<std::uint8_t>(static_cast<std::uint16_t>(temp_raw) >> 8);
  const auto t_lo = static_cast<std::uint8_t>(static_cast<std::uint16_t>(temp_raw) & 0xFF);
  check(seed(bus, {{reg(mpu::Register::TEMP_OUT_H), t_hi}, {reg(mpu::Register::TEMP_OUT_H) + 1, t_lo}}),
        "seed TEMP_OUT = 25 deg C");
  ResetCompletingBus chip_bus(bus);
  mpu::Mpu6000 driver(chip_bus, settings);
  TimeNs now_ns = 1'000'000'000;
  auto s = run_until_stream(driver, now_ns, 10'000);
  check(s.ok() && driver.state() == mpu::State::kStream, "driver configures the chip and streams",
        s.ok() ? mpu::state_name(driver.state()) : s.error().message);
  check(chip_bus.resets == 1, "one reset", std::to_string(chip_bus.resets));
  int bad_rows = 0;
  for (const auto& row : driver.config_rows()) {
    auto v = bus.read_u8(reg(row.reg));
    const bool good = v.ok() && (*v & row.set_bits) == row.set_bits && (*v & row.clear_bits) == 0;
    if (!good) {
      ++bad_rows;
      std::printf("  register 0x%02X reads 0x%02X (set 0x%02X clear 0x%02X)\n", reg(row.reg), v.ok() ? *v : 0,
                  row.set_bits, row.clear_bits);
    }
  }
  check(bad_rows == 0, "every configuration row reads back from the stub",
        std::to_string(bad_rows) + " wrong");
  auto smplrt = bus.read_u8(reg(mpu::Register::SMPLRT_DIV));
  check(smplrt.ok() && *smplrt == 4, "SMPLRT_DIV = 4 in the stub");

  fifo_read_checks(bus, driver, settings, now_ns, temp_raw);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string device = argc > 1 ? argv[1] : "/dev/i2c-0";
  auto bus = I2cDevBus::open(device);
  if (!bus.ok()) {
    std::printf("FAIL - open %s: %s\n", device.c_str(), bus.error().message.c_str());
    return 1;
  }
  check(true, "open " + (*bus)->name());
  bus_checks(**bus);
  error_checks();
  driver_checks(**bus);
  std::printf("%s: %d failed check(s)\n", failures == 0 ? "PASS" : "FAIL", failures);
  return failures == 0 ? 0 : 1;
}
