// SPDX-License-Identifier: BSD-3-Clause
// Checking given calibrations on a fixed set of static intervals and motions: the rotation
// convention on a known rotation, the figures of the true and of perturbed models on a synthetic
// recording, the breaks the set never crosses, and the two calibration formats read.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "app/calibration_check.hpp"
#include "app/results/output.hpp"
#include "app/results/static_results.hpp"
#include "tests/calib/test_static_synth.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

/// Two static poses joined by a rotation of `angle` about body x at a constant rate: gravity
/// (specific force, +g up) starts along body z and ends at Rx(angle)^T z = (0, sin, cos).
CheckSet rotation_about_x(double angle, double rate_sign) {
  const double g = 9.80665;
  const double duration = 2.0;
  const int n = 201;
  CheckSet set;
  set.intervals.resize(2);
  set.intervals[0].accel_mean_raw = Eigen::Vector3d(0, 0, g);
  set.intervals[1].accel_mean_raw = Eigen::Vector3d(0, g * std::sin(angle), g * std::cos(angle));
  for (auto& iv : set.intervals) {  // one second at rest
    for (int i = 0; i < 100; ++i) {
      iv.t_s.push_back(0.01 * i);
      iv.accel_raw.push_back(iv.accel_mean_raw);
      iv.gyro_raw.push_back(Eigen::Vector3d::Zero());
    }
  }
  CheckTransfer tr;
  tr.from = 0;
  for (int i = 0; i < n; ++i) {
    tr.t_s.push_back(duration * i / (n - 1));
    tr.gyro_raw.push_back(Eigen::Vector3d(rate_sign * angle / duration, 0, 0));
    tr.accel_raw.push_back(Eigen::Vector3d(0, 0, g));  // unused with G = 0
  }
  set.transfers.push_back(tr);
  return set;
}

TEST(CalibrationCheck, GyroCarriesGravityWithTheBodyRotationConvention) {
  const double angle = 1.2;
  const CheckFiguresPair ok = check_calibration(rotation_about_x(angle, 1.0), CanonicalImuModel{}, 9.80665);
  EXPECT_EQ(ok.gravity_magnitude_mps2.count, 2);
  EXPECT_NEAR(ok.gravity_magnitude_mps2.max, 0.0, 1e-12);
  ASSERT_EQ(ok.gravity_direction_rad.count, 1);
  EXPECT_LT(ok.gravity_direction_rad.max, 1e-9);
  // The opposite rotation direction would end 2 * angle away.
  const CheckFiguresPair wrong =
      check_calibration(rotation_about_x(angle, -1.0), CanonicalImuModel{}, 9.80665);
  EXPECT_NEAR(wrong.gravity_direction_rad.max, 2 * angle, 1e-6);
}

TEST(CalibrationCheck, GSensitivityActsOnTheCalibratedAccelerometer) {
  // A gyro that reads g-sensitivity G a on top of the rate: the model with that G is exact.
  const double angle = 0.8;
  CheckSet set = rotation_about_x(angle, 1.0);
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  G(0, 2) = 2e-3;  // rad/s per m/s^2: x rate from the z specific force
  for (auto& iv : set.intervals) {
    for (std::size_t i = 0; i < iv.gyro_raw.size(); ++i) iv.gyro_raw[i] += G * iv.accel_raw[i];
  }
  for (auto& w : set.transfers[0].gyro_raw) w += G * set.transfers[0].accel_raw[0];
  CanonicalImuModel with_g;
  with_g.G = G;
  EXPECT_LT(check_calibration(set, with_g, 9.80665).gravity_direction_rad.max, 1e-9);
  EXPECT_GT(check_calibration(set, CanonicalImuModel{}, 9.80665).gravity_direction_rad.max, 0.03);
}

struct Synth {
  test::SynthConfig cfg;
  test::SynthRecording rec;
  CanonicalImuModel truth;
};

