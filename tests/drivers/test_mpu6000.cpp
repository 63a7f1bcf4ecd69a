// SPDX-License-Identifier: BSD-3-Clause
// The MPU-6000 driver against the register emulator, end to end: probe, configuration with
// read-back, streaming with every sample checked against the emulator's truth, and recovery
// from each injected fault without passing on a damaged sample.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <vector>

#include "core/imu.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "drivers/mpu6000/registers.hpp"

namespace imucal {
namespace {

using drivers::DataReadyEdge;
using namespace drivers::mpu6000;
using fake::Corruption;
using fake::EmulatorOptions;
using fake::Mpu6000Emulator;
using fake::SensorReading;
using fake::SimDataReadyLine;
using fake::TruthSample;

constexpr TimeNs kMs = 1'000'000;
constexpr TimeNs kS = 1'000'000'000;

/// Smooth, varying signals; gyro z ramps fast enough that consecutive samples differ even at
/// 8 kHz, so a sample identifies its truth record by value.
SensorReading moving_source(TimeNs t_ns) {
  const double t = ns_to_s(t_ns);
  const double two_pi = 2.0 * std::numbers::pi;
  SensorReading r;
  r.specific_force = {0.3 * std::sin(two_pi * 1.3 * t), -0.2 * std::cos(two_pi * 0.7 * t),
                      kStandardGravity + 0.1 * std::sin(two_pi * 2.1 * t)};
  const double frac = t - std::floor(t);
  r.angular_rate = {0.5 * std::sin(two_pi * 1.1 * t), -0.3 * std::sin(two_pi * 0.9 * t), -15.0 + 30.0 * frac};
  r.temperature_c = 25.0 + 0.5 * std::sin(two_pi * 0.1 * t);
  return r;
}

bool same(const TruthSample& t, const RawSample& s) {
  return t.accel == s.accel && t.gyro == s.gyro && t.temp == s.temp;
}

struct TruthCheck {
  std::size_t delivered = 0;
  std::size_t unmatched = 0;       // a delivered sample the chip never produced: corrupt data
  std::size_t lost = 0;            // samples the chip produced between delivered ones, not delivered
  std::size_t unflagged_gaps = 0;  // a loss without kImuFlagGapBefore on the next sample
  std::size_t first_index = 0;     // truth index of the first delivered sample
  std::size_t last_index = 0;
};

TruthCheck check_against_truth(const std::vector<RawSample>& out, const std::vector<TruthSample>& truth) {
  TruthCheck c;
  c.delivered = out.size();
  std::size_t next = 0;
  std::optional<std::size_t> prev;
  for (const RawSample& s : out) {
    std::size_t j = next;
    while (j < truth.size() && !(truth[j].to_fifo && same(truth[j], s))) ++j;
    if (j == truth.size()) {
      ++c.unmatched;
      continue;
    }
    if (!prev) c.first_index = j;
    if (prev && j > *prev + 1) {
      c.lost += j - *prev - 1;
      if (!(s.flags & kImuFlagGapBefore)) ++c.unflagged_gaps;
    }
    prev = j;
    c.last_index = j;
    next = j + 1;
  }
  return c;
}

/// Drives the driver the way an acquisition loop does: wait for data-ready edges, poll at the
/// read interval with the latest edge.
class Harness {
 public:
  Harness(Settings settings, EmulatorOptions options = {}, fake::DataReadyTiming timing = {},
          fake::SensorSource source = moving_source)
      : emu(std::move(source), options), line(emu, timing), driver(emu, settings) {
    emu.connect(line);
  }

  using Hook = std::function<void(TimeNs now_ns)>;

  Status run_until(TimeNs end_ns, const Hook& before_poll = {}) {
    const TimeNs interval = driver.settings().read_interval_ns;
    TimeNs next_poll = emu.now_ns();
    while (emu.now_ns() < end_ns) {
      std::optional<DataReadyEdge> edge;
      if (driver.state() == State::kStream) {
        while (emu.now_ns() < next_poll) {
          auto w = line.wait(next_poll - emu.now_ns());
          if (!w.ok()) return w.error();
          if (!*w) break;
          edge = **w;
          driver.on_edge(*edge);
        }
      } else if (emu.now_ns() < next_poll) {
        emu.advance_to(next_poll);
      }
      if (before_poll) before_poll(emu.now_ns());
      auto r = driver.poll(emu.now_ns(), edge);
      if (!r.ok()) return r.error();
      if (r->batch) {
        out.insert(out.end(), r->batch->samples.begin(), r->batch->samples.end());
        ++batches;
      }
      next_poll = std::min(r->next_poll_ns, emu.now_ns() + interval);
    }
    return {};
  }

  Status run_for(TimeNs d, const Hook& hook = {}) { return run_until(emu.now_ns() + d, hook); }

  /// Runs until the driver streams (configuration done).
  Status start() {
    const TimeNs limit = emu.now_ns() + 2 * kS;
    while (driver.state() != State::kStream && emu.now_ns() < limit) {
      auto r = driver.poll(emu.now_ns());
      if (!r.ok()) return r.error();
      emu.advance_to(std::max(r->next_poll_ns, emu.now_ns()));
    }
    if (driver.state() != State::kStream) return make_error(Errc::kTimeout, "driver did not reach Stream");
    return {};
  }

