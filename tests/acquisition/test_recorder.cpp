// SPDX-License-Identifier: BSD-3-Clause
// `imucal record --sim`: the emulator, the MPU-6000 driver, the data-ready line, the
// timestamper, the stream and the session-log writer, end to end through the CLI; and the
// acquisition loop on the simulated rig, with every sample time compared to the emulator's truth.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "log/session_log.hpp"
#include "sim/rig.hpp"
#include "tests/support/emulator_accounting.hpp"
#include "tests/support/session_log_util.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::acq {
namespace {

using namespace imucal::test;  // shared session-log helpers (tests/support)

std::string write_config(const std::string& dir, const std::string& name, const std::string& imu_extra,
                         const std::string& bus = "sim") {
  const std::string path = dir + "/" + name;
  std::ofstream out(path);
  out << "name: test\n"
      << "imu:\n"
      << "  bus: " << bus << "\n"
      << "  accel_range_g: 4\n"
      << "  gyro_range_dps: 500\n"
      << "  rate_hz: 1000\n"
      << "  dlpf_hz: 188\n"
      << imu_extra << "storage:\n"
      << "  backend: file\n"
      << "  path: " << dir << "/calibration.bin\n";
  return path;
}

/// Emulator + data-ready line + driver + acquisition loop at the settings `imucal record` uses
/// (a FIFO read every max(1, rate / 1 kHz) edges, read interval twice that), chip 1.5 % slow.
emutest::Accounting run_sim_rig(std::uint8_t dlpf_cfg, std::uint8_t smplrt_div, double seconds) {
  sim::SimRigOptions o;
  o.settings.dlpf_cfg = dlpf_cfg;
  o.settings.smplrt_div = smplrt_div;
  const double per_read = std::max(1.0, std::round(o.settings.sample_rate_hz() / 1000.0));
  o.settings.read_interval_ns = static_cast<TimeNs>(2.0 * per_read * 1e9 / o.settings.sample_rate_hz());
  o.record_truth = true;
  auto created = sim::SimImuRig::create(emutest::wobble, o);
  EXPECT_TRUE(created.ok());
  if (!created.ok()) return {};
  sim::SimImuRig& rig = **created;
  std::vector<ImuSample> out, all;
  const TimeNs end = rig.emulator().now_ns() + s_to_ns(seconds);
  while (rig.emulator().now_ns() < end) {
    const auto st = rig.acquisition().step(out);
    EXPECT_TRUE(st.ok());
    if (!st.ok()) return {};
    all.insert(all.end(), out.begin(), out.end());
  }
  return emutest::account(all, rig.emulator(), 2 * kNsPerSecond);
}

// Sample times from the whole chain (the chip's own oscillator 1.5 % slow, 30 us RMS edge
// jitter, the driver's FIFO reads, the timestamper) against the chip's true sample instants;
// every frame the chip wrote is delivered once, in order.
TEST(SimRigTiming, SampleTimesMatchTheChipEndToEnd) {
  struct Case {
    const char* name;
    std::uint8_t dlpf_cfg, smplrt_div;
  };
  for (const Case c : {Case{"1 kHz, FIFO read per edge", 1, 0}, Case{"8 kHz, FIFO read every 8 edges", 0, 0},
                       Case{"200 Hz, FIFO read per edge", 1, 4}}) {
    const emutest::Accounting r = run_sim_rig(c.dlpf_cfg, c.smplrt_div, 10.0);
    std::printf("  %s: rms %.2f us, max %.1f us, %zu samples delivered, %zu left in the FIFO\n", c.name,
                r.rms_time_error_ns / 1e3, r.max_time_error_ns / 1e3, r.delivered, r.still_in_fifo);
    EXPECT_LT(r.rms_time_error_ns, 5'000.0) << c.name;
    EXPECT_LT(r.max_time_error_ns, 25'000.0) << c.name;
    EXPECT_EQ(r.lost, 0u) << c.name;
    EXPECT_GT(r.delivered, 1500u) << c.name;
    EXPECT_EQ(r.mismatched, 0u) << c.name;
    EXPECT_EQ(r.delivered + r.still_in_fifo, r.produced) << c.name;
    EXPECT_EQ(r.gap_flags, 0u) << c.name;
  }
}

TEST(RecordCli, SimRecordsTimestampedRawSamples) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_config(dir, "rig.yaml", "");
  const std::string log = dir + "/rec.imulog";
  const auto res =
      test::run_cli({"record", "--config", cfg, "-o", log, "--sim", "--duration", "2", "--json"});
  ASSERT_EQ(res.exit_code, 0) << res.err;
  const auto summary = nlohmann::json::parse(res.out);
  // The emulated chip runs 1.5 % slow (the default --sim-clock-ppm).
  EXPECT_NEAR(summary["period_error_ppm"].get<double>(), 15'228.0, 300.0);  // 1/(1-0.015) - 1
  EXPECT_EQ(summary["gaps"].get<int>(), 0);

  const auto rec = read_recorded_log(log);
  EXPECT_TRUE(rec.complete);
  EXPECT_EQ(rec.info.units, ImuUnits::kRaw);
  EXPECT_EQ(rec.info.accel_full_scale_g, 4);
  EXPECT_EQ(rec.info.gyro_full_scale_dps, 500);
  // 2 s at 1000 Hz * (1 - 0.015).
  ASSERT_NEAR(static_cast<double>(rec.samples.size()), 1970.0, 3.0);
  EXPECT_EQ(summary["samples"].get<std::size_t>(), rec.samples.size());
  // Strictly increasing, and every interval close to the chip's real period.
  for (std::size_t i = 1; i < rec.samples.size(); ++i) {
    const TimeNs d = rec.samples[i].t_ns - rec.samples[i - 1].t_ns;
    ASSERT_GT(d, 0);
    // Within the bounded window from the start, within 3 us once the period has been learnt.
    EXPECT_NEAR(static_cast<double>(d), 1e9 / 985.0, i < 200 ? 0.08e6 : 3'000.0) << i;
    EXPECT_EQ(rec.samples[i].flags & kImuFlagGapBefore, 0u) << i;
  }
  // At rest on a table: gravity on +z of the IMU, about 8192 counts at +-4 g.
  EXPECT_NEAR(rec.samples[100].accel.z(), 8192.0, 600.0);
  for (const char* key : {"rig_config", "imu.mounting", "imu.timing", "imu.driver", "imu.stream", "sim"}) {
    EXPECT_TRUE(rec.metadata.count(key)) << key;
  }
  const auto timing = nlohmann::json::parse(rec.metadata.at("imu.timing"));
  EXPECT_EQ(timing["gaps"].get<int>(), 0);
  const auto stream = nlohmann::json::parse(rec.metadata.at("imu.stream"));
  EXPECT_EQ(stream["log_dropped"].get<int>(), 0);
}

// The mounting remap, axis by axis, end to end: the same simulated rig recorded with the IMU
// mounted yaw 90 deg (rig x = -IMU y, rig y = +IMU x) gives exactly the remapped counts.
TEST(RecordCli, AxisPermutationMountingRemapsRawCountsExactly) {
  const std::string dir = test::scratch_dir();
  const std::string id_cfg = write_config(dir, "id.yaml", "");
  const std::string rot_cfg =
      write_config(dir, "rot.yaml", "  mounting:\n    R_rig_imu: [[0, -1, 0], [1, 0, 0], [0, 0, 1]]\n");
  const std::string a = dir + "/a.imulog", b = dir + "/b.imulog";
  ASSERT_EQ(test::run_cli({"record", "--config", id_cfg, "-o", a, "--sim", "--duration", "0.5"}).exit_code,
            0);
  const auto res = test::run_cli({"record", "--config", rot_cfg, "-o", b, "--sim", "--duration", "0.5"});
  ASSERT_EQ(res.exit_code, 0) << res.err;
  const auto ra = read_recorded_log(a), rb = read_recorded_log(b);
  ASSERT_EQ(ra.samples.size(), rb.samples.size());
  ASSERT_GT(ra.samples.size(), 400u);
  for (std::size_t i = 0; i < ra.samples.size(); ++i) {
    const auto& s = ra.samples[i];
    const auto& r = rb.samples[i];
    ASSERT_EQ(r.t_ns, s.t_ns);
    ASSERT_EQ(r.accel.x(), -s.accel.y()) << i;
    ASSERT_EQ(r.accel.y(), s.accel.x()) << i;
    ASSERT_EQ(r.accel.z(), s.accel.z()) << i;
    ASSERT_EQ(r.gyro.x(), -s.gyro.y()) << i;
    ASSERT_EQ(r.gyro.y(), s.gyro.x()) << i;
    ASSERT_EQ(r.gyro.z(), s.gyro.z()) << i;
  }
  const auto m = nlohmann::json::parse(rb.metadata.at("imu.mounting"));
  EXPECT_EQ(m["kind"], "axis-permutation");
  EXPECT_EQ(m["samples_frame"], "rig");
}

// A general rotation cannot be applied to int16 counts: samples stay in the IMU frame and the
// rotation is recorded for use in SI.
TEST(RecordCli, GeneralMountingKeepsImuFrameAndRecordsRotation) {
  const std::string dir = test::scratch_dir();
  const std::string id_cfg = write_config(dir, "id.yaml", "");
  const std::string rot_cfg = write_config(dir, "rot.yaml", "  mounting:\n    rpy_deg: [0, 0, 30]\n");
  const std::string a = dir + "/a.imulog", b = dir + "/b.imulog";
  ASSERT_EQ(test::run_cli({"record", "--config", id_cfg, "-o", a, "--sim", "--duration", "0.3"}).exit_code,
            0);
  const auto res = test::run_cli({"record", "--config", rot_cfg, "-o", b, "--sim", "--duration", "0.3"});
  ASSERT_EQ(res.exit_code, 0) << res.err;
  const auto ra = read_recorded_log(a), rb = read_recorded_log(b);
  ASSERT_EQ(ra.samples.size(), rb.samples.size());
  for (std::size_t i = 0; i < ra.samples.size(); ++i) ASSERT_EQ(ra.samples[i].accel, rb.samples[i].accel);
  const auto m = nlohmann::json::parse(rb.metadata.at("imu.mounting"));
  EXPECT_EQ(m["kind"], "general");
  EXPECT_EQ(m["samples_frame"], "imu");
  EXPECT_NEAR(m["R_rig_imu"][1][0].get<double>(), 0.5, 1e-9);  // sin 30 deg
}

TEST(RecordCli, RefusesToOverwriteWithoutForce) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_config(dir, "rig.yaml", "");
  const std::string log = dir + "/rec.imulog";
  ASSERT_EQ(test::run_cli({"record", "--config", cfg, "-o", log, "--sim", "--duration", "0.1"}).exit_code, 0);
  const auto again = test::run_cli({"record", "--config", cfg, "-o", log, "--sim", "--duration", "0.1"});
  EXPECT_NE(again.exit_code, 0);
  EXPECT_FALSE(again.err.empty());
  EXPECT_EQ(test::run_cli({"record", "--config", cfg, "-o", log, "--sim", "--duration", "0.1", "--force"})
                .exit_code,
            0);
}

TEST(RecordCli, MissingDeviceSaysWhatToCheck) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_config(dir, "spi.yaml", "  device: /dev/spidev97.3\n", "spi");
  const auto res = test::run_cli({"record", "--config", cfg, "-o", dir + "/x.imulog", "--duration", "1"});
  EXPECT_EQ(res.exit_code, 6) << res.err;
  EXPECT_NE(res.err.find("spidev97.3"), std::string::npos) << res.err;
}

TEST(RecordCli, BadDurationIsAUsageError) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_config(dir, "rig.yaml", "");
  const auto res =
      test::run_cli({"record", "--config", cfg, "-o", dir + "/x.imulog", "--sim", "--duration", "-1"});
  EXPECT_EQ(res.exit_code, 2);
  EXPECT_NE(res.err.find("duration"), std::string::npos);
}

}  // namespace
}  // namespace imucal::acq