Synth synthetic(unsigned seed) {
  Synth s;
  s.cfg.seed = seed;
  s.cfg.truth = test::random_truth(seed);
  s.cfg.poses = 36;
  s.cfg.hold_min_s = 2.0;
  s.cfg.hold_max_s = 4.0;
  s.rec = test::make_static_recording(s.cfg);
  s.truth = canonical_from_tedaldi(s.cfg.truth);
  return s;
}

TEST(CalibrationCheck, FindsTheHeldPosesOfASyntheticRecording) {
  const Synth s = synthetic(11);
  auto set = build_check_set(s.rec.samples);
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(set->intervals.size(), s.rec.holds_s.size());  // the still start and every hold
  EXPECT_EQ(set->transfers.size(), set->intervals.size() - 1);
  EXPECT_EQ(set->gaps, 0);
  EXPECT_NEAR(set->rate_hz, 100.0, 1e-6);
  // Interval k overlaps hold k and no other (it may reach into the slow start or end of a move).
  for (std::size_t k = 0; k < set->intervals.size(); ++k) {
    const double t0 = ns_to_s(set->intervals[k].t0_ns), t1 = ns_to_s(set->intervals[k].t1_ns);
    for (std::size_t h = 0; h < s.rec.holds_s.size(); ++h) {
      const bool overlaps = t0 <= s.rec.holds_s[h].second && t1 >= s.rec.holds_s[h].first;
      EXPECT_EQ(overlaps, h == k) << "interval " << k << " (" << t0 << "-" << t1 << " s), hold " << h;
    }
  }
}

TEST(CalibrationCheck, TrueModelScoresAtTheNoiseLevelAndPerturbedModelsWorse) {
  const Synth s = synthetic(12);
  auto set = build_check_set(s.rec.samples);
  ASSERT_TRUE(set.ok()) << set.error().message;
  const double g = s.cfg.gravity;
  const CheckFiguresPair truth = check_calibration(*set, s.truth, g);
  // Noise: accel 0.039 m/s^2 per sample over >= 100 samples; gyro 0.87 mrad/s per sample.
  // Observed: 0.0024 m/s^2 and 0.57 mrad RMS.
  EXPECT_LT(truth.gravity_magnitude_mps2.rms, 0.005);
  EXPECT_LT(truth.gravity_direction_rad.rms, 1.0e-3);

  CanonicalImuModel gyro_scale = s.truth;  // +1 % on the x axis of the gyro
  gyro_scale.A_g = Eigen::Vector3d(1.01, 1.0, 1.0).asDiagonal() * s.truth.A_g;
  CanonicalImuModel gyro_mis = s.truth;  // 5 mrad between the gyro's x and y axes
  gyro_mis.A_g(0, 1) += 5e-3 * s.truth.A_g(1, 1);
  CanonicalImuModel accel_scale = s.truth;  // +0.5 % on the accelerometer's z axis
  accel_scale.A_a = Eigen::Vector3d(1.0, 1.0, 1.005).asDiagonal() * s.truth.A_a;

  const CheckFiguresPair fs = check_calibration(*set, gyro_scale, g);
  const CheckFiguresPair fm = check_calibration(*set, gyro_mis, g);
  const CheckFiguresPair fa = check_calibration(*set, accel_scale, g);
  EXPECT_GT(fs.gravity_direction_rad.rms, 5.0 * truth.gravity_direction_rad.rms);    // observed 10x
  EXPECT_GT(fm.gravity_direction_rad.rms, 3.0 * truth.gravity_direction_rad.rms);    // 5.5x
  EXPECT_GT(fa.gravity_magnitude_mps2.rms, 4.0 * truth.gravity_magnitude_mps2.rms);  // 7x
  // A gyro change leaves the accelerometer figure alone.
  EXPECT_DOUBLE_EQ(fs.gravity_magnitude_mps2.rms, truth.gravity_magnitude_mps2.rms);
}

