// SPDX-License-Identifier: BSD-3-Clause
// Simulated sessions written to a session log: stream description, events, determinism, gaps,
// saturation and the truth file round trip.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>

#include "log/session_log.hpp"
#include "sim/motion.hpp"
#include "sim/session.hpp"
#include "sim/truth.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::sim {
namespace {

std::unique_ptr<sim::PoseScript> short_static(std::uint64_t seed, double excitation = 1.0) {
  sim::StaticProtocolOptions o;
  o.poses = 9;
  o.initial_still_s = 5.0;
  o.excitation = excitation;
  auto r = sim::make_static_protocol(o, seed);
  EXPECT_TRUE(r.ok());
  return std::move(r).value();
}

SimImuSessionOptions options(std::uint64_t seed) {
  SimImuSessionOptions o;
  o.seed = seed;
  o.poses = 9;
  o.imu = sim::ImuModelParams::draw(seed);
  return o;
}

std::vector<ImuSample> read_all(const std::string& path, ImuStreamInfo* info = nullptr) {
  auto reader = log::SessionLogReader::open(path);
  EXPECT_TRUE(reader.ok()) << (reader.ok() ? "" : reader.error().message);
  if (!reader.ok()) return {};
  auto id = (*reader)->find_imu_stream();
  EXPECT_TRUE(id.ok());
  if (info) *info = (*reader)->imu_streams().at(*id);
  auto samples = (*reader)->read_imu(*id);
  EXPECT_TRUE(samples.ok());
  return samples.ok() ? *samples : std::vector<ImuSample>{};
}

// The checks of the session below, one per part of what it wrote.

void expect_raw_counts_with_nominal_conversion(const ImuStreamInfo& info) {
  EXPECT_EQ(info.units, ImuUnits::kRaw);
  EXPECT_EQ(info.device, "sim");
  EXPECT_EQ(info.accel_full_scale_g, 8);
  EXPECT_EQ(info.gyro_full_scale_dps, 1000);
  EXPECT_DOUBLE_EQ(info.accel.scale.x(), 9.80665 / 4096.0);
  EXPECT_DOUBLE_EQ(info.gyro.scale.z(), std::numbers::pi / 180.0 / 32.8);
  EXPECT_DOUBLE_EQ(info.temperature_scale, 1.0 / 340.0);
  EXPECT_DOUBLE_EQ(info.temperature_offset, 36.53);
  EXPECT_EQ(info.rate_hz, 100.0);
}

void expect_samples_at_the_chips_rate(const std::vector<ImuSample>& samples, const ImuStreamInfo& info,
                                      const sim::Trajectory& traj, const sim::SimTruth& truth) {
  // The emulated chip runs 1.5 % slow (the default): 98.5 samples per second of trajectory, each
  // stamped by the timestamper from the data-ready edges.
  const double duration = ns_to_s(traj.end_ns() - traj.start_ns());
  const double chip_period_ns = 1e7 / (1.0 - 0.015);
  EXPECT_NEAR(static_cast<double>(samples.size()), duration * 1e9 / chip_period_ns, 1.0);
  EXPECT_EQ(truth.recording.samples, static_cast<std::int64_t>(samples.size()));
  EXPECT_EQ(truth.recording.dropped_samples, 0);
  ASSERT_FALSE(samples.empty());
  EXPECT_GE(samples.front().t_ns, traj.start_ns());
  EXPECT_LE(samples.front().t_ns, traj.start_ns() + static_cast<TimeNs>(chip_period_ns) + 1);
  EXPECT_LE(samples.back().t_ns, traj.end_ns());
  for (std::size_t k = 0; k < samples.size(); ++k) {
    if (k > 0) {
      ASSERT_NEAR(static_cast<double>(samples[k].t_ns - samples[k - 1].t_ns), chip_period_ns, 20'000.0) << k;
    }
    EXPECT_EQ(samples[k].flags & kImuFlagGapBefore, 0u);
    for (int i = 0; i < 3; ++i) {
      ASSERT_EQ(samples[k].accel[i], std::round(samples[k].accel[i]));
      ASSERT_LE(std::abs(samples[k].gyro[i]), 32768.0);
    }
  }
  // First sample: flat rig, z reads about +1 g (within scale error, bias and noise).
  const double az_g = samples[0].accel.z() * info.accel.scale.z() / 9.80665;
  EXPECT_NEAR(az_g, 1.0, 0.15);
}

void expect_events_and_driver_metadata(const std::string& log, std::size_t samples) {
  auto reader = log::SessionLogReader::open(log);
  ASSERT_TRUE(reader.ok());
  EXPECT_TRUE((*reader)->health().complete);
  auto events = (*reader)->events();
  ASSERT_TRUE(events.ok());
  int begins = 0, ends = 0, stills = 0;
  for (const log::Event& e : *events) {
    begins += e.kind == "pose_begin";
    ends += e.kind == "pose_end";
    stills += e.kind == "still_begin";
  }
  EXPECT_EQ(begins, 9);
  EXPECT_EQ(ends, 9);
  EXPECT_EQ(stills, 1);
  EXPECT_TRUE((*reader)->metadata().count("sim"));
  EXPECT_TRUE((*reader)->metadata().count("rig_config"));
  // The samples went through the driver: its settings and counters are in the log.
  const auto driver = nlohmann::json::parse((*reader)->metadata().at("imu.driver"));
  EXPECT_EQ(driver["settings"]["smplrt_div"].get<int>(), 9);
  EXPECT_EQ(driver["settings"]["accel_full_scale_g"].get<int>(), 8);
  EXPECT_EQ(driver["counters"]["fifo_overflows"].get<int>(), 0);
  EXPECT_EQ(driver["counters"]["bad_transfers"].get<int>(), 0);
  EXPECT_GE(driver["counters"]["samples"].get<std::int64_t>(), static_cast<std::int64_t>(samples));
  const auto timing = nlohmann::json::parse((*reader)->metadata().at("imu.timing"));
  // The period is 1 / (1 - 0.015) = 1.015228 times nominal.
  EXPECT_NEAR(timing["period_error_ppm"].get<double>(), 15'228.4, 100.0);
}

/// The truth file round trip: the imu: section reads back to the same parameters, bit for bit,
/// and a session from them has the same samples.
void expect_truth_round_trip(const std::string& dir, const std::string& truth_path,
                             const SimImuSessionOptions& o, const sim::Trajectory& traj,
                             const std::vector<ImuSample>& samples) {
  auto loaded = sim::load_imu_params(truth_path);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->accel_scale, o.imu.accel_scale);
  EXPECT_EQ(loaded->accel_misalignment, o.imu.accel_misalignment);
  EXPECT_EQ(loaded->accel_bias, o.imu.accel_bias);
  EXPECT_EQ(loaded->gyro_scale, o.imu.gyro_scale);
  EXPECT_EQ(loaded->gyro_misalignment, o.imu.gyro_misalignment);
  EXPECT_EQ(loaded->q_body_gyro.coeffs(), o.imu.q_body_gyro.coeffs());
  EXPECT_EQ(loaded->g_sensitivity, o.imu.g_sensitivity);
  EXPECT_EQ(loaded->gyro_bias, o.imu.gyro_bias);
  EXPECT_EQ(loaded->accel_full_scale_g, 8);
  EXPECT_EQ(loaded->gyro_noise_density, o.imu.gyro_noise_density);

  const YAML::Node doc = YAML::LoadFile(truth_path);
  EXPECT_EQ(doc["seed"].as<std::uint64_t>(), 4u);
  EXPECT_EQ(doc["trajectory"]["poses"].as<int>(), 9);
  EXPECT_EQ(doc["trajectory"]["segments"].size(), 19u);
  EXPECT_TRUE(doc["canonical"]["counts"]["A_a"]);
  EXPECT_TRUE(doc["tedaldi"]["si"]["T_a"]);
  EXPECT_TRUE(doc["software_version"]);
  // Same seed, with the parameters from the truth file: the same samples.
  const std::string log2 = dir + "/s2.imulog";
  SimImuSessionOptions o2 = o;
  o2.imu = *loaded;
  o2.params_from_file = true;
  ASSERT_TRUE(write_sim_imu_session(o2, traj, log2, "").ok());
  const auto again = read_all(log2);
  ASSERT_EQ(again.size(), samples.size());
  for (std::size_t k = 0; k < samples.size(); ++k) {
    ASSERT_EQ(again[k].accel, samples[k].accel);
    ASSERT_EQ(again[k].gyro, samples[k].gyro);
  }
}

TEST(SimSession, WritesRawCountsWithNominalConversionEventsAndTruth) {
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/s.imulog", truth_path = sim::truth_path_for(log);
  EXPECT_EQ(truth_path, dir + "/s.truth.yaml");
  auto traj = short_static(4);
  SimImuSessionOptions o = options(4);
  o.imu.accel_full_scale_g = 8;
  o.imu.gyro_full_scale_dps = 1000;
  auto truth = write_sim_imu_session(o, *traj, log, truth_path);
  ASSERT_TRUE(truth.ok()) << truth.error().message;

  ImuStreamInfo info;
  const auto samples = read_all(log, &info);
  expect_raw_counts_with_nominal_conversion(info);
  ASSERT_NO_FATAL_FAILURE(expect_samples_at_the_chips_rate(samples, info, *traj, *truth));
  ASSERT_NO_FATAL_FAILURE(expect_events_and_driver_metadata(log, samples.size()));
  expect_truth_round_trip(dir, truth_path, o, *traj, samples);
}

TEST(SimSession, SameSeedSameSamplesOtherSeedOtherSamples) {
  const std::string dir = test::scratch_dir();
  std::vector<std::vector<ImuSample>> runs;
  for (std::uint64_t seed : {21u, 21u, 22u}) {
    const std::string log = dir + "/r" + std::to_string(runs.size()) + ".imulog";
    auto traj = short_static(seed);
    ASSERT_TRUE(write_sim_imu_session(options(seed), *traj, log, "").ok());
    runs.push_back(read_all(log));
  }
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (std::size_t k = 0; k < runs[0].size(); ++k) {
    ASSERT_EQ(runs[0][k].t_ns, runs[1][k].t_ns);
    ASSERT_EQ(runs[0][k].accel, runs[1][k].accel);
    ASSERT_EQ(runs[0][k].gyro, runs[1][k].gyro);
    ASSERT_EQ(runs[0][k].temperature, runs[1][k].temperature);
    ASSERT_EQ(runs[0][k].flags, runs[1][k].flags);
  }
  const std::size_t n = std::min(runs[0].size(), runs[2].size());
  std::size_t same = 0;
  for (std::size_t k = 0; k < n; ++k) same += runs[0][k].accel == runs[2][k].accel;
  EXPECT_LT(same, n / 10);
}

TEST(SimSession, HoldsReadConstantWithoutNoise) {
  const std::string dir = test::scratch_dir();
  auto traj = short_static(6);
  SimImuSessionOptions o = options(6);
  o.imu.accel_noise_density = o.imu.gyro_noise_density = 0.0;
  o.imu.accel_bias_random_walk = o.imu.gyro_bias_random_walk = 0.0;
  const std::string log = dir + "/h.imulog";
  ASSERT_TRUE(write_sim_imu_session(o, *traj, log, "").ok());
  const auto samples = read_all(log);
  int checked = 0;
  for (const sim::Segment& seg : traj->segments()) {
    if (seg.kind == "move") continue;
    const ImuSample* first = nullptr;
    for (const ImuSample& s : samples) {
      if (s.t_ns < seg.t0_ns || s.t_ns >= seg.t1_ns) continue;
      if (!first) first = &s;
      // Still: accel and gyro do not change (no noise, no tremor, no random walk).
      ASSERT_EQ(s.accel, first->accel);
      ASSERT_EQ(s.gyro, first->gyro);
      ++checked;
    }
    ASSERT_NE(first, nullptr);
    // The accelerometer magnitude reads about 1 g in every hold.
    EXPECT_NEAR(first->accel.norm() / 8192.0, 1.0, 0.1);
  }
  EXPECT_GT(checked, 500);
}

TEST(SimSession, HostStallsBeyondTheFifoLeaveAFlaggedGap) {
  const std::string dir = test::scratch_dir();
  auto traj = short_static(8);
  SimImuSessionOptions o = options(8);
  o.path.clock_ppm = 0.0;
  // 0.5 s fits in the 73-frame FIFO at 100 Hz: read late, nothing lost. 2 s does not.
  o.drops = {{5.0, 0.5}, {10.0, 2.0}};
  const std::string log = dir + "/g.imulog";
  auto truth = write_sim_imu_session(o, *traj, log, "");
  ASSERT_TRUE(truth.ok()) << truth.error().message;
  // At least the 2 s less what the FIFO held when the host came back; at most the whole stall
  // plus one FIFO's worth (the driver discards a full FIFO rather than trust it).
  EXPECT_GE(truth->recording.dropped_samples, 200 - 73);
  EXPECT_LE(truth->recording.dropped_samples, 200 + 74);
  const auto samples = read_all(log);
  int gaps = 0;
  for (std::size_t k = 1; k < samples.size(); ++k) {
    const TimeNs dt = samples[k].t_ns - samples[k - 1].t_ns;
    if (samples[k].flags & kImuFlagGapBefore) {
      ++gaps;
      EXPECT_GE(samples[k].t_ns, 10'000'000'000);
      EXPECT_LE(samples[k].t_ns, 12'100'000'000 + 730'000'000);
      EXPECT_NEAR(static_cast<double>(dt),
                  10e6 * (1.0 + static_cast<double>(truth->recording.dropped_samples)), 0.1e6);
    } else {
      // Right after the gap the timestamper starts again from single edges (30 us jitter).
      ASSERT_NEAR(static_cast<double>(dt), 10e6, 100e3) << "sample " << k << " at " << samples[k].t_ns;
    }
  }
  EXPECT_EQ(gaps, 1);
  auto reader = log::SessionLogReader::open(log);
  ASSERT_TRUE(reader.ok());
  const auto driver = nlohmann::json::parse((*reader)->metadata().at("imu.driver"));
  EXPECT_GE(driver["counters"]["fifo_overflows"].get<int>(), 1);
}

TEST(SimSession, ChipClockAndBusAreThoseAskedFor) {
  const std::string dir = test::scratch_dir();
  sim::StillOptions still;
  still.duration_s = 4.0;
  auto traj = sim::make_still(still, 5);
  ASSERT_TRUE(traj.ok());
  SimImuSessionOptions o = options(5);
  o.kind = o.script = "still";
  o.imu_rate_hz = 1000.0;
  o.path.bus = drivers::mpu6000::BusKind::kI2c;
  o.path.clock_ppm = 20'000.0;  // 2 % fast
  const std::string log = dir + "/c.imulog";
  auto truth = write_sim_imu_session(o, **traj, log, "");
  ASSERT_TRUE(truth.ok()) << truth.error().message;
  const auto samples = read_all(log);
  ASSERT_GT(samples.size(), 1000u);
  const double mean_dt = static_cast<double>(samples.back().t_ns - samples.front().t_ns) /
                         static_cast<double>(samples.size() - 1);
  EXPECT_NEAR(mean_dt, 1e6 / 1.02, 0.5);
  EXPECT_EQ(truth->recording.dropped_samples, 0);
  for (const ImuSample& s : samples) ASSERT_EQ(s.flags & kImuFlagGapBefore, 0u);
  auto reader = log::SessionLogReader::open(log);
  ASSERT_TRUE(reader.ok());
  const auto rig = nlohmann::json::parse((*reader)->metadata().at("rig_config"));
  EXPECT_EQ(rig["imu"]["bus"].get<std::string>(), "i2c");
  const auto driver = nlohmann::json::parse((*reader)->metadata().at("imu.driver"));
  EXPECT_EQ(driver["settings"]["bus"].get<std::string>(), "i2c");
  EXPECT_EQ(driver["settings"]["smplrt_div"].get<int>(), 0);
  EXPECT_EQ(driver["settings"]["dlpf_cfg"].get<int>(), 1);  // 188 Hz below the 500 Hz Nyquist
}

TEST(SimSession, RatesTheChipCannotProduceAreRefusedWithTheNearestOnes) {
  const std::string dir = test::scratch_dir();
  auto traj = short_static(3);
  SimImuSessionOptions o = options(3);
  o.imu_rate_hz = 300.0;
  auto r = write_sim_imu_session(o, *traj, dir + "/r.imulog", "");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInvalidArgument);
  EXPECT_NE(r.error().message.find("cannot produce 300 Hz"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("nearest"), std::string::npos) << r.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir + "/r.imulog"));
}

TEST(SimSession, FastMovesSaturateANarrowRange) {
  const std::string dir = test::scratch_dir();
  auto traj = short_static(9, 3.0);
  SimImuSessionOptions o = options(9);
  o.imu.accel_full_scale_g = 2;
  o.imu.gyro_full_scale_dps = 250;
  const std::string log = dir + "/sat.imulog";
  auto truth = write_sim_imu_session(o, *traj, log, "");
  ASSERT_TRUE(truth.ok());
  EXPECT_GT(truth->recording.gyro_saturated, 0);
  EXPECT_GT(truth->recording.accel_saturated, 0);
  int flagged = 0;
  for (const ImuSample& s : read_all(log)) {
    if (s.flags & kImuFlagGyroSaturated) {
      ++flagged;
      EXPECT_EQ(s.gyro.cwiseAbs().maxCoeff() >= 32767.0, true);
    }
  }
  EXPECT_EQ(flagged, truth->recording.gyro_saturated);
}

TEST(SimSession, RefusesToOverwriteAndRejectsBadOptions) {
  const std::string dir = test::scratch_dir();
  auto traj = short_static(2);
  const std::string log = dir + "/o.imulog";
  ASSERT_TRUE(write_sim_imu_session(options(2), *traj, log, "").ok());
  auto again = write_sim_imu_session(options(2), *traj, log, "");
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, Errc::kAlreadyExists) << again.error().message;
  EXPECT_NE(again.error().message.find(log + " already exists"), std::string::npos);
  SimImuSessionOptions forced = options(2);
  forced.overwrite = true;
  EXPECT_TRUE(write_sim_imu_session(forced, *traj, log, "").ok());
  SimImuSessionOptions bad = options(2);
  bad.imu_rate_hz = 1.0;
  bad.overwrite = true;
  EXPECT_FALSE(write_sim_imu_session(bad, *traj, log, "").ok());
}

TEST(SimTruth, BadTruthFilesGiveClearErrors) {
  const std::string dir = test::scratch_dir();
  EXPECT_EQ(sim::load_imu_params(dir + "/missing.yaml").error().code, Errc::kNotFound);
  const std::string bad = dir + "/bad.yaml";
  {
    std::ofstream f(bad);
    f << "imu:\n  accel:\n    scale: [1, 1]\n  gyro: {}\n";
  }
  auto r = sim::load_imu_params(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("imu.accel.scale"), std::string::npos) << r.error().message;
  {
    std::ofstream f(bad);
    f << "imu:\n  accel: {}\n  gyro:\n    bias_radps: [5, 0, 0]\n";
  }
  r = sim::load_imu_params(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("deg/s"), std::string::npos) << r.error().message;
  {
    std::ofstream f(bad);
    f << "imu: [unclosed\n";
  }
  EXPECT_EQ(sim::load_imu_params(bad).error().code, Errc::kCorrupt);
}

}  // namespace
}  // namespace imucal::sim
