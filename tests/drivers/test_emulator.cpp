// SPDX-License-Identifier: BSD-3-Clause
// The MPU-6000 register emulator on its own: reset values, rates, FIFO semantics, oscillator,
// quantization, bus timing. These pin down the behaviour the driver tests rely on.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/registers.hpp"

namespace imucal {
namespace {

using namespace drivers::mpu6000;
using fake::EmulatorOptions;
using fake::Mpu6000Emulator;
using fake::SensorReading;

constexpr TimeNs kMs = 1'000'000;
constexpr TimeNs kS = 1'000'000'000;

SensorReading ramp_source(TimeNs t_ns) {
  SensorReading r;
  const double t = ns_to_s(t_ns);
  r.specific_force = {t, -t, kStandardGravity};
  r.angular_rate = {0.1, 0.2, 2.0 * t};
  r.temperature_c = 25.0;
  return r;
}

EmulatorOptions untimed() {
  EmulatorOptions o;
  o.timing.enabled = false;
  return o;
}

std::uint8_t rd(Mpu6000Emulator& e, Register r) {
  auto v = e.read_u8(reg_addr(r));
  EXPECT_TRUE(v.ok());
  return v.ok() ? *v : 0;
}

void wr(Mpu6000Emulator& e, Register r, std::uint8_t v) { ASSERT_TRUE(e.write(reg_addr(r), v).ok()); }

/// Wakes the chip with the given rate configuration and the FIFO on (no timing model).
void wake(Mpu6000Emulator& e, std::uint8_t dlpf, std::uint8_t div, bool fifo = true) {
  wr(e, Register::CONFIG, dlpf);
  wr(e, Register::SMPLRT_DIV, div);
  if (fifo) {
    wr(e, Register::FIFO_EN, TEMP_FIFO_EN | XG_FIFO_EN | YG_FIFO_EN | ZG_FIFO_EN | ACCEL_FIFO_EN);
    wr(e, Register::USER_CTRL, FIFO_EN);
  }
  wr(e, Register::PWR_MGMT_1, CLKSEL_PLL_GYRO_X);
}

TEST(Mpu6000Emulator, ResetValues) {
  Mpu6000Emulator e(ramp_source, untimed());
  EXPECT_EQ(rd(e, Register::WHO_AM_I), WHOAMI);
  EXPECT_EQ(rd(e, Register::PWR_MGMT_1), 0x40);
  EXPECT_EQ(rd(e, Register::GYRO_CONFIG), 0);
  EXPECT_EQ(rd(e, Register::USER_CTRL), 0);
  EXPECT_EQ(rd(e, Register::FIFO_COUNTH), 0);
  EXPECT_TRUE(e.sleeping());
  // Asleep: no samples.
  e.advance_to(100 * kMs);
  EXPECT_EQ(e.stats().samples, 0u);
  // DEVICE_RESET restores the reset values and ignores the bus while it runs.
  wake(e, 1, 0);
  wr(e, Register::GYRO_CONFIG, 0x18);
  wr(e, Register::PWR_MGMT_1, DEVICE_RESET);
  EXPECT_EQ(rd(e, Register::WHO_AM_I), 0) << "busy right after DEVICE_RESET";
  e.advance_to(e.now_ns() + 20 * kMs);
  EXPECT_EQ(rd(e, Register::WHO_AM_I), WHOAMI);
  EXPECT_EQ(rd(e, Register::GYRO_CONFIG), 0);
  EXPECT_EQ(rd(e, Register::PWR_MGMT_1), 0x40);
}

TEST(Mpu6000Emulator, SampleRatesFollowDlpfAndDivider) {
  struct Case {
    std::uint8_t dlpf, div;
    std::uint64_t per_second;
  };
  for (const Case c :
       {Case{0, 0, 8000}, Case{1, 0, 1000}, Case{0, 7, 1000}, Case{3, 4, 200}, Case{6, 9, 100}}) {
    Mpu6000Emulator e(ramp_source, untimed());
    wake(e, c.dlpf, c.div, false);
    const TimeNs t0 = e.now_ns();
    e.advance_to(t0 + kS);
    EXPECT_EQ(e.stats().samples, c.per_second) << "dlpf " << int(c.dlpf) << " div " << int(c.div);
  }
}

TEST(Mpu6000Emulator, AccelRepeatsAt8kHz) {
  Mpu6000Emulator e(ramp_source, untimed());
  wake(e, 0, 0, false);
  e.advance_to(e.now_ns() + 10 * kMs);
  const auto& t = e.truth();
  ASSERT_EQ(t.size(), 80u);
  int accel_changes = 0, gyro_changes = 0;
  for (std::size_t i = 1; i < t.size(); ++i) {
    accel_changes += t[i].accel != t[i - 1].accel;
    gyro_changes += t[i].gyro != t[i - 1].gyro;
    EXPECT_LE(t[i].accel_t_ns, t[i].t_ns);
    EXPECT_GT(t[i].t_ns - t[i].accel_t_ns, -1);
    EXPECT_LT(t[i].t_ns - t[i].accel_t_ns, 1 * kMs);
  }
  EXPECT_EQ(accel_changes, 10);  // new accel value once per millisecond
  EXPECT_GE(gyro_changes, 70);
}

TEST(Mpu6000Emulator, OscillatorOffsetShiftsSampleTimes) {
  EmulatorOptions o = untimed();
  o.clock_ppm = 100.0;  // the chip runs fast
  Mpu6000Emulator e(ramp_source, o);
  wake(e, 1, 0, false);
  const TimeNs t0 = e.now_ns();
  e.advance_to(t0 + 2 * kS);
  const auto& t = e.truth();
  ASSERT_GE(t.size(), 2000u);
  // Sample k is at k ms of chip time = k / (1 + 1e-4) ms of host time.
  EXPECT_EQ(t[1999].t_ns - t0, std::llround(2000.0 * 1e6 / 1.0001));
  EXPECT_EQ(t.size(), 2000u);  // 2000.2 samples' worth in 2 s
}

TEST(Mpu6000Emulator, QuantizesAndSaturatesAtTheConfiguredRange) {
  auto source = [](TimeNs) {
    SensorReading r;
    r.specific_force = {0.5 * kStandardGravity, 5.0 * kStandardGravity, -1.0 * kStandardGravity};
    r.angular_rate = {std::numbers::pi, -40.0, 0.0};  // 180 dps, beyond 2000 dps
    r.temperature_c = 36.53 + 10.0;
    return r;
  };
  Mpu6000Emulator e(source, untimed());
  wr(e, Register::ACCEL_CONFIG, static_cast<std::uint8_t>(AccelRange::k4g) << 3);
  wr(e, Register::GYRO_CONFIG, static_cast<std::uint8_t>(GyroRange::k2000dps) << 3);
  wake(e, 1, 0, false);
  e.advance_to(e.now_ns() + 2 * kMs);
  std::array<std::uint8_t, 14> b{};
  ASSERT_TRUE(e.read(reg_addr(Register::ACCEL_XOUT_H), b).ok());
  EXPECT_EQ(be16(b[0], b[1]), 4096);   // 0.5 g at 8192 LSB/g
  EXPECT_EQ(be16(b[2], b[3]), 32767);  // 5 g saturates
  EXPECT_EQ(be16(b[4], b[5]), -8192);
  EXPECT_EQ(be16(b[6], b[7]), 3400);  // 10 deg C above the offset
  EXPECT_EQ(be16(b[8], b[9]), 2952);  // 180 dps at 16.4 LSB/dps
  EXPECT_EQ(be16(b[10], b[11]), -32768);
  EXPECT_EQ(be16(b[12], b[13]), 0);
}

TEST(Mpu6000Emulator, FifoOverflowOverwritesOldestAndSetsStatus) {
  Mpu6000Emulator e(ramp_source, untimed());
  wake(e, 1, 0);
  e.advance_to(e.now_ns() + 50 * kMs + kMs / 2);  // 50 frames
  EXPECT_EQ(e.fifo_bytes(), 700u);
  EXPECT_EQ(rd(e, Register::INT_STATUS) & FIFO_OFLOW_INT, 0);
  e.advance_to(e.now_ns() + 50 * kMs);  // 100 frames > 73
  EXPECT_EQ(e.fifo_bytes(), 1024u);
  std::array<std::uint8_t, 2> count{};
  ASSERT_TRUE(e.read(reg_addr(Register::FIFO_COUNTH), count).ok());
  EXPECT_EQ((count[0] << 8) | count[1], 1024);
  const std::uint8_t status = rd(e, Register::INT_STATUS);
  EXPECT_TRUE(status & FIFO_OFLOW_INT);
  EXPECT_TRUE(status & DATA_RDY_INT);
  EXPECT_EQ(rd(e, Register::INT_STATUS), 0) << "reading INT_STATUS clears it";
  // The newest bytes survive: the last 14 bytes are the last frame.
  std::vector<std::uint8_t> all(1024);
  ASSERT_TRUE(e.read(reg_addr(Register::FIFO_R_W), all).ok());
  const auto& last = e.truth().back();
  const std::uint8_t* f = all.data() + 1024 - 14;
  EXPECT_EQ(be16(f[0], f[1]), last.accel[0]);
  EXPECT_EQ(be16(f[6], f[7]), last.temp);
  EXPECT_EQ(be16(f[12], f[13]), last.gyro[2]);
  EXPECT_EQ(e.stats().fifo_bytes_overwritten, 100u * 14 - 1024);
  EXPECT_EQ(e.fifo_bytes(), 0u);
}

TEST(Mpu6000Emulator, FifoResetNeedsFifoDisabled) {
  Mpu6000Emulator e(ramp_source, untimed());
  wake(e, 1, 0);
  e.advance_to(e.now_ns() + 10 * kMs + kMs / 2);
  EXPECT_EQ(e.fifo_bytes(), 140u);
  wr(e, Register::USER_CTRL, FIFO_EN | FIFO_RESET);  // RM 4.27: no effect while FIFO_EN is 1
  EXPECT_EQ(e.fifo_bytes(), 140u);
  wr(e, Register::USER_CTRL, FIFO_RESET);
  EXPECT_EQ(e.fifo_bytes(), 0u);
  EXPECT_EQ(rd(e, Register::USER_CTRL) & FIFO_RESET, 0) << "self-clearing";
}

TEST(Mpu6000Emulator, FifoFrameOrderAndByteOrder) {
  auto source = [](TimeNs) {
    SensorReading r;
    r.specific_force = Eigen::Vector3d(1.0, 2.0, 3.0) * kStandardGravity / 16384.0 * 0x0102;
    r.angular_rate = Eigen::Vector3d(1.0, 2.0, 3.0) * (std::numbers::pi / 180.0) / 131.0 * 0x0304;
    r.temperature_c = 36.53 + 0x0506 / 340.0;
    return r;
  };
  Mpu6000Emulator e(source, untimed());
  wake(e, 1, 0);
  e.advance_to(e.now_ns() + kMs);
  std::array<std::uint8_t, 14> f{};
  ASSERT_TRUE(e.read(reg_addr(Register::FIFO_R_W), f).ok());
  const std::array<std::uint8_t, 14> expected = {0x01, 0x02, 0x02, 0x04, 0x03, 0x06, 0x05,
                                                 0x06, 0x03, 0x04, 0x06, 0x08, 0x09, 0x0C};
  EXPECT_EQ(f, expected);
}

TEST(Mpu6000Emulator, OffsetAndSelfTestRegistersChangeTheOutput) {
  auto source = [](TimeNs) { return SensorReading{}; };
  Mpu6000Emulator e(source, untimed());
  wake(e, 1, 0, false);
  e.advance_to(e.now_ns() + 2 * kMs);
  EXPECT_EQ(e.truth().back().gyro[0], 0);
  wr(e, Register::XG_OFFS_USRH, 0x00);
  wr(e, Register::XG_OFFS_USRL, 100);  // at +-250 dps: 4 output LSB per offset LSB
  e.advance_to(e.now_ns() + 2 * kMs);
  EXPECT_EQ(e.truth().back().gyro[0], 400);
  wr(e, Register::GYRO_CONFIG, XG_ST);
  e.advance_to(e.now_ns() + 2 * kMs);
  EXPECT_EQ(e.truth().back().gyro[0], 400 + std::lround(e.gyro_factory_trim()[0]));
  const auto st = rd(e, Register::SELF_TEST_X);
  EXPECT_EQ(st & 0x1F, 13);
}

TEST(Mpu6000Emulator, BusTimingModel) {
  const fake::BusTiming spi = fake::BusTiming::spi();
  // 14 FIFO bytes + address byte at 20 MHz: 6 us, plus 20 us per transfer.
  EXPECT_EQ(spi.transfer_ns(14, true, 20'000'000), 26'000);
  EXPECT_EQ(spi.transfer_ns(1, false, 1'000'000), 36'000);
  const fake::BusTiming i2c = fake::BusTiming::i2c();
  // (14 + 3) bytes x 9 bits at 400 kHz = 382.5 us, plus 50 us.
  EXPECT_EQ(i2c.transfer_ns(14, true, 20'000'000), 432'500);

  Mpu6000Emulator e(ramp_source);
  const TimeNs t0 = e.now_ns();
  e.set_speed_hz(1'000'000);
  ASSERT_TRUE(e.read_u8(reg_addr(Register::WHO_AM_I)).ok());
  EXPECT_EQ(e.now_ns() - t0, 36'000);
  EXPECT_EQ(e.stats().bus_busy_ns, 36'000);
  EXPECT_EQ(e.stats().speed_violations, 0u);
  e.set_speed_hz(20'000'000);
  ASSERT_TRUE(e.read_u8(reg_addr(Register::WHO_AM_I)).ok());
  EXPECT_EQ(e.stats().speed_violations, 1u) << "WHO_AM_I is not a sensor register: 1 MHz only";
  ASSERT_TRUE(e.read_u8(reg_addr(Register::INT_STATUS)).ok());
  EXPECT_EQ(e.stats().speed_violations, 1u);
}

TEST(Mpu6000Emulator, I2cInterfaceDisableCutsOffI2c) {
  EmulatorOptions o = untimed();
  o.bus = BusKind::kI2c;
  Mpu6000Emulator e(ramp_source, o);
  wr(e, Register::USER_CTRL, I2C_IF_DIS);
  auto v = e.read_u8(reg_addr(Register::WHO_AM_I));
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.error().message.find("I2C_IF_DIS"), std::string::npos);
}

TEST(Mpu6000Emulator, InjectedFaults) {
  Mpu6000Emulator e(ramp_source, untimed());
  e.fail_next_transfers(2);
  EXPECT_FALSE(e.read_u8(reg_addr(Register::WHO_AM_I)).ok());
  EXPECT_FALSE(e.write(reg_addr(Register::GYRO_CONFIG), 0x18).ok());
  EXPECT_EQ(rd(e, Register::GYRO_CONFIG), 0) << "a failed write changes nothing";
  EXPECT_EQ(e.counters().transfer_errors, 2u);
  e.corrupt_next_read(fake::Corruption::kStuckHigh);
  EXPECT_EQ(rd(e, Register::WHO_AM_I), 0xFF);
  EXPECT_EQ(rd(e, Register::WHO_AM_I), WHOAMI);
  wake(e, 1, 0);
  e.advance_to(e.now_ns() + 5 * kMs + kMs / 2);
  e.spontaneous_reset();
  EXPECT_TRUE(e.sleeping());
  EXPECT_EQ(e.fifo_bytes(), 0u);
  const auto n = e.stats().samples;
  e.advance_to(e.now_ns() + 10 * kMs);
  EXPECT_EQ(e.stats().samples, n);
}

// A byte slip at offset k of a FIFO burst: the host gets bytes 0..k-1, then the FIFO's bytes
// from k + 1 on; the FIFO is one byte short of whole frames afterwards.
TEST(Mpu6000Emulator, ByteSlipLosesOneFifoByteAtTheGivenOffset) {
  for (const std::size_t at :
       {std::size_t{0}, std::size_t{7}, std::size_t{20}, std::size_t{27}, std::size_t{500}}) {
    Mpu6000Emulator e(ramp_source, untimed());
    wake(e, 1, 0);
    e.advance_to(e.now_ns() + 3 * kMs + kMs / 2);  // 3 frames
    ASSERT_EQ(e.fifo_bytes(), 42u);
    std::vector<std::uint8_t> clean(42);
    {
      Mpu6000Emulator ref(ramp_source, untimed());
      wake(ref, 1, 0);
      ref.advance_to(ref.now_ns() + 3 * kMs + kMs / 2);
      ASSERT_TRUE(ref.read(reg_addr(Register::FIFO_R_W), clean).ok());
    }
    e.corrupt_next_read(fake::Corruption::kByteSlip, at);
    std::vector<std::uint8_t> got(28);
    ASSERT_TRUE(e.read(reg_addr(Register::FIFO_R_W), got).ok());
    const std::size_t k = std::min<std::size_t>(at, got.size() - 1);
    for (std::size_t i = 0; i < got.size(); ++i) {
      EXPECT_EQ(got[i], clean[i < k ? i : i + 1]) << "slip at " << at << ", byte " << i;
    }
    EXPECT_EQ(e.fifo_bytes(), 13u) << "slip at " << at;
    EXPECT_EQ(e.stats().injected_corruptions, 1u);
  }
}

TEST(SimDataReadyLine, DeliversEdgesInOrderWithSequence) {
  Mpu6000Emulator e(ramp_source, untimed());
  fake::SimDataReadyLine line(e, {.latency_ns = 50'000, .sigma_ns = 0, .seed = 1});
  e.connect(line);
  wr(e, Register::INT_ENABLE, DATA_RDY_EN);
  wake(e, 1, 0, false);
  const TimeNs t0 = e.now_ns();
  std::vector<drivers::DataReadyEdge> edges;
  for (int i = 0; i < 5; ++i) {
    auto w = line.wait(10 * kMs);
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE(w->has_value());
    edges.push_back(**w);
  }
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(edges[i].sequence, static_cast<std::uint64_t>(i + 1));
    EXPECT_EQ(edges[i].t_ns, t0 + (i + 1) * kMs + 50'000);
  }
  line.drop_next(2);
  auto w = line.wait(10 * kMs);
  ASSERT_TRUE(w.ok() && w->has_value());
  EXPECT_EQ((*w)->sequence, 8u);
  // Interrupt disabled: the wait times out at its deadline.
  wr(e, Register::INT_ENABLE, 0);
  const TimeNs before = e.now_ns();
  w = line.wait(5 * kMs);
  ASSERT_TRUE(w.ok());
  EXPECT_FALSE(w->has_value());
  EXPECT_EQ(e.now_ns(), before + 5 * kMs);
}

}  // namespace
}  // namespace imucal