TEST(CalibrationCheck, TheSetDoesNotDependOnRawCountsOrSi) {
  // The same motion in counts centred at 32768: the same intervals, and the counts-form truth
  // gives the same figures as the SI one.
  Synth si = synthetic(13);
  test::SynthConfig cfg = si.cfg;
  cfg.raw_counts = true;
  const auto counts = test::make_static_recording(cfg);
  auto set_si = build_check_set(si.rec.samples);
  auto set_counts = build_check_set(counts.samples);
  ASSERT_TRUE(set_si.ok() && set_counts.ok());
  EXPECT_EQ(set_si->intervals.size(), set_counts->intervals.size());
  CanonicalImuModel m = si.truth;
  m.A_a = si.truth.A_a * cfg.accel_lsb;
  m.b_a = Eigen::Vector3d::Constant(cfg.accel_offset) + si.truth.b_a / cfg.accel_lsb;
  m.A_g = si.truth.A_g * cfg.gyro_lsb;
  m.b_g = Eigen::Vector3d::Constant(cfg.gyro_offset) + si.truth.b_g / cfg.gyro_lsb;
  const auto f = check_calibration(*set_counts, m, cfg.gravity);
  EXPECT_LT(f.gravity_magnitude_mps2.rms, 0.005);
  EXPECT_LT(f.gravity_direction_rad.rms, 1.0e-3);
}

TEST(CalibrationCheck, NoIntervalOrTransferCrossesAGapOrSaturation) {
  Synth s = synthetic(14);
  auto clean = build_check_set(s.rec.samples);
  ASSERT_TRUE(clean.ok());
  ASSERT_GE(clean->intervals.size(), 10u);
  // A gap in the motion after interval 3, a saturated gyro sample in the motion after interval 6,
  // and a device reset in the middle of the still start (interval 0).
  auto& samples = s.rec.samples;
  const auto mid = [&](std::size_t k) {
    return (clean->intervals[k].end + clean->intervals[k + 1].begin) / 2;
  };
  samples[mid(3)].flags |= kImuFlagGapBefore;
  samples[mid(6)].flags |= kImuFlagGyroSaturated;
  const std::size_t reset = (clean->intervals[0].begin + clean->intervals[0].end) / 2;
  samples[reset].flags |= kImuFlagDeviceReset;
  auto set = build_check_set(samples);
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(set->gaps, 2);
  EXPECT_EQ(set->gyro_saturated, 1);
  EXPECT_EQ(set->motions_with_gap, 2);  // the gap's motion and the reset, now between two halves
  EXPECT_EQ(set->motions_with_saturation, 1);
  EXPECT_EQ(set->intervals.size(), clean->intervals.size() + 1);  // the still start split in two
  EXPECT_EQ(set->transfers.size(), set->intervals.size() - 1 - 3);
  for (const auto& iv : set->intervals) {
    for (std::size_t i = iv.begin + 1; i < iv.end; ++i) EXPECT_EQ(samples[i].flags, 0u) << i;
  }
}

TEST(CalibrationCheck, RefusesARecordingWithoutPosesOrWithTimeGoingBack) {
  // 30 s at rest: one static interval, no motion to check the gyro on.
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.04);
  std::vector<ImuSample> still(3000);
  for (std::size_t i = 0; i < still.size(); ++i) {
    still[i].t_ns = static_cast<TimeNs>(i) * 10'000'000;
    still[i].accel = Eigen::Vector3d(noise(rng), noise(rng), 9.8 + noise(rng));
  }
  auto set = build_check_set(still);
  ASSERT_FALSE(set.ok());
  EXPECT_EQ(set.error().code, Errc::kInsufficientData);
  EXPECT_NE(set.error().message.find("found 1 static interval(s)"), std::string::npos) << set.error().message;

  still[10].t_ns = still[9].t_ns;
  auto bad_time = build_check_set(still);
  ASSERT_FALSE(bad_time.ok());
  EXPECT_EQ(bad_time.error().code, Errc::kCorrupt);
}

// ---- formats ----------------------------------------------------------------------------------