  /// A one-shot hook that runs `f` at the first poll at or after `at_ns`.
  static Hook at(TimeNs at_ns, std::function<void()> f) {
    auto done = std::make_shared<bool>(false);
    return [=](TimeNs now) {
      if (!*done && now >= at_ns) {
        *done = true;
        f();
      }
    };
  }

  Mpu6000Emulator emu;
  SimDataReadyLine line;
  Mpu6000 driver;
  std::vector<RawSample> out;
  std::size_t batches = 0;
};

Settings spi_8khz() {
  Settings s;
  s.dlpf_cfg = 0;  // gyro 8 kHz
  s.smplrt_div = 0;
  s.read_interval_ns = 1 * kMs;
  return s;
}

Settings i2c_1khz() {
  Settings s;
  s.bus = BusKind::kI2c;
  s.dlpf_cfg = 1;
  s.smplrt_div = 0;
  s.read_interval_ns = 4 * kMs;
  return s;
}

EmulatorOptions i2c_options() {
  EmulatorOptions o;
  o.bus = BusKind::kI2c;
  o.timing = fake::BusTiming::i2c();
  return o;
}

void expect_clean_stream(const Harness& h, std::size_t min_samples) {
  const TruthCheck c = check_against_truth(h.out, h.emu.truth());
  EXPECT_GE(c.delivered, min_samples);
  EXPECT_EQ(c.unmatched, 0u);
  EXPECT_EQ(c.lost, 0u);
  // Everything the chip wrote into the FIFO after the first delivered sample was delivered,
  // except what is still in the FIFO.
  std::size_t produced = 0;
  for (std::size_t i = c.first_index; i < h.emu.truth().size(); ++i) produced += h.emu.truth()[i].to_fifo;
  EXPECT_EQ(produced, c.delivered + h.emu.fifo_bytes() / FIFO::kFrameBytes);
  ASSERT_FALSE(h.out.empty());
  EXPECT_EQ(h.out.front().flags, static_cast<std::uint32_t>(kImuFlagDeviceReset));
  for (std::size_t i = 1; i < h.out.size(); ++i) ASSERT_EQ(h.out[i].flags, 0u) << "sample " << i;
}

/// Every delivered sample is one the chip produced, in order, and every loss is flagged.
void expect_never_corrupt(const Harness& h) {
  const TruthCheck c = check_against_truth(h.out, h.emu.truth());
  EXPECT_EQ(c.unmatched, 0u) << "a corrupted sample was delivered";
  EXPECT_EQ(c.unflagged_gaps, 0u);
  EXPECT_GT(c.delivered, 0u);
}

TEST(Mpu6000Driver, StreamsSpi8kHzWithoutLoss) {
  Harness h(spi_8khz());
  ASSERT_TRUE(h.run_for(2 * kS).ok());
  EXPECT_EQ(h.driver.state(), State::kStream);
  expect_clean_stream(h, 14000);  // ~1.7 s of streaming at 8 kHz
  const Counters& c = h.driver.counters();
  EXPECT_EQ(c.resets, 1u);
  EXPECT_EQ(c.bad_transfers + c.fifo_overflows + c.fifo_resets + c.bad_fifo_counts + c.implausible_data +
                c.config_mismatches + c.missed_data_ready + c.no_data_timeouts,
            0u)
      << h.driver.status_line();
  EXPECT_EQ(h.emu.stats().speed_violations, 0u) << "configuration registers accessed above 1 MHz";
  EXPECT_TRUE(h.emu.i2c_interface_disabled());
  EXPECT_EQ(h.emu.stats().fifo_bytes_overwritten, 0u);
  EXPECT_DOUBLE_EQ(h.emu.sample_rate_hz(), 8000.0);
}

TEST(Mpu6000Driver, StreamsI2c1kHzWithoutLoss) {
  Harness h(i2c_1khz(), i2c_options());
  ASSERT_TRUE(h.run_for(3 * kS).ok());
  expect_clean_stream(h, 2500);
  EXPECT_FALSE(h.emu.i2c_interface_disabled());
  EXPECT_EQ(h.driver.counters().bad_transfers, 0u);
  EXPECT_DOUBLE_EQ(h.emu.sample_rate_hz(), 1000.0);
}

TEST(Mpu6000Driver, ConfigurationIsReadBackAndMatchesSettings) {
  Settings s = spi_8khz();
  s.accel_range = AccelRange::k4g;
  s.gyro_range = GyroRange::k1000dps;  // the source turns at up to 15 rad/s = 860 deg/s
  s.dlpf_cfg = 3;
  s.smplrt_div = 4;
  s.read_interval_ns = 10 * kMs;
  Harness h(s);
  ASSERT_TRUE(h.start().ok());
  for (const auto& row : h.driver.config_rows()) {
    const std::uint8_t v = h.emu.peek(row.reg);
    EXPECT_EQ(v & row.set_bits, row.set_bits) << "register " << int(reg_addr(row.reg));
    EXPECT_EQ(v & row.clear_bits, 0) << "register " << int(reg_addr(row.reg));
  }
  EXPECT_EQ(h.emu.peek(Register::GYRO_CONFIG), 2 << 3);
  EXPECT_EQ(h.emu.peek(Register::ACCEL_CONFIG), 1 << 3);
  EXPECT_EQ(h.emu.peek(Register::CONFIG), 3);
  EXPECT_EQ(h.emu.peek(Register::SMPLRT_DIV), 4);
  EXPECT_EQ(h.emu.peek(Register::PWR_MGMT_1), CLKSEL_PLL_GYRO_X);
  EXPECT_DOUBLE_EQ(h.emu.sample_rate_hz(), 200.0);
  ASSERT_TRUE(h.run_for(1 * kS).ok());
  expect_clean_stream(h, 150);
}

TEST(Mpu6000Driver, ByteOrderAxisOrderAndScales) {
  // Distinct constant values per axis; expected counts computed from the datasheet sensitivities.
  auto source = [](TimeNs) {
    SensorReading r;
    r.specific_force = Eigen::Vector3d(0.5, -0.25, 1.0) * kStandardGravity;
    r.angular_rate = Eigen::Vector3d(100.0, -50.0, 10.0) * std::numbers::pi / 180.0;
    r.temperature_c = 30.0;
    return r;
  };
  Settings s = spi_8khz();
  s.accel_range = AccelRange::k16g;    // 2048 LSB/g
  s.gyro_range = GyroRange::k2000dps;  // 16.4 LSB/dps
  Harness h(s, {}, {}, source);
  ASSERT_TRUE(h.run_for(300 * kMs).ok());
  ASSERT_FALSE(h.out.empty());
  for (const RawSample& x : h.out) {
    EXPECT_EQ(x.accel[0], 1024);
    EXPECT_EQ(x.accel[1], -512);
    EXPECT_EQ(x.accel[2], 2048);
    EXPECT_EQ(x.gyro[0], 1640);
    EXPECT_EQ(x.gyro[1], -820);
    EXPECT_EQ(x.gyro[2], 164);
    EXPECT_EQ(x.temp, -2220);  // (30 - 36.53) * 340
  }
  // The raw->SI description agrees with the counts.
  const ImuStreamInfo info = make_stream_info(s, "mpu6000@sim");
  const RawSample& x = h.out.back();
  const Eigen::Vector3d a = info.accel.to_si(Eigen::Vector3d(x.accel[0], x.accel[1], x.accel[2]));
  EXPECT_NEAR(a.x(), 0.5 * kStandardGravity, 1e-9);
  EXPECT_NEAR(a.y(), -0.25 * kStandardGravity, 1e-9);
  const Eigen::Vector3d w = info.gyro.to_si(Eigen::Vector3d(x.gyro[0], x.gyro[1], x.gyro[2]));
  EXPECT_NEAR(w.x(), 100.0 * std::numbers::pi / 180.0, 1e-9);
  EXPECT_NEAR(info.temperature_scale * x.temp + info.temperature_offset, 30.0, 0.01);
  EXPECT_EQ(info.accel_full_scale_g, 16);
  EXPECT_EQ(info.gyro_full_scale_dps, 2000);
  EXPECT_DOUBLE_EQ(info.rate_hz, 8000.0);
  EXPECT_EQ(info.units, ImuUnits::kRaw);
}

TEST(Mpu6000Driver, SaturationIsFlagged) {
  auto source = [](TimeNs) {
    SensorReading r;
    r.specific_force = {0, 0, 3.0 * kStandardGravity};
    r.angular_rate = {0, 0, 10.0};  // 573 dps, beyond +-250
    return r;
  };
  Settings s = spi_8khz();
  s.accel_range = AccelRange::k2g;
  s.gyro_range = GyroRange::k250dps;
  Harness h(s, {}, {}, source);
  ASSERT_TRUE(h.run_for(300 * kMs).ok());
  ASSERT_FALSE(h.out.empty());
  for (const RawSample& x : h.out) {
    EXPECT_EQ(x.accel[2], 32767);
    EXPECT_EQ(x.gyro[2], 32767);
    EXPECT_TRUE(x.flags & kImuFlagAccelSaturated);
    EXPECT_TRUE(x.flags & kImuFlagGyroSaturated);
  }
}

TEST(Mpu6000Driver, WrongWhoAmIIsAClearError) {
  EmulatorOptions o;
  o.who_am_i = 0x70;
  Harness h(spi_8khz(), o);
  auto p = h.driver.probe();
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, Errc::kDevice);
  EXPECT_NE(p.error().message.find("0x70"), std::string::npos) << p.error().message;
  EXPECT_NE(p.error().message.find("0x68"), std::string::npos) << p.error().message;
  auto s = h.run_for(2 * kS);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("WHO_AM_I reads 0x70"), std::string::npos) << s.error().message;
  EXPECT_TRUE(h.out.empty());
}

