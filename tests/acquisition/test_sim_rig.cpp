// The simulated IMU path (acquisition/sim_rig.hpp) under host stalls: what the FIFO holds is
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

#include "acquisition/sim_rig.hpp"
#include "drivers/mpu6000/output_settings.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::acq {
namespace {

namespace mpu = drivers::mpu6000;

sim::SensorReading wobble(TimeNs t_ns) {
  const double t = ns_to_s(t_ns), two_pi = 2.0 * std::numbers::pi;
  sim::SensorReading r;
  r.specific_force = {2.0 * std::sin(two_pi * 2.3 * t), 1.5 * std::cos(two_pi * 1.1 * t), 9.81};
  r.angular_rate = {0.8 * std::sin(two_pi * 3.7 * t), 0.6 * std::cos(two_pi * 1.9 * t),
                    0.5 * std::sin(two_pi * 4.3 * t + 0.2)};
  r.temperature_c = 31.0;
  return r;
}

struct StallRun {
  std::vector<ImuSample> delivered;
  std::vector<sim::TruthSample> written;  // frames the chip wrote into its FIFO
  std::size_t gaps = 0;
  std::size_t mismatched = 0;  // delivered samples that are no frame the chip wrote
  std::size_t lost = 0;        // written frames, between the first and last delivered, never delivered
  double max_time_error_ns = 0.0;
};

StallRun run_with_stall(double rate_hz, double stall_at_s, double stall_s, double seconds) {
  mpu::OutputRequest req;
  req.rate_hz = rate_hz;
  auto settings = mpu::settings_for(req);
  EXPECT_TRUE(settings.ok());
  SimRigOptions o;
  o.settings = *settings;
  o.record_truth = true;
  auto created = SimImuRig::create(wobble, o);
  EXPECT_TRUE(created.ok());
  StallRun r;
  if (!created.ok()) return r;
  SimImuRig& rig = **created;
  const TimeNs t0 = rig.clock().now_ns();
  const TimeNs stall_begin = t0 + s_to_ns(stall_at_s), stall_end = stall_begin + s_to_ns(stall_s);
  bool stalled = false;
  std::vector<ImuSample> out;
  while (rig.clock().now_ns() < t0 + s_to_ns(seconds)) {
    if (!stalled && rig.clock().now_ns() >= stall_begin) {
      rig.stall_until(stall_end);
      stalled = true;
    }
    EXPECT_TRUE(rig.acquisition().step(out).ok());
    r.delivered.insert(r.delivered.end(), out.begin(), out.end());
  }
  for (const auto& t : rig.emulator().truth()) {
    if (t.to_fifo) r.written.push_back(t);
  }
  auto same = [](const ImuSample& a, const sim::TruthSample& b) {
    return a.accel == Eigen::Vector3d(b.accel[0], b.accel[1], b.accel[2]) &&
           a.gyro == Eigen::Vector3d(b.gyro[0], b.gyro[1], b.gyro[2]) && a.temperature == b.temp;
  };
  std::size_t j = 0, first = r.written.size(), last = 0;
  for (const ImuSample& s : r.delivered) {
    if (s.flags & kImuFlagGapBefore) ++r.gaps;
    std::size_t k = j;
    while (k < r.written.size() && !same(s, r.written[k])) ++k;
    if (k == r.written.size()) {
      ++r.mismatched;
      continue;
    }
    first = std::min(first, k);
    if (k > j && first != k) r.lost += k - j;
    last = k;
    j = k + 1;
    const double e = static_cast<double>(s.t_ns - r.written[k].t_ns);
    if (std::getenv("SIMRIG_DEBUG") && std::abs(e) > 20'000.0)
      std::printf("    k=%zu true %.6f stamped %.6f err %.1f us flags %u\n", k,
                  ns_to_s(r.written[k].t_ns - t0), ns_to_s(s.t_ns - t0), e / 1e3, s.flags);
    if (r.written[k].t_ns - t0 > 2 * kNsPerSecond)
      r.max_time_error_ns = std::max(r.max_time_error_ns, std::abs(e));
  }
  (void)last;
  return r;
}

TEST(SimRigStall, AStallTheFifoAbsorbsLosesNothing) {
  // 0.5 s at 100 Hz: 50 frames, the FIFO holds 73.
  const StallRun r = run_with_stall(100.0, 3.0, 0.5, 6.0);
  EXPECT_EQ(r.mismatched, 0u);
  EXPECT_EQ(r.lost, 0u);
  EXPECT_EQ(r.gaps, 0u);
  EXPECT_LT(r.max_time_error_ns, 100'000.0);
}

TEST(SimRigStall, ALongStallLosesOnlyBehindOneFlaggedGapAndKeepsTrueTimes) {
  for (double rate : {100.0, 1000.0}) {
    const StallRun r = run_with_stall(rate, 3.0, 2.0, 7.0);
    std::printf("  %.0f Hz: %zu delivered, %zu lost, %zu gaps, max time error %.1f us\n", rate,
                r.delivered.size(), r.lost, r.gaps, r.max_time_error_ns / 1e3);
    EXPECT_EQ(r.mismatched, 0u) << rate;
    EXPECT_EQ(r.gaps, 1u) << rate;
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
}  // namespace imucal::acq