// /tmp/peers/runs/test_imu_acc.calib as imu_tk writes it (Eigen's stream format).
const char* kImuTkAcc =
    "          1  -0.0033593 -0.00890639\n"
    "          0           1  -0.0213341\n"
    "         -0           0           1\n"
    "\n"
    "0.00241278          0          0\n"
    "         0 0.00242712          0\n"
    "         0          0 0.00241168\n"
    "\n"
    "33124.2\n"
    "33275.2\n"
    "32364.4\n"
    "\n";

// The paired comparison of two calibrations' RMS: the difference and its standard error by
// hand on four items, and the standard error's meaning: over many pairs of calibrations whose
// per-transfer errors come from one distribution, the difference lies within two standard
// errors about 95 % of the time.
TEST(CalibrationCheck, PairedRmsDifferenceAndItsStandardError) {
  const std::vector<double> a = {1, 2, 3, 4}, b = {2, 2, 3, 4};
  const RmsDifference r = paired_rms_difference(a, b);
  EXPECT_EQ(r.count, 4);
  // RMS 7.5^0.5 and 8.25^0.5; squares differ by (3, 0, 0, 0): mean 0.75, sd 1.5, error 0.75.
  EXPECT_NEAR(r.difference, std::sqrt(8.25) - std::sqrt(7.5), 1e-15);
  EXPECT_NEAR(r.sigma, 0.75 / (std::sqrt(8.25) + std::sqrt(7.5)), 1e-15);
  const RmsDifference same = paired_rms_difference(a, a);
  EXPECT_EQ(same.difference, 0.0);
  EXPECT_EQ(same.sigma, 0.0);
  EXPECT_TRUE(std::isnan(paired_rms_difference(std::vector<double>{1.0}, std::vector<double>{2.0}).sigma));

  std::mt19937 rng(7);
  std::normal_distribution<double> n01;
  int within = 0;
  constexpr int kTrials = 2000;
  for (int trial = 0; trial < kTrials; ++trial) {
    std::vector<double> x(38), y(38);
    for (std::size_t i = 0; i < x.size(); ++i) {
      // A shared part (the motion's own difficulty) and each calibration's own error.
      const double shared = 10.0 * std::abs(n01(rng));
      x[i] = shared + 2.0 * std::abs(n01(rng));
      y[i] = shared + 2.0 * std::abs(n01(rng));
    }
    const RmsDifference d = paired_rms_difference(x, y);
    if (std::abs(d.difference) <= 2.0 * d.sigma) ++within;
  }
  EXPECT_NEAR(static_cast<double>(within) / kTrials, 0.95, 0.02);  // 1905 of 2000
}

TEST(CalibrationCheckFormats, ImuTkTriadIsTKTimesRawMinusB) {
  auto t = parse_imu_tk_triad(kImuTkAcc, "acc.calib");
  ASSERT_TRUE(t.ok()) << t.error().message;
  Eigen::Matrix3d T;
  T << 1, -0.0033593, -0.00890639, 0, 1, -0.0213341, 0, 0, 1;
  const Eigen::Matrix3d K = Eigen::Vector3d(0.00241278, 0.00242712, 0.00241168).asDiagonal();
  EXPECT_TRUE(t->A.isApprox(T * K, 1e-15));
  EXPECT_EQ(t->b, Eigen::Vector3d(33124.2, 33275.2, 32364.4));
}