TEST(Mpu6000Driver, SilentBusGivesUpWithAnError) {
  Harness h(spi_8khz());
  h.emu.fail_next_transfers(1'000'000);
  auto s = h.run_for(20 * kS);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kDevice);
  EXPECT_NE(s.error().message.find("did not come up"), std::string::npos) << s.error().message;
}

TEST(Mpu6000Driver, ConfigMismatchTriggersReset) {
  Harness h(spi_8khz());
  ASSERT_TRUE(h.run_for(500 * kMs).ok());
  const std::size_t before = h.out.size();
  ASSERT_TRUE(
      h.run_for(1500 * kMs, Harness::at(600 * kMs, [&] { h.emu.poke(Register::INT_PIN_CFG, LATCH_INT_EN); }))
          .ok());
  const Counters& c = h.driver.counters();
  EXPECT_EQ(c.config_mismatches, 1u) << h.driver.status_line();
  EXPECT_EQ(c.resets, 2u);
  EXPECT_EQ(h.driver.state(), State::kStream);
  EXPECT_EQ(h.emu.peek(Register::INT_PIN_CFG), 0) << "reconfigured after the reset";
  EXPECT_GT(h.out.size(), before + 4000);
  expect_never_corrupt(h);
  const TruthCheck t = check_against_truth(h.out, h.emu.truth());
  EXPECT_GT(t.lost, 0u);  // the reset loses samples, and says so
  std::size_t flagged = 0;
  for (std::size_t i = 1; i < h.out.size(); ++i) {
    flagged += (h.out[i].flags & (kImuFlagGapBefore | kImuFlagDeviceReset)) ==
               (kImuFlagGapBefore | kImuFlagDeviceReset);
  }
  EXPECT_EQ(flagged, 1u);
}

