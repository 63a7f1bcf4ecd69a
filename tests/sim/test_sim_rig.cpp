// SPDX-License-Identifier: BSD-3-Clause
// The simulated IMU path (sim/rig.hpp) under host stalls: what the FIFO holds is
// delivered late but intact, what it cannot hold is lost behind one flagged gap, and every
// delivered sample is a frame the chip wrote, stamped near its true instant.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <vector>

#include "drivers/mpu6000/output_settings.hpp"
#include "sim/rig.hpp"
#include "tests/support/emulator_accounting.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::sim {
namespace {

namespace mpu = drivers::mpu6000;

/// Samples delivered through a stall of the host from `stall_at_s` for `stall_s`, accounted
/// against the emulator's frames (time errors after the first 2 s).
emutest::Accounting run_with_stall(double rate_hz, double stall_at_s, double stall_s, double seconds) {
  mpu::OutputRequest req;
  req.rate_hz = rate_hz;
  auto settings = mpu::settings_for(req);
  EXPECT_TRUE(settings.ok());
  SimRigOptions o;
  o.settings = *settings;
  o.record_truth = true;
  auto created = SimImuRig::create(emutest::wobble, o);
  EXPECT_TRUE(created.ok());
  if (!created.ok()) return {};
  SimImuRig& rig = **created;
  const TimeNs t0 = rig.clock().now_ns();
  const TimeNs stall_begin = t0 + s_to_ns(stall_at_s), stall_end = stall_begin + s_to_ns(stall_s);
  bool stalled = false;
  std::vector<ImuSample> out, all;
  while (rig.clock().now_ns() < t0 + s_to_ns(seconds)) {
    if (!stalled && rig.clock().now_ns() >= stall_begin) {
      rig.stall_until(stall_end);
      stalled = true;
    }
    EXPECT_TRUE(rig.acquisition().step(out).ok());
    all.insert(all.end(), out.begin(), out.end());
  }
  return emutest::account(all, rig.emulator(), 2 * kNsPerSecond);
}

TEST(SimRigStall, AStallTheFifoAbsorbsLosesNothing) {
  // 0.5 s at 100 Hz: 50 frames, the FIFO holds 73.
  const emutest::Accounting r = run_with_stall(100.0, 3.0, 0.5, 6.0);
  EXPECT_EQ(r.mismatched, 0u);
  EXPECT_EQ(r.lost, 0u);
  EXPECT_EQ(r.gap_flags, 0u);
  EXPECT_EQ(r.delivered + r.still_in_fifo, r.produced);
  EXPECT_LT(r.max_time_error_ns, 100'000.0);
}

TEST(SimRigStall, ALongStallLosesOnlyBehindOneFlaggedGapAndKeepsTrueTimes) {
  for (double rate : {100.0, 1000.0}) {
    const emutest::Accounting r = run_with_stall(rate, 3.0, 2.0, 7.0);
    std::printf("  %.0f Hz: %zu delivered, %zu lost, %zu gaps, max time error %.1f us\n", rate, r.delivered,
                r.lost, r.gap_flags, r.max_time_error_ns / 1e3);
    EXPECT_EQ(r.mismatched, 0u) << rate;
    EXPECT_EQ(r.unflagged_losses, 0u) << rate;
    EXPECT_EQ(r.gap_flags, 1u) << rate;
    // The whole stall at most, plus what was in the FIFO when it overflowed.
    EXPECT_GE(static_cast<double>(r.lost), 2.0 * rate * 0.985 - 74.0) << rate;
    EXPECT_LE(static_cast<double>(r.lost), 2.0 * rate + 2.0 * 74.0) << rate;
    EXPECT_LT(r.max_time_error_ns, 100'000.0) << rate;
  }
}

// `imucal record --sim --sim-motion static` moves the virtual rig through the multi-position
// protocol, and the recording calibrates like one from `imucal sim static`.
TEST(SimRigRecord, StaticMotionRecordsAProtocolThatCalibrates) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = dir + "/rig.yaml";
  {
    std::ofstream out(cfg);
    out << "name: test\nimu:\n  bus: sim\n  accel_range_g: 4\n  gyro_range_dps: 500\n  rate_hz: 100\n"
        << "  dlpf_hz: 42\nstorage:\n  backend: file\n  path: " << dir << "/calibration.bin\n";
  }
  const std::string log = dir + "/protocol.imulog";
  auto rec = test::run_cli({"record", "--config", cfg, "-o", log, "--sim", "--sim-motion", "static",
                            "--duration", "215", "--seed", "4"});
  ASSERT_EQ(rec.exit_code, 0) << rec.err;
  auto cal = test::run_cli({"calibrate", "static", log, "--gravity", "9.80665", "--json", dir + "/c.json"});
  ASSERT_EQ(cal.exit_code, 0) << cal.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/c.json"));
  EXPECT_GE(j["distinct_attitudes"].get<int>(), 30) << j["warnings"].dump();
  EXPECT_LT(j["quality"]["accel_gravity_magnitude"]["after"]["mean_mps2"].get<double>(), 0.01);
  EXPECT_LT(j["quality"]["gyro_gravity_direction"]["after"]["mean_rad"].get<double>(), 0.02);
  auto still =
      test::run_cli({"record", "--config", cfg, "-o", dir + "/still.imulog", "--sim", "--duration", "60"});
  ASSERT_EQ(still.exit_code, 0) << still.err;
  auto none = test::run_cli({"calibrate", "static", dir + "/still.imulog", "--gravity", "9.80665"});
  EXPECT_EQ(none.exit_code, 4) << "a rig at rest has one attitude, not a protocol: " << none.err;
}

}  // namespace
}  // namespace imucal::sim