TEST(CalibrationCheckFormats, MalformedImuTkFilesAreRefusedNamingTheFile) {
  std::string short_text = kImuTkAcc;
  short_text.resize(short_text.rfind("32364.4"));  // 20 numbers
  auto a = parse_imu_tk_triad(short_text, "cut.calib");
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.error().code, Errc::kCorrupt);
  EXPECT_NE(a.error().message.find("cut.calib: 20 numbers found, 21 expected"), std::string::npos)
      << a.error().message;

  std::string word = kImuTkAcc;
  word.replace(word.find("33275.2"), 7, "bias_y");
  auto b = parse_imu_tk_triad(word, "word.calib");
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().message.find("word.calib: 'bias_y' (value 20) is not a finite number"),
            std::string::npos)
      << b.error().message;

  const std::string dir = test::scratch_dir();
  std::ofstream(dir + "/acc.calib") << kImuTkAcc;
  std::ofstream(dir + "/gyro.calib") << word;
  auto pair = read_imu_tk_calibration(dir + "/acc.calib", dir + "/gyro.calib");
  ASSERT_FALSE(pair.ok());
  EXPECT_NE(pair.error().message.find(dir + "/gyro.calib: 'bias_y'"), std::string::npos)
      << pair.error().message;
  auto missing = read_imu_tk_calibration(dir + "/acc.calib", dir + "/none.calib");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::kNotFound);
  EXPECT_NE(missing.error().message.find(dir + "/none.calib"), std::string::npos);
}

TEST(CalibrationCheckFormats, ImuTkPairReadsAsOneCanonicalModel) {
  const std::string dir = test::scratch_dir();
  std::ofstream(dir + "/acc.calib") << kImuTkAcc;
  std::ofstream(dir + "/gyro.calib") << "1 0.1 0 0 1 0 0 0 1  2 0 0 0 3 0 0 0 4  5 6 7\n";
  auto c = read_imu_tk_calibration(dir + "/acc.calib", dir + "/gyro.calib");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->name, "acc.calib + gyro.calib");
  EXPECT_EQ(c->format, "imu_tk");
  EXPECT_FALSE(c->input_units.has_value());
  Eigen::Matrix3d Ag;
  Ag << 2, 0.3, 0, 0, 3, 0, 0, 0, 4;
  EXPECT_TRUE(c->model.A_g.isApprox(Ag));
  EXPECT_EQ(c->model.b_g, Eigen::Vector3d(5, 6, 7));
  EXPECT_EQ(c->model.b_a, Eigen::Vector3d(33124.2, 33275.2, 32364.4));
  EXPECT_TRUE(c->model.G.isZero());
  // Applied as T K (raw - B).
  EXPECT_TRUE(c->model.correct_gyro(Eigen::Vector3d(6, 6, 8), Eigen::Vector3d(0, 0, 9.8))
                  .isApprox(Eigen::Vector3d(2, 0, 4)));
}