TEST(Mpu6000Driver, SpontaneousChipResetIsDetectedAndRecovered) {
  Harness h(spi_8khz());
  ASSERT_TRUE(h.run_for(2 * kS, Harness::at(700 * kMs, [&] { h.emu.spontaneous_reset(); })).ok());
  const Counters& c = h.driver.counters();
  EXPECT_EQ(c.resets, 2u) << h.driver.status_line();
  EXPECT_EQ(c.no_data_timeouts + c.config_mismatches, 1u);
  EXPECT_EQ(h.driver.state(), State::kStream);
  expect_never_corrupt(h);
  // Streaming resumed: samples from the last 0.5 s are there.
  const TruthCheck t = check_against_truth(h.out, h.emu.truth());
  EXPECT_GT(h.emu.truth()[t.last_index].t_ns, 1500 * kMs);
}

TEST(Mpu6000Driver, BusErrorsAreCountedAndNeverCorruptData) {
  Harness h(spi_8khz());
  std::vector<Harness::Hook> hooks;
  for (int i = 0; i < 6; ++i) {
    hooks.push_back(Harness::at((400 + 100 * i) * kMs, [&h, i] { h.emu.fail_next_transfers(1 + i % 2); }));
  }
  ASSERT_TRUE(h.run_for(1500 * kMs, [&](TimeNs now) {
                 for (auto& f : hooks) f(now);
               }).ok());
  const Counters& c = h.driver.counters();
  EXPECT_EQ(c.bad_transfers, 9u) << h.driver.status_line();
  EXPECT_EQ(c.resets, 1u) << "isolated bus errors do not need a chip reset";
  EXPECT_EQ(h.driver.state(), State::kStream);
  expect_never_corrupt(h);
}

TEST(Mpu6000Driver, StuckHighReadsAreRejected) {
  Harness h(spi_8khz());
  std::vector<Harness::Hook> hooks;
  for (int i = 0; i < 8; ++i) {
    hooks.push_back(
        Harness::at((400 + 50 * i) * kMs, [&] { h.emu.corrupt_next_read(Corruption::kStuckHigh); }));
  }
  ASSERT_TRUE(h.run_for(1200 * kMs, [&](TimeNs now) {
                 for (auto& f : hooks) f(now);
               }).ok());
  const Counters& c = h.driver.counters();
  EXPECT_EQ(h.emu.stats().injected_corruptions, 8u);
  EXPECT_GE(c.bad_fifo_counts + c.implausible_data + c.bad_transfers, 8u) << h.driver.status_line();
  EXPECT_EQ(c.resets, 1u) << "a bad read is not a lost configuration";
  EXPECT_EQ(h.driver.state(), State::kStream);
  expect_never_corrupt(h);
}

TEST(Mpu6000Driver, MisalignedFifoIsDetectedAndReset) {
  // Every slip leaves the FIFO one byte short of the frame kept back in it, so the count after
  // the burst catches it before the temperature check runs (at 40 +- 0.2 deg C, raw
  // 0x0458..0x04E0, the temperature check would catch it too).
  auto source = [](TimeNs t_ns) {
    SensorReading r = moving_source(t_ns);
    r.temperature_c = 40.0 + 0.2 * std::sin(2.0 * std::numbers::pi * 0.1 * ns_to_s(t_ns));
    return r;
  };
  Harness h(spi_8khz(), {}, {}, source);
  std::vector<Harness::Hook> hooks;
  for (int i = 0; i < 5; ++i) {
    hooks.push_back(
        Harness::at((400 + 100 * i) * kMs, [&] { h.emu.corrupt_next_read(Corruption::kByteSlip); }));
  }
  ASSERT_TRUE(h.run_for(1200 * kMs, [&](TimeNs now) {
                 for (auto& f : hooks) f(now);
               }).ok());
  const Counters& c = h.driver.counters();
  EXPECT_EQ(h.emu.stats().injected_corruptions, 5u);
  EXPECT_EQ(c.bad_fifo_counts, 5u) << h.driver.status_line();
  EXPECT_EQ(c.implausible_data, 0u) << h.driver.status_line();
  EXPECT_EQ(c.fifo_resets, 5u);
  expect_never_corrupt(h);
}