TEST(CalibrationCheckFormats, ImucalResultYamlRoundTrips) {
  calib::StaticCalibrationResult r;
  r.canonical.A_a << 5.9e-4, -5.8e-6, -1.9e-5, 0, 5.9e-4, -1.4e-5, 0, 0, 5.8e-4;
  r.canonical.b_a = Eigen::Vector3d(32424.2, 32805.4, 31850.44);
  r.canonical.A_g << 1.3e-4, -8.3e-7, -4.2e-6, -2.3e-6, 1.35e-4, -1.0e-6, 2.5e-6, -3.4e-6, 1.3e-4;
  r.canonical.b_g = Eigen::Vector3d(32709.4, 33416.5, 32749.75);
  r.canonical.G << 1e-4, 2e-5, -3e-4, 0, 0, 1e-5, 0, 0, 0;
  r.gravity_mps2 = 9.81;
  ImuStreamInfo info;
  info.units = ImuUnits::kRaw;
  const std::string dir = test::scratch_dir();
  ASSERT_TRUE(write_text_file(dir + "/result.yaml", static_result_yaml(r, info)).ok());
  auto c = read_imucal_calibration(dir + "/result.yaml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->name, "result.yaml");
  EXPECT_EQ(c->format, "imucal");
  ASSERT_TRUE(c->input_units.has_value());
  EXPECT_EQ(*c->input_units, ImuUnits::kRaw);
  EXPECT_TRUE(c->model.A_a.isApprox(r.canonical.A_a, 1e-11));
  EXPECT_TRUE(c->model.b_a.isApprox(r.canonical.b_a, 1e-11));
  EXPECT_TRUE(c->model.A_g.isApprox(r.canonical.A_g, 1e-11));
  EXPECT_TRUE(c->model.b_g.isApprox(r.canonical.b_g, 1e-11));
  EXPECT_TRUE(c->model.G.isApprox(r.canonical.G, 1e-11));
}

TEST(CalibrationCheckFormats, MalformedImucalYamlIsRefusedNamingTheFileAndTheKey) {
  auto none = parse_imucal_calibration("accel: {scale: [1, 1, 1]}\n", "other.yaml");
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.error().code, Errc::kCorrupt);
  EXPECT_NE(none.error().message.find("other.yaml: no 'canonical:' section"), std::string::npos);
  auto rows = parse_imucal_calibration(
      "canonical:\n  A_a: [[1, 0, 0], [0, 1, 0]]\n  b_a: [0, 0, 0]\n  A_g: [[1, 0, 0], [0, 1, 0], [0, 0, "
      "1]]\n"
      "  b_g: [0, 0, 0]\n  G: [[0, 0, 0], [0, 0, 0], [0, 0, 0]]\n",
      "rows.yaml");
  ASSERT_FALSE(rows.ok());
  EXPECT_NE(rows.error().message.find("rows.yaml: canonical.A_a must be 3 rows of 3 numbers"),
            std::string::npos)
      << rows.error().message;
  auto word = parse_imucal_calibration(
      "canonical:\n  A_a: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  b_a: [0, x, 0]\n  A_g: [[1, 0, 0], [0, 1, 0], "
      "[0, "
      "0, 1]]\n  b_g: [0, 0, 0]\n  G: [[0, 0, 0], [0, 0, 0], [0, 0, 0]]\n",
      "word.yaml");
  ASSERT_FALSE(word.ok());
  EXPECT_NE(word.error().message.find("word.yaml: canonical.b_a holds 'x'"), std::string::npos)
      << word.error().message;
  auto yaml = parse_imucal_calibration("canonical: [\n", "broken.yaml");
  ASSERT_FALSE(yaml.ok());
  EXPECT_NE(yaml.error().message.find("broken.yaml: not valid YAML"), std::string::npos);
}

TEST(CalibrationCheck, CrossingGivesEachGyroscopeTheFirstAccelerometer) {
  const Synth s = synthetic(16);
  auto set = build_check_set(s.rec.samples);
  ASSERT_TRUE(set.ok()) << set.error().message;
  NamedCalibration truth{"truth.yaml", "imucal", "/x/truth.yaml", s.truth, ImuUnits::kSi, "", std::nullopt};
  NamedCalibration accel_off = truth;  // +0.5 % on the accelerometer's z axis, the truth's gyro
  accel_off.name = "accel_off.yaml";
  accel_off.model.A_a = Eigen::Vector3d(1.0, 1.0, 1.005).asDiagonal() * s.truth.A_a;
  accel_off.model.b_a += Eigen::Vector3d(0.01, 0.0, 0.0);
  NamedCalibration gyro_off = truth;  // +1 % on the gyro's x axis and another G, the truth's accelerometer
  gyro_off.name = "gyro_off.yaml";
  gyro_off.model.A_g = Eigen::Vector3d(1.01, 1.0, 1.0).asDiagonal() * s.truth.A_g;
  gyro_off.model.G(0, 0) += 1e-4;

  EXPECT_TRUE(gyro_with_first_accelerometer({truth}).empty());
  const auto crossed = gyro_with_first_accelerometer({truth, accel_off, gyro_off});
  ASSERT_EQ(crossed.size(), 2u);
  EXPECT_EQ(crossed[0].name, "[gyro] accel_off.yaml");
  EXPECT_EQ(crossed[0].accelerometer_of, "truth.yaml");
  EXPECT_EQ(crossed[1].name, "[gyro] gyro_off.yaml");
  EXPECT_EQ(crossed[1].model.A_a, truth.model.A_a);
  EXPECT_EQ(crossed[1].model.b_a, truth.model.b_a);
  EXPECT_EQ(crossed[1].model.A_g, gyro_off.model.A_g);
  EXPECT_EQ(crossed[1].model.b_g, gyro_off.model.b_g);
  EXPECT_EQ(crossed[1].model.G, gyro_off.model.G);

  // The accelerometer moves the direction figure too; with the first's accelerometer, a
  // calibration whose gyroscope is the first's scores exactly as the first.
  const double g = s.cfg.gravity;
  const CheckFiguresPair f_truth = check_calibration(*set, truth.model, g);
  const CheckFiguresPair f_accel = check_calibration(*set, accel_off.model, g);
  const CheckFiguresPair f_cross = check_calibration(*set, crossed[0].model, g);
  EXPECT_NE(f_accel.gravity_direction_rad.rms, f_truth.gravity_direction_rad.rms);
  EXPECT_EQ(f_cross.direction_per_transfer_rad, f_truth.direction_per_transfer_rad);
  EXPECT_EQ(f_cross.magnitude_per_interval_mps2, f_truth.magnitude_per_interval_mps2);
  // And the crossed gyro_off differs from the first by its gyroscope alone: the same as gyro_off.
  EXPECT_EQ(check_calibration(*set, crossed[1].model, g).direction_per_transfer_rad,
            check_calibration(*set, gyro_off.model, g).direction_per_transfer_rad);
}