/// The moving source with the temperature at raw 0xF0F0 +- 1 (25.19 C): its high and low bytes
/// are nearly equal, so a frame shifted by one byte carries a temperature (the old low byte, then
/// the gyro X high byte) within the plausible step of the true one.
SensorReading moving_source_equal_temp_bytes(TimeNs t_ns) {
  SensorReading r = moving_source(t_ns);
  r.temperature_c = 25.19 + 0.003 * std::sin(2.0 * std::numbers::pi * 0.7 * ns_to_s(t_ns));
  return r;
}

// Byte slips where the temperature check cannot see them: every one must still be caught (by
// the FIFO count after the burst, which the frame kept back in the FIFO makes sensitive to it),
// flagged as a gap, and no shifted frame delivered.
TEST(Mpu6000Driver, EveryByteSlipIsCaughtWhereTheTemperatureCannotSeeIt) {
  constexpr int kSlips = 120;
  struct Case {
    const char* name;
    Settings settings;
    EmulatorOptions options;
  };
  for (const Case& c : {Case{"SPI 8 kHz", spi_8khz(), {}}, Case{"I2C 1 kHz", i2c_1khz(), i2c_options()}}) {
    Harness h(c.settings, c.options, {}, moving_source_equal_temp_bytes);
    const TimeNs spacing = std::max<TimeNs>(11'100'000, 5 * c.settings.read_interval_ns);
    std::vector<Harness::Hook> hooks;
    for (int i = 0; i < kSlips; ++i) {
      // Slips at every phase of the sample clock and of the polls (the spacing is no multiple of
      // either), and at every position in the burst: its first byte (the slip the temperature
      // check could not see on a read that emptied the FIFO), inside the temperature field, in
      // later frames, at its last byte.
      const std::size_t at = i % 3 == 0 ? 0 : static_cast<std::size_t>(i * 37) % 130;
      hooks.push_back(Harness::at(400 * kMs + i * spacing,
                                  [&h, at] { h.emu.corrupt_next_read(Corruption::kByteSlip, at); }));
    }
    ASSERT_TRUE(h.run_for(400 * kMs + kSlips * spacing + 100 * kMs, [&](TimeNs now) {
                   for (auto& f : hooks) f(now);
                 }).ok());
    // The formerly undetectable case: for every sample the chip produced, a one-byte shift
    // gives a temperature within the allowed step.
    const int max_step = static_cast<int>(std::lround(c.settings.max_temperature_step_c * kTempLsbPerDegC));
    std::size_t plausible_when_shifted = 0;
    for (const TruthSample& t : h.emu.truth()) {
      const auto temp = static_cast<std::uint16_t>(t.temp);
      const auto gyro_x = static_cast<std::uint16_t>(t.gyro[0]);
      const std::int16_t shifted =
          be16(static_cast<std::uint8_t>(temp & 0xFF), static_cast<std::uint8_t>(gyro_x >> 8));
      plausible_when_shifted += std::abs(shifted - t.temp) <= max_step;
    }
    EXPECT_EQ(plausible_when_shifted, h.emu.truth().size()) << c.name;

    const Counters& k = h.driver.counters();
    EXPECT_EQ(h.emu.stats().injected_corruptions, static_cast<std::uint64_t>(kSlips)) << c.name;
    EXPECT_EQ(k.bad_fifo_counts, static_cast<std::uint64_t>(kSlips))
        << c.name << ": " << h.driver.status_line();
    EXPECT_EQ(k.implausible_data, 0u) << c.name;
    EXPECT_EQ(k.fifo_resets, static_cast<std::uint64_t>(kSlips)) << c.name;
    EXPECT_EQ(k.resets, 1u) << c.name;
    expect_never_corrupt(h);
    const TruthCheck t = check_against_truth(h.out, h.emu.truth());
    EXPECT_GT(t.lost, 0u) << c.name;
    std::size_t gaps = 0;
    for (std::size_t i = 1; i < h.out.size(); ++i) gaps += (h.out[i].flags & kImuFlagGapBefore) != 0;
    EXPECT_EQ(gaps, static_cast<std::size_t>(kSlips)) << c.name << ": one flagged gap per slip";
    std::printf(
        "  %s: %d slips injected, %llu caught by the FIFO count, %llu by the temperature, %zu samples "
        "delivered, %zu lost (flagged), %zu unmatched\n",
        c.name, kSlips, static_cast<unsigned long long>(k.bad_fifo_counts),
        static_cast<unsigned long long>(k.implausible_data), t.delivered, t.lost, t.unmatched);
  }
}

// Long clean runs: every frame the chip wrote is delivered exactly once and in order; what is
// not delivered yet is still in the FIFO.
TEST(Mpu6000Driver, LongRunsDeliverEverySampleExactlyOnce) {
  Settings spi_1khz = spi_8khz();
  spi_1khz.dlpf_cfg = 1;
  spi_1khz.read_interval_ns = 1 * kMs;
  struct Case {
    const char* name;
    Settings settings;
    EmulatorOptions options;
    std::size_t min_samples;
  };
  for (const Case& c : {Case{"SPI 8 kHz", spi_8khz(), {}, 150'000}, Case{"SPI 1 kHz", spi_1khz, {}, 19'000},
                        Case{"I2C 1 kHz", i2c_1khz(), i2c_options(), 19'000}}) {
    SCOPED_TRACE(c.name);
    Harness h(c.settings, c.options);
    ASSERT_TRUE(h.run_for(20 * kS).ok());
    expect_clean_stream(h, c.min_samples);
    const TruthCheck t = check_against_truth(h.out, h.emu.truth());
    EXPECT_EQ(t.last_index - t.first_index + 1, t.delivered) << "consecutive frames, none twice";
    EXPECT_EQ(h.emu.fifo_bytes() % FIFO::kFrameBytes, 0u);
    EXPECT_GE(h.emu.fifo_bytes(), FIFO::kFrameBytes) << "the newest frame stays in the FIFO";
    EXPECT_EQ(h.driver.counters().samples, t.delivered);
  }
}

TEST(Mpu6000Driver, FifoOverflowFromStalledReadsIsFlagged) {
  Harness h(spi_8khz());
  // The bus is held for 20 ms: 160 samples arrive, the FIFO holds 73.
  ASSERT_TRUE(h.run_for(1 * kS, Harness::at(500 * kMs, [&] { h.emu.stall_next_transfer(20 * kMs); })).ok());
  const Counters& c = h.driver.counters();
  EXPECT_GT(h.emu.stats().fifo_bytes_overwritten, 0u);
  EXPECT_EQ(c.fifo_overflows, 1u) << h.driver.status_line();
  EXPECT_EQ(c.fifo_resets, 1u);
  expect_never_corrupt(h);
  const TruthCheck t = check_against_truth(h.out, h.emu.truth());
  EXPECT_GE(t.lost, 73u);
}

TEST(Mpu6000Driver, FifoIsResetBeforeItOverflows) {
  // Stalls of every length up to past overflow: the driver either reads everything, resets the
  // FIFO at the watermark, or sees the overflow; it never delivers a damaged sample.
  int watermark_resets = 0;
  for (TimeNs stall_us = 5000; stall_us <= 10000; stall_us += 250) {
    Harness h(spi_8khz());
    ASSERT_TRUE(
        h.run_for(400 * kMs, Harness::at(300 * kMs, [&] { h.emu.stall_next_transfer(stall_us * 1000); }))
            .ok());
    expect_never_corrupt(h);
    const Counters& c = h.driver.counters();
    const TruthCheck t = check_against_truth(h.out, h.emu.truth());
    if (t.lost > 0) {
      EXPECT_EQ(c.fifo_resets, 1u) << "stall " << stall_us << " us";
    }
    if (c.fifo_overflows == 0 && c.fifo_resets == 1) {
      EXPECT_EQ(h.emu.stats().fifo_bytes_overwritten, 0u) << "reset at the watermark, before overflow";
      ++watermark_resets;
    }
  }
  EXPECT_GT(watermark_resets, 0);
  EXPECT_EQ(spi_8khz().fifo_watermark_bytes(), 1024 - 14 * 9);
}

TEST(Mpu6000Driver, MissedDataReadyEdgesAreCountedWithoutLoss) {
  Harness h(spi_8khz());
  ASSERT_TRUE(h.run_for(1 * kS, Harness::at(500 * kMs, [&] { h.line.drop_next(5); })).ok());
  EXPECT_EQ(h.line.dropped(), 5u);
  EXPECT_EQ(h.driver.counters().missed_data_ready, 5u);
  expect_clean_stream(h, 6000);  // streaming starts after the 230 ms reset sequence
}

TEST(Mpu6000Driver, DataReadyEdgesFollowSamplesWithJitter) {
  Harness h(spi_8khz(), {}, {.latency_ns = 20'000, .sigma_ns = 30'000, .seed = 7});
  ASSERT_TRUE(h.run_for(1 * kS).ok());
  // Every sample raised an edge once data-ready was enabled; latencies have the configured spread.
  const auto& lat = h.line.latencies_ns();
  ASSERT_GT(lat.size(), 6000u);
  double sum = 0, sum2 = 0;
  for (TimeNs l : lat) {
    EXPECT_GE(l, 0);
    sum += static_cast<double>(l);
    sum2 += static_cast<double>(l) * static_cast<double>(l);
  }
  const double mean = sum / lat.size();
  const double sd = std::sqrt(sum2 / lat.size() - mean * mean);
  // N(20 us, 30 us) clipped at 0: mean 24.5 us, standard deviation 23.7 us.
  EXPECT_NEAR(mean, 24'500, 1'500);
  EXPECT_NEAR(sd, 23'700, 1'500);
}

SensorReading still_source(TimeNs t_ns) {
  SensorReading r;
  // A little deterministic "noise" so averaging is exercised.
  const double n = std::sin(static_cast<double>(t_ns) * 1.7e-5);
  r.specific_force = {0.01 * n, -0.02 * n, kStandardGravity};
  r.angular_rate = {0.001 * n, 0.002, -0.001};
  r.temperature_c = 28.0;
  return r;
}

Status run_self_test(Harness& h, Result<SelfTestResult>* out) {
  IMUCAL_TRY(h.start());
  *out = h.driver.self_test([&](TimeNs d) { h.emu.advance_to(h.emu.now_ns() + d); });
  return {};
}

TEST(Mpu6000Driver, SelfTestPasses) {
  Harness h(spi_8khz(), {}, {}, still_source);
  Result<SelfTestResult> r = make_error(Errc::kInternal, "not run");
  ASSERT_TRUE(run_self_test(h, &r).ok());
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_TRUE(r->pass()) << r->summary();
  const auto ft_a = h.emu.accel_factory_trim();
  const auto ft_g = h.emu.gyro_factory_trim();
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(r->accel[i].factory_trim, ft_a[i], 1e-9);
    EXPECT_NEAR(r->gyro[i].factory_trim, ft_g[i], 1e-9);
    EXPECT_LT(std::abs(r->accel[i].change), 0.01);
    EXPECT_LT(std::abs(r->gyro[i].change), 0.01);
  }
  EXPECT_LT(r->gyro[1].factory_trim, 0.0);  // RM 4.1: FT[Yg] is negative
  // Afterwards the driver configures again and streams with the configured ranges.
  ASSERT_TRUE(h.run_for(300 * kMs).ok());
  EXPECT_EQ(h.driver.state(), State::kStream);
  EXPECT_EQ(h.emu.peek(Register::GYRO_CONFIG), static_cast<int>(GyroRange::k2000dps) << 3);
  EXPECT_EQ(h.emu.peek(Register::ACCEL_CONFIG), static_cast<int>(AccelRange::k16g) << 3);
  ASSERT_FALSE(h.out.empty());
  EXPECT_TRUE(h.out.front().flags & kImuFlagDeviceReset);
}

TEST(Mpu6000Driver, SelfTestFailsOnWeakOrStrongResponse) {
  for (double gain : {0.5, 1.3}) {
    EmulatorOptions o;
    o.gyro_self_test_gain = gain;
    Harness h(spi_8khz(), o, {}, still_source);
    Result<SelfTestResult> r = make_error(Errc::kInternal, "not run");
    ASSERT_TRUE(run_self_test(h, &r).ok());
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_FALSE(r->pass()) << r->summary();
    for (int i = 0; i < 3; ++i) {
      EXPECT_TRUE(r->accel[i].pass) << r->summary();
      EXPECT_FALSE(r->gyro[i].pass) << r->summary();
      EXPECT_NEAR(r->gyro[i].change, gain - 1.0, 0.01);
    }
  }
}

TEST(Mpu6000Driver, SelfTestNeedsAConfiguredDevice) {
  Harness h(spi_8khz(), {}, {}, still_source);
  auto r = h.driver.self_test([&](TimeNs d) { h.emu.advance_to(h.emu.now_ns() + d); });
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInvalidArgument);
}