TEST(CalibrationCheckFormats, JsonReportHoldsTheSetAndOneEntryPerCalibration) {
  const Synth s = synthetic(15);
  auto set = build_check_set(s.rec.samples);
  ASSERT_TRUE(set.ok());
  NamedCalibration truth{"truth.yaml", "imucal", "/x/truth.yaml", s.truth, ImuUnits::kSi, "", std::nullopt};
  NamedCalibration ident{"a.calib + g.calib", "imu_tk", "a.calib,g.calib", CanonicalImuModel{},
                         std::nullopt,        "",       std::nullopt};
  const std::vector<CheckFiguresPair> figs = {check_calibration(*set, truth.model, 9.80665),
                                              check_calibration(*set, ident.model, 9.80665)};
  const auto j = nlohmann::json::parse(
      calibration_check_json("rec.imulog", ImuStreamInfo{}, *set, 9.80665, "given", {truth, ident}, figs));
  EXPECT_EQ(j["check_set"]["static_intervals"].size(), set->intervals.size());
  EXPECT_EQ(j["check_set"]["transfers"].size(), set->transfers.size());
  EXPECT_EQ(j["check_set"]["rule"]["multiplier"].get<double>(), 6.0);
  ASSERT_EQ(j["calibrations"].size(), 2u);
  EXPECT_EQ(j["calibrations"][1]["format"], "imu_tk");
  EXPECT_DOUBLE_EQ(j["calibrations"][0]["gravity_direction_rad"]["rms"].get<double>(),
                   figs[0].gravity_direction_rad.rms);
  EXPECT_EQ(j["calibrations"][0]["magnitude_per_interval_mps2"].size(), set->intervals.size());
  EXPECT_EQ(j["calibrations"][0]["direction_per_transfer_rad"].size(), set->transfers.size());
  EXPECT_FALSE(j["calibrations"][1].contains("accelerometer_of"));

  // A crossed calibration names the one whose accelerometer it has.
  const auto crossed = gyro_with_first_accelerometer({truth, ident});
  const auto jc = nlohmann::json::parse(calibration_check_json(
      "rec.imulog", ImuStreamInfo{}, *set, 9.80665, "given", {truth, ident, crossed[0]},
      {figs[0], figs[1], check_calibration(*set, crossed[0].model, 9.80665)}));
  ASSERT_EQ(jc["calibrations"].size(), 3u);
  EXPECT_EQ(jc["calibrations"][2]["name"], "[gyro] a.calib + g.calib");
  EXPECT_EQ(jc["calibrations"][2]["accelerometer_of"], "truth.yaml");
}

}  // namespace
}  // namespace imucal::app