TEST(Mpu6000Driver, OffsetRegistersRoundTripAndShiftTheOutput) {
  auto source = [](TimeNs) {
    SensorReading r;
    r.specific_force = {0.1, 0.2, kStandardGravity};
    r.angular_rate = {0.01, 0.02, 0.03};
    return r;
  };
  Harness h(spi_8khz(), {}, {}, source);
  ASSERT_TRUE(h.run_for(400 * kMs).ok());
  ASSERT_FALSE(h.out.empty());
  const RawSample before = h.out.back();
  auto factory = h.driver.read_offsets();
  ASSERT_TRUE(factory.ok());
  EXPECT_EQ(factory->accel, (std::array<std::int16_t, 3>{-1854, 2210, 1369}));
  EXPECT_EQ(factory->gyro, (std::array<std::int16_t, 3>{0, 0, 0}));

  OffsetRegisters o = *factory;
  o.accel[0] += 64;
  o.accel[2] -= 33;  // bit 0 is reserved: written as -34, the chip's bit 0 kept
  o.gyro = {100, -50, 0};
  ASSERT_TRUE(h.driver.write_offsets(o).ok());
  auto back = h.driver.read_offsets();
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->accel[0], factory->accel[0] + 64);
  EXPECT_EQ(back->accel[2],
            static_cast<std::int16_t>(((factory->accel[2] - 33) & ~1) | (factory->accel[2] & 1)));
  EXPECT_EQ(back->gyro, o.gyro);

  h.out.clear();
  ASSERT_TRUE(h.run_for(100 * kMs).ok());
  ASSERT_FALSE(h.out.empty());
  const RawSample after = h.out.back();
  // +-16 g: 1 offset LSB = 1 output LSB. +-2000 dps: 1 offset LSB = 4 / 2^3 output LSB.
  EXPECT_EQ(after.accel[0] - before.accel[0], 64);
  EXPECT_EQ(after.accel[1] - before.accel[1], 0);
  EXPECT_EQ(after.accel[2] - before.accel[2], back->accel[2] - factory->accel[2]);
  EXPECT_EQ(after.gyro[0] - before.gyro[0], 50);
  EXPECT_EQ(after.gyro[1] - before.gyro[1], -25);
  EXPECT_EQ(after.gyro[2] - before.gyro[2], 0);
}

// The register counts 1/32.8 deg/s at every range: a bias of 100 output counts is 25 register
// counts at +-250 deg/s and 200 at +-2000; the value is rounded and held within int16.
TEST(Mpu6000Offsets, AGyroBiasInOutputCountsBecomesRegisterCountsOfItsRange) {
  EXPECT_EQ(gyro_offset_register_for_bias(100.0, GyroRange::k250dps), -25);
  EXPECT_EQ(gyro_offset_register_for_bias(100.0, GyroRange::k500dps), -50);
  EXPECT_EQ(gyro_offset_register_for_bias(100.0, GyroRange::k1000dps), -100);
  EXPECT_EQ(gyro_offset_register_for_bias(100.0, GyroRange::k2000dps), -200);
  EXPECT_EQ(gyro_offset_register_for_bias(-7.0, GyroRange::k250dps), 2);  // 1.75 rounded
  EXPECT_EQ(gyro_offset_register_for_bias(1e6, GyroRange::k2000dps), -32768);
  EXPECT_EQ(gyro_offset_register_for_bias(-1e6, GyroRange::k2000dps), 32767);
  EXPECT_EQ(gyro_offset_register_for_bias(std::numeric_limits<double>::quiet_NaN(), GyroRange::k250dps), 0);
}

// Through the chip: the output's gyro counts, written back as the registers for that bias,
// bring the output to zero within the register's resolution (1/2 output count at +-2000 deg/s).
TEST(Mpu6000Offsets, TheRegistersForTheOutputsBiasCancelIt) {
  auto source = [](TimeNs) {
    SensorReading r;
    r.specific_force = {0.0, 0.0, kStandardGravity};
    r.angular_rate = {0.21, -0.37, 0.05};
    return r;
  };
  Harness h(spi_8khz(), {}, {}, source);
  ASSERT_TRUE(h.run_for(400 * kMs).ok());
  ASSERT_FALSE(h.out.empty());
  const RawSample before = h.out.back();
  auto regs = h.driver.read_offsets();
  ASSERT_TRUE(regs.ok());
  for (int i = 0; i < 3; ++i) {
    EXPECT_GT(std::abs(before.gyro[i]), 10) << i;
    regs->gyro[i] = gyro_offset_register_for_bias(before.gyro[i], spi_8khz().gyro_range);
  }
  ASSERT_TRUE(h.driver.write_offsets(*regs).ok());
  h.out.clear();
  ASSERT_TRUE(h.run_for(100 * kMs).ok());
  ASSERT_FALSE(h.out.empty());
  for (int i = 0; i < 3; ++i)
    EXPECT_LE(std::abs(h.out.back().gyro[i]), 1) << i << " before " << before.gyro[i];
}

TEST(Mpu6000Settings, ValidationExplainsWhatIsWrong) {
  // The message of a failed validation, or "" when it passed.
  auto why = [](const Settings& settings) {
    const Status valid = settings.validate();
    return valid.ok() ? std::string() : valid.error().message;
  };
  EXPECT_EQ(why(spi_8khz()), "");
  EXPECT_EQ(why(i2c_1khz()), "");
  Settings s = spi_8khz();
  s.read_interval_ns = 20 * kMs;
  EXPECT_THAT(why(s), ::testing::HasSubstr("too long"));
  s = spi_8khz();
  s.dlpf_cfg = 7;
  EXPECT_THAT(why(s), ::testing::HasSubstr("reserved"));
  s = spi_8khz();
  s.config_speed_hz = 20'000'000;
  EXPECT_THAT(why(s), ::testing::HasSubstr("1 MHz"));
}

TEST(Mpu6000Settings, RatesAndScales) {
  Settings s;
  s.dlpf_cfg = 0;
  s.smplrt_div = 0;
  EXPECT_DOUBLE_EQ(s.sample_rate_hz(), 8000.0);
  EXPECT_EQ(s.sample_period_ns(), 125'000);
  s.dlpf_cfg = 2;
  s.smplrt_div = 4;
  EXPECT_DOUBLE_EQ(s.sample_rate_hz(), 200.0);
  EXPECT_EQ(s.sample_period_ns(), 5'000'000);
  EXPECT_DOUBLE_EQ(accel_lsb_per_g(AccelRange::k2g), 16384.0);
  EXPECT_DOUBLE_EQ(accel_lsb_per_g(AccelRange::k16g), 2048.0);
  EXPECT_DOUBLE_EQ(gyro_lsb_per_dps(GyroRange::k250dps), 131.0);
  EXPECT_DOUBLE_EQ(gyro_lsb_per_dps(GyroRange::k2000dps), 16.4);
  EXPECT_EQ(accel_full_scale_g(AccelRange::k8g), 8);
  EXPECT_EQ(gyro_full_scale_dps(GyroRange::k1000dps), 1000);
}

TEST(Mpu6000Registers, FifoFrameLayout) {
  static_assert(sizeof(FIFO::DATA) == 14);
  EXPECT_EQ(offsetof(FIFO::DATA, TEMP_OUT_H), 6u);
  EXPECT_EQ(offsetof(FIFO::DATA, GYRO_XOUT_H), 8u);
  EXPECT_EQ(offsetof(FIFO::DATA, GYRO_ZOUT_L), 13u);
  EXPECT_EQ(be16(0x12, 0x34), 0x1234);
  EXPECT_EQ(be16(0xFF, 0xFE), -2);
  EXPECT_EQ(reg_addr(Register::WHO_AM_I), 0x75);
  EXPECT_EQ(reg_addr(Register::XG_OFFS_USRH), 0x13);
  EXPECT_EQ(reg_addr(Register::XA_OFFS_H), 0x06);
}

}  // namespace
}  // namespace imucal
