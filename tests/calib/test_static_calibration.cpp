// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "calib/static_calibration.hpp"
#include "calib/static_detector.hpp"
#include "calib/static_steps.hpp"
#include "tests/calib/test_static_synth.hpp"
#include "tests/support/test_helpers.hpp"

namespace imucal::calib {
namespace {

using test::make_static_recording;
using test::SynthConfig;

/// The method's default options with the recording's gravity.
StaticCalibrationOptions options_for(const SynthConfig& cfg) {
  StaticCalibrationOptions opt;
  opt.gravity_mps2 = cfg.gravity;
  return opt;
}

/// All warnings, one per line, for searching.
std::string joined(const std::vector<std::string>& warnings) {
  std::string all;
  for (const auto& w : warnings) all += w + "\n";
  return all;
}

/// Every estimated parameter within k sigma of the truth (plus a tiny absolute floor for
/// parameters whose sigma is far below the numerical resolution).
void expect_within(const TedaldiTriad& est, const TriadSigma& sigma, const TedaldiTriad& truth, double k,
                   const std::string& what) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (i == j) continue;
      if (sigma.T(i, j) == 0.0) {
        EXPECT_NEAR(est.T(i, j), truth.T(i, j), 1e-12) << what << " T(" << i << "," << j << ") is fixed";
        continue;
      }
      EXPECT_NEAR(est.T(i, j), truth.T(i, j), k * sigma.T(i, j) + 1e-9)
          << what << " T(" << i << "," << j << ")";
    }
    EXPECT_NEAR(est.scale[i], truth.scale[i], k * sigma.scale[i] + 1e-12) << what << " scale " << i;
    EXPECT_NEAR(est.bias[i], truth.bias[i], k * sigma.bias[i] + 1e-12) << what << " bias " << i;
    EXPECT_GT(sigma.scale[i], 0.0) << what;
    EXPECT_GT(sigma.bias[i], 0.0) << what;
  }
}

TEST(StaticDetector, RunningVarianceMatchesDirect) {
  std::vector<Eigen::Vector3d> v;
  for (int i = 0; i < 300; ++i)
    v.emplace_back(32768 + std::sin(0.3 * i) * 40, 16000 + (i % 7), 1e5 + i * 0.5);
  const auto s = variance_magnitude_sq(v, 21);
  for (int i : {0, 5, 10, 150, 290, 299}) {
    const int a = std::max(0, i - 10), b = std::min(300, i + 11);
    EXPECT_NEAR(s[i], variance_magnitude_sq_of(std::span<const Eigen::Vector3d>(v.data() + a, b - a)),
                1e-6 * (1.0 + s[i]))
        << i;
  }
}

TEST(StaticDetector, IntervalsSplitAtBreaksAndRespectMinimum) {
  std::vector<double> s = {0, 0, 0, 5, 0, 0, 0, 0, 0, 0};
  std::vector<bool> usable(10, true), brk(10, false);
  brk[6] = true;
  const auto iv = detect_static_intervals(s, 1.0, usable, brk, 2);
  ASSERT_EQ(iv.size(), 3u);
  EXPECT_EQ(iv[0].begin, 0u);
  EXPECT_EQ(iv[0].end, 3u);
  EXPECT_EQ(iv[1].begin, 4u);
  EXPECT_EQ(iv[1].end, 6u);
  EXPECT_EQ(iv[2].begin, 6u);
  EXPECT_EQ(iv[2].end, 10u);
}

TEST(StaticCalibration, RecoversTruthWithinUncertaintySi) {
  SynthConfig cfg;
  cfg.seed = 3;
  cfg.truth = test::random_truth(3);
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  opt.accel_init = AxisConversion{};
  opt.gyro_init = AxisConversion{};
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  expect_within(res->model.accel, res->accel_sigma, cfg.truth.accel, 4.5, "accel");
  TedaldiTriad gyro_truth = cfg.truth.gyro;
  expect_within(res->model.gyro, res->gyro_sigma, gyro_truth, 4.5, "gyro");
  EXPECT_GE(res->distinct_attitudes, 30);
  EXPECT_GE(res->threshold_multiplier, opt.multiplier_min);
  EXPECT_TRUE(res->init_still_from_allan);
  EXPECT_GT(res->init_still_s, 20.0);
  // Both gyro passes together take 6 solver iterations here. The first is steered by the
  // first-order rate derivatives: wrong ones leave the result right (the exact second pass
  // decides it) but cost iterations: 13 with each step's frame taken at its start instead of
  // halfway, 15 with their sign flipped, 25 and 40 with them doubled or scaled by 0.6.
  EXPECT_LE(res->gyro_iterations, 9);
  // Quality: calibration improves both figures by a large factor (Tedaldi tables 4.4, 4.5).
  ASSERT_TRUE(res->quality.before_available);
  EXPECT_LT(res->quality.accel_after.mean_mps2 * 5, res->quality.accel_before.mean_mps2);
  EXPECT_LT(res->quality.gyro_after.mean_rad * 5, res->quality.gyro_before.mean_rad);
  EXPECT_LT(res->quality.gyro_after.mean_rad, 2e-3);
  // Canonical form applies the same correction.
  const Eigen::Vector3d raw(1.0, 2.0, -9.0);
  EXPECT_TRUE(res->canonical.correct_accel(raw).isApprox(res->model.accel.apply(raw), 1e-12));
  EXPECT_TRUE(res->warnings.empty()) << res->warnings.front();
}

TEST(StaticCalibration, RawCountsWithLargeOffsetsAndEllipsoidStart) {
  SynthConfig cfg;
  cfg.seed = 11;
  cfg.truth = test::random_truth(11);
  cfg.raw_counts = true;
  const auto rec = make_static_recording(cfg);
  // Truth in counts: ideal = T (K lsb) (c - offset + b / lsb).
  TedaldiTriad accel_truth = cfg.truth.accel, gyro_truth = cfg.truth.gyro;
  accel_truth.scale *= cfg.accel_lsb;
  accel_truth.bias = cfg.truth.accel.bias / cfg.accel_lsb - Eigen::Vector3d::Constant(cfg.accel_offset);
  gyro_truth.scale *= cfg.gyro_lsb;
  gyro_truth.bias = cfg.truth.gyro.bias / cfg.gyro_lsb - Eigen::Vector3d::Constant(cfg.gyro_offset);

  StaticCalibrationOptions opt;
  opt.gravity_mps2 = cfg.gravity;
  opt.gyro_init = test::counts_conversion(cfg.gyro_lsb, 0.0);  // scale only; no accel guess
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  EXPECT_FALSE(res->quality.before_available);
  expect_within(res->model.accel, res->accel_sigma, accel_truth, 4.5, "accel");
  expect_within(res->model.gyro, res->gyro_sigma, gyro_truth, 4.5, "gyro");

  // With the nominal conversion as the initial guess the answer is the same.
  opt.accel_init = test::counts_conversion(cfg.accel_lsb, cfg.accel_offset);
  auto res2 = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res2.ok()) << res2.error().message;
  EXPECT_TRUE(res2->model.accel.scale.isApprox(res->model.accel.scale, 1e-6));
  EXPECT_TRUE(res2->quality.before_available);

  // A nominal conversion that does not know the offset (raw counts imported without it) reads
  // 4 g at rest and turned every pose one way: it is set aside, said so, and the answer is the
  // same. Before: "found at most 1 distinct static attitudes ... Record again".
  opt.accel_init = test::counts_conversion(cfg.accel_lsb, 0.0);
  auto res3 = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res3.ok()) << res3.error().message;
  EXPECT_TRUE(res3->model.accel.scale.isApprox(res->model.accel.scale, 1e-6));
  EXPECT_TRUE(res3->model.accel.bias.isApprox(res->model.accel.bias, 1e-6));
  EXPECT_EQ(res3->distinct_attitudes, res->distinct_attitudes);
  EXPECT_FALSE(res3->quality.before_available);
  ASSERT_FALSE(res3->warnings.empty());
  EXPECT_NE(res3->warnings.front().find("carry an offset"), std::string::npos) << res3->warnings.front();
  // calib/ names the quantities, in the host's words: without a host, plain ones.
  EXPECT_NE(res3->warnings.front().find("(zero counts at import: given)"), std::string::npos)
      << res3->warnings.front();
  EXPECT_EQ(res3->warnings.front().find("--"), std::string::npos) << res3->warnings.front();
  // A wrong scale trips the same check: the warning names the scales too.
  EXPECT_NE(res3->warnings.front().find("(scales at import: given:"), std::string::npos)
      << res3->warnings.front();
}

TEST(StaticCalibration, EstimatedGyroBiasAgreesWithStillBias) {
  SynthConfig cfg;
  cfg.seed = 5;
  cfg.truth = test::random_truth(5);
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt;
  opt.init_still_s = 40.0;
  opt.estimate_gyro_bias = true;
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  EXPECT_FALSE(res->init_still_from_allan);
  EXPECT_EQ(res->gyro_covariance.rows(), 12);
  expect_within(res->model.gyro, res->gyro_sigma, cfg.truth.gyro, 4.5, "gyro");
}

// The gyro solve runs on several threads, each over a fixed run of transfers: the result is the
// same to the last bit whatever their number, with the bias fixed or estimated.
TEST(StaticCalibration, TheResultDoesNotDependOnTheNumberOfThreads) {
  SynthConfig cfg;
  cfg.seed = 8;
  cfg.truth = test::random_truth(8);
  const auto rec = make_static_recording(cfg);
  for (const bool estimate_bias : {false, true}) {
    StaticCalibrationOptions opt = options_for(cfg);
    opt.estimate_gyro_bias = estimate_bias;
    opt.threads = 1;
    auto one = calibrate_static(rec.samples, opt);
    ASSERT_TRUE(one.ok()) << one.error().message;
    for (const int threads : {2, 3, 7}) {
      opt.threads = threads;
      auto many = calibrate_static(rec.samples, opt);
      ASSERT_TRUE(many.ok()) << many.error().message;
      EXPECT_EQ(many->model.gyro.T, one->model.gyro.T) << threads << " threads";
      EXPECT_EQ(many->model.gyro.scale, one->model.gyro.scale) << threads << " threads";
      EXPECT_EQ(many->model.gyro.bias, one->model.gyro.bias) << threads << " threads";
      EXPECT_EQ(many->gyro_covariance, one->gyro_covariance) << threads << " threads";
      EXPECT_EQ(many->gyro_residual_rms, one->gyro_residual_rms) << threads << " threads";
    }
  }
  StaticCalibrationOptions bad = options_for(cfg);
  bad.threads = -1;
  EXPECT_FALSE(bad.validate().ok());
}

TEST(StaticCalibration, TooFewPosesSaysWhatToRecord) {
  SynthConfig cfg;
  cfg.poses = 5;
  cfg.truth = test::random_truth(2);
  const auto rec = make_static_recording(cfg);
  auto res = calibrate_static(rec.samples, StaticCalibrationOptions{});
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.error().code, Errc::kInsufficientData);
  EXPECT_NE(res.error().message.find("the full accelerometer model needs 9, scales and biases alone 6"),
            std::string::npos)
      << res.error().message;
  EXPECT_NE(res.error().message.find("36-50 different attitudes"), std::string::npos) << res.error().message;
}

TEST(StaticCalibration, FewPosesWarn) {
  SynthConfig cfg;
  cfg.poses = 14;
  cfg.seed = 21;
  cfg.truth = test::random_truth(21);
  const auto rec = make_static_recording(cfg);
  auto res = calibrate_static(rec.samples, StaticCalibrationOptions{});
  ASSERT_TRUE(res.ok()) << res.error().message;
  ASSERT_FALSE(res->warnings.empty());
  EXPECT_NE(res->warnings.front().find("distinct attitudes"), std::string::npos);
}

TEST(StaticCalibration, MissingStillStartIsAnError) {
  SynthConfig cfg;
  cfg.still_s = 2.0;
  cfg.truth = test::random_truth(4);
  const auto rec = make_static_recording(cfg);
  auto res = calibrate_static(rec.samples, StaticCalibrationOptions{});
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.error().code, Errc::kInsufficientData);
  EXPECT_NE(res.error().message.find("no still period at the start"), std::string::npos)
      << res.error().message;
  // A given still period that contains motion is refused too.
  StaticCalibrationOptions opt;
  opt.init_still_s = 10.0;
  res = calibrate_static(rec.samples, opt);
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.error().code, Errc::kInsufficientData);
  EXPECT_NE(res.error().message.find("not still"), std::string::npos) << res.error().message;
  // The library speaks of its options, not of a command line's flags.
  EXPECT_NE(res.error().message.find("init_still_s"), std::string::npos) << res.error().message;
  EXPECT_EQ(res.error().message.find("--"), std::string::npos) << res.error().message;
}

/// An MPU-6000-like g-sensitivity (about 0.1 deg/s per g on and across the axes).
Eigen::Matrix3d mpu_gsens() {
  Eigen::Matrix3d G;
  G << 1.6e-4, -0.8e-4, 0.5e-4,  //
      0.9e-4, -1.2e-4, 1.4e-4,   //
      -0.6e-4, 1.1e-4, 1.8e-4;
  return G;
}

TEST(StaticCalibration, GSensitivityIsEstimatedFromThePosesAndRemovedFromTheGyro) {
  SynthConfig cfg;
  cfg.seed = 41;
  cfg.truth = test::random_truth(41);
  cfg.gsens = mpu_gsens();
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  EXPECT_EQ(res->gsens_mode, GSensitivityMode::kEstimate);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_GT(res->gsens_sigma(i, j), 0.0);
      EXPECT_LT(res->gsens_sigma(i, j), 2e-5);
      EXPECT_NEAR(res->canonical.G(i, j), cfg.gsens(i, j), 4.5 * res->gsens_sigma(i, j)) << "G " << i << j;
    }
  }
  expect_within(res->model.gyro, res->gyro_sigma, cfg.truth.gyro, 4.5, "gyro with G estimated");
  EXPECT_EQ(res->gsens_dof.parameters, 6);  // bias, 3 of H, a quadratic drift (40 poses)
  EXPECT_EQ(res->gsens_dof.residuals, static_cast<int>(res->intervals.size()) + 1);
  // Nothing is dropped as "rotation": the g-sensitivity explains what the gyro shows at rest.
  for (const auto& w : res->warnings) EXPECT_EQ(w.find("turned inside"), std::string::npos) << w;

  // Neglected (Tedaldi's model), the same recording gives a worse gyro: the g-sensitivity acts
  // as a pose-dependent bias in every transfer.
  opt.gsens = GSensitivityMode::kOff;
  auto off = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(off.ok()) << off.error().message;
  EXPECT_TRUE(off->canonical.G.isZero(0.0));
  EXPECT_GT(off->quality.gyro_after.mean_rad, 1.5 * res->quality.gyro_after.mean_rad);

  // Given (fixed), it is used as it is and the bias is fitted to the poses around it.
  opt.gsens = GSensitivityMode::kFixed;
  opt.gsens_fixed = cfg.gsens;
  auto fixed = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(fixed.ok()) << fixed.error().message;
  EXPECT_TRUE(fixed->canonical.G.isApprox(cfg.gsens, 1e-12));
  expect_within(fixed->model.gyro, fixed->gyro_sigma, cfg.truth.gyro, 4.5, "gyro with G fixed");
}

TEST(StaticCalibration, EarthRateIsRemovedFromGWhenTheLatitudeIsKnown) {
  SynthConfig cfg;
  cfg.seed = 43;
  cfg.truth = test::random_truth(43);
  cfg.gsens = mpu_gsens();  // estimated (a G indistinguishable from zero would be neglected)
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  auto without = calibrate_static(rec.samples, opt);
  opt.latitude_deg = 47.37;
  auto with = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(without.ok() && with.ok());
  const double e = 7.2921150e-5 * std::sin(47.37 * M_PI / 180.0) / cfg.gravity;
  EXPECT_NEAR(with->earth_rate_removed, e, 1e-12);
  EXPECT_TRUE((without->canonical.G - with->canonical.G).isApprox(e * Eigen::Matrix3d::Identity(), 1e-9));
}

TEST(StaticCalibration, ANoisyAccelerometerInTheStillStartIsStillAStillStart) {
  // The gyro is quiet for the whole 50 s still start but the accelerometer is 4 times noisier
  // there than in the poses (16 times on varsigma): the still start is found, and a given one is
  // accepted.
  SynthConfig cfg;
  cfg.seed = 45;
  cfg.truth = test::random_truth(45);
  cfg.accel_noise_start = 4.0;
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  auto found = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(found.ok()) << found.error().message;
  EXPECT_GT(found->init_still_s, 20.0);
  opt.init_still_s = 45.0;
  auto given = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(given.ok()) << given.error().message;
  EXPECT_NEAR(given->init_still_s, 45.0, 0.05);
  expect_within(given->model.accel, given->accel_sigma, cfg.truth.accel, 4.5, "accel");
}

TEST(StaticCalibration, AGyroHeldByHandInTheStillStartIsStillAStillStart) {
  // The rig is held by hand at the start: the gyro's variance is 40 times its later level while
  // the accelerometer stays quiet (a real recording does this). Not motion.
  SynthConfig cfg;
  cfg.seed = 49;
  cfg.truth = test::random_truth(49);
  cfg.gyro_noise_start = std::sqrt(40.0);
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  EXPECT_GT(res->init_still_s, 20.0);
}

TEST(StaticCalibration, AShortStillStartIsUsedWithAWarningAndATinyOneIsRefused) {
  SynthConfig cfg;
  cfg.seed = 51;
  cfg.truth = test::random_truth(51);
  cfg.still_s = 6.0;
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  EXPECT_LT(res->init_still_s, 6.5);
  const std::string all = joined(res->warnings);
  EXPECT_NE(all.find("the still start is only"), std::string::npos) << all;
  opt.init_still_s = 0.5;
  auto tiny = calibrate_static(rec.samples, opt);
  ASSERT_FALSE(tiny.ok());
  EXPECT_NE(tiny.error().message.find("too short"), std::string::npos) << tiny.error().message;
}

TEST(StaticCalibration, TooFewPosesForTheGSensitivityNeglectItWithAWarning) {
  SynthConfig cfg;
  cfg.seed = 53;
  cfg.truth = test::random_truth(53);
  cfg.poses = 11;
  cfg.hold_min_s = 3.0;
  cfg.hold_max_s = 4.0;
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  auto res = calibrate_static(rec.samples, opt);
  ASSERT_TRUE(res.ok()) << res.error().message;
  EXPECT_EQ(res->gsens_mode, GSensitivityMode::kOff);
  EXPECT_TRUE(res->canonical.G.isZero(0.0));
  const std::string all = joined(res->warnings);
  EXPECT_NE(all.find("g-sensitivity was not estimated"), std::string::npos) << all;
}

TEST(StaticCalibration, AsManyPosesAsParametersLeaveTheSigmasUndetermined) {
  // With exactly 9 static means the 9 accelerometer parameters fit them exactly: no residual
  // variance is left to scale the covariance, so the sigmas are NaN (undetermined), never 1e-15.
  SynthConfig cfg;
  cfg.seed = 47;
  cfg.truth = test::random_truth(47);
  cfg.poses = 8;  // with the still start: 9 static means
  cfg.hold_min_s = 3.0;
  cfg.hold_max_s = 4.0;
  cfg.move_min_s = 2.0;
  cfg.move_max_s = 3.0;
  const auto rec = make_static_recording(cfg);
  StaticCalibrationOptions opt = options_for(cfg);
  opt.min_attitudes = 9;
  auto res = calibrate_static(rec.samples, opt);
  if (!res.ok()) GTEST_SKIP() << "this seed does not give 9 distinct attitudes: " << res.error().message;
  ASSERT_EQ(res->intervals.size(), 9u) << "the detector split or merged a pose";
  EXPECT_EQ(res->accel_dof.dof(), 0);
  EXPECT_FALSE(res->accel_dof.determined());
  const std::string all = joined(res->warnings);
  EXPECT_NE(all.find("the accelerometer fit is exact"), std::string::npos) << all;
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(std::isnan(res->accel_sigma.scale[i])) << res->accel_sigma.scale[i];
    EXPECT_TRUE(std::isnan(res->accel_sigma.bias[i])) << res->accel_sigma.bias[i];
  }
}

TEST(StaticCalibration, GapsAndSaturationAreExcludedWithWarnings) {
  SynthConfig cfg;
  cfg.seed = 8;
  cfg.truth = test::random_truth(8);
  auto rec = make_static_recording(cfg);
  // A gap of 0.5 s in the middle of the 10th motion and saturated gyro samples in the 20th.
  const double t_gap = rec.holds_s[10].second + 0.8;
  const double t_sat = rec.holds_s[20].second + 0.8;
  std::vector<ImuSample> cut;
  bool flagged = false;
  for (auto s : rec.samples) {
    const double t = ns_to_s(s.t_ns);
    if (t > t_gap && t < t_gap + 0.5) {
      flagged = false;
      continue;
    }
    if (t >= t_gap + 0.5 && !flagged) {
      s.flags |= kImuFlagGapBefore;
      flagged = true;
    }
    if (t > t_sat && t < t_sat + 0.05) s.flags |= kImuFlagGyroSaturated;
    cut.push_back(s);
  }
  auto res = calibrate_static(cut, StaticCalibrationOptions{});
  ASSERT_TRUE(res.ok()) << res.error().message;
  const std::string all = joined(res->warnings);
  EXPECT_NE(all.find("gap"), std::string::npos) << all;
  EXPECT_NE(all.find("saturated"), std::string::npos) << all;
  EXPECT_NE(all.find("were not used for the gyroscope"), std::string::npos) << all;
  EXPECT_LE(res->gyro_transfers, static_cast<int>(res->intervals.size()) - 3);
  expect_within(res->model.gyro, res->gyro_sigma, cfg.truth.gyro, 4.5, "gyro");
}

TEST(StaticCalibration, MotionInsideAPoseDoesNotDegradeTheResult) {
  SynthConfig cfg;
  cfg.seed = 9;
  cfg.truth = test::random_truth(9);
  cfg.hold_min_s = 3.0;
  cfg.hold_max_s = 4.0;
  auto rec = make_static_recording(cfg);
  // Shake the rig (accel and gyro) for 0.3 s in the middle of several holds.
  for (int h : {5, 12, 25}) {
    const double tm = 0.5 * (rec.holds_s[h].first + rec.holds_s[h].second);
    for (auto& s : rec.samples) {
      const double t = ns_to_s(s.t_ns);
      if (t > tm && t < tm + 0.3) {
        const double ph = 60.0 * (t - tm);
        s.accel += Eigen::Vector3d(2.0 * std::sin(ph), 1.5 * std::cos(ph), 0.0);
      }
    }
  }
  auto res = calibrate_static(rec.samples, StaticCalibrationOptions{});
  ASSERT_TRUE(res.ok()) << res.error().message;
  expect_within(res->model.accel, res->accel_sigma, cfg.truth.accel, 4.5, "accel");
  expect_within(res->model.gyro, res->gyro_sigma, cfg.truth.gyro, 4.5, "gyro");
}

TEST(StaticCalibration, RotationInsideAStaticIntervalIsDropped) {
  SynthConfig cfg;
  cfg.seed = 10;
  cfg.truth = test::random_truth(10);
  cfg.hold_min_s = 3.0;
  cfg.hold_max_s = 4.0;
  auto rec = make_static_recording(cfg);
  // A slow, smooth 3 deg creep during one hold that the variance detector cannot see.
  const auto [h0, h1] = rec.holds_s[7];
  const double rate = 3.0 * M_PI / 180.0 / (h1 - h0);
  for (auto& s : rec.samples) {
    const double t = ns_to_s(s.t_ns);
    if (t >= h0 && t <= h1) s.gyro += cfg.truth.gyro.TK().inverse() * Eigen::Vector3d(rate, 0, 0);
  }
  auto res = calibrate_static(rec.samples, StaticCalibrationOptions{});
  ASSERT_TRUE(res.ok()) << res.error().message;
  const std::string all = joined(res->warnings);
  EXPECT_NE(all.find("the rig turned inside them"), std::string::npos) << all;
}

// ---- the steps on their own ----

std::vector<ImuSample> still_samples(std::size_t n) {
  std::vector<ImuSample> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    v[i].t_ns = static_cast<TimeNs>(i) * 10'000'000;  // 100 Hz
    v[i].accel = Eigen::Vector3d(0.0, 0.0, 9.8);
    v[i].gyro = Eigen::Vector3d(0.01, 0.0, 0.0);
  }
  return v;
}

TEST(StaticSteps, ScanFindsBreaksAndInvalidSamplesAndWarns) {
  std::vector<ImuSample> v = still_samples(1200);
  for (std::size_t i = 500; i < v.size(); ++i) v[i].t_ns += 50'000'000;  // 5 periods lost
  v[700].flags |= kImuFlagDeviceReset;
  v[800].flags |= kImuFlagAccelSaturated;
  v[801].accel.x() = std::nan("");
  v[900].flags |= kImuFlagGyroSaturated;
  std::vector<std::string> warnings;
  auto scan = scan_recording(v, &warnings);
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  EXPECT_NEAR(scan->rate_hz, 100.0, 1e-9);
  EXPECT_EQ(scan->gaps, 2);
  EXPECT_TRUE(scan->break_before[500]);
  EXPECT_FALSE(scan->reset_before[500]);
  EXPECT_TRUE(scan->break_before[700]);
  EXPECT_TRUE(scan->reset_before[700]);
  EXPECT_EQ(scan->accel_saturated, 2);
  EXPECT_EQ(scan->gyro_saturated, 1);
  EXPECT_FALSE(scan->accel_ok[800]);
  EXPECT_FALSE(scan->accel_ok[801]);
  EXPECT_FALSE(scan->gyro_ok[900]);
  // Invalid accelerometer values are replaced by the last valid one, so running sums stay finite.
  EXPECT_EQ(scan->accel[801], v[799].accel);
  ASSERT_EQ(warnings.size(), 2u);
  EXPECT_NE(warnings[0].find("saturated"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[1].find("gap"), std::string::npos) << warnings[1];

  v[1000].t_ns = v[999].t_ns;
  scan = scan_recording(v, &warnings);
  ASSERT_FALSE(scan.ok());
  EXPECT_EQ(scan.error().code, Errc::kCorrupt);
  scan = scan_recording(still_samples(2), &warnings);
  ASSERT_FALSE(scan.ok());
  EXPECT_EQ(scan.error().code, Errc::kInsufficientData);
  // The method itself needs a still start and poses.
  auto short_run = calibrate_static(still_samples(999), StaticCalibrationOptions{});
  ASSERT_FALSE(short_run.ok());
  EXPECT_EQ(short_run.error().code, Errc::kInsufficientData);
}

TEST(StaticSteps, ACoarseClockIsNotAGapButALostSampleIs) {
  // 100 Hz samples stamped by a host on a coarse clock: steps of 5.12, 10.24 and 15.36 ms, the
  // long ones made up for by a short one next to them.
  std::vector<ImuSample> v = still_samples(3000);
  const std::vector<TimeNs> t = test::coarse_clock_times_100hz(v.size(), 7);
  for (std::size_t i = 0; i < v.size(); ++i) v[i].t_ns = t[i];
  std::vector<std::string> warnings;
  auto scan = scan_recording(v, &warnings);
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  int long_steps = 0;
  for (std::size_t i = 1; i < v.size(); ++i) long_steps += v[i].t_ns - v[i - 1].t_ns > 15'000'000 ? 1 : 0;
  ASSERT_GT(long_steps, 100);  // the clock does step by 1.5 periods of the median step
  EXPECT_EQ(scan->gaps, 0);
  EXPECT_TRUE(warnings.empty()) << warnings.front();
  // The rate is the samples' (the median step, 10.24 ms, would say 97.7 Hz).
  EXPECT_NEAR(scan->rate_hz, 100.0, 0.01);

  // A late sample (1.6 and 0.4 periods) loses nothing; a lost sample (2 periods) is a gap.
  v = still_samples(1000);
  v[300].t_ns += 6'000'000;
  for (std::size_t i = 600; i < v.size(); ++i) v[i].t_ns += 10'000'000;
  scan = scan_recording(v, &warnings);
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  EXPECT_EQ(scan->gaps, 1);
  EXPECT_FALSE(scan->break_before[300]);
  EXPECT_FALSE(scan->break_before[301]);
  EXPECT_TRUE(scan->break_before[600]);
  EXPECT_NEAR(scan->rate_hz, 100.0, 1e-9);  // the gap's step is not part of the rate
}

TEST(StaticSteps, StillStartGivenOrFromAllanDeviation) {
  SynthConfig cfg;
  cfg.seed = 6;
  cfg.truth = test::random_truth(6);
  const auto rec = make_static_recording(cfg);
  std::vector<std::string> warnings;
  auto scan = scan_recording(rec.samples, &warnings);
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  const StaticDetection det = detect_variance(*scan, 1.0);
  EXPECT_EQ(det.window, 100u);
  EXPECT_GT(det.floor_sq, 0.0);

  StaticCalibrationOptions opt;
  opt.init_still_s = 30.0;
  auto given = find_still_start(rec.samples, *scan, det, opt, &warnings);
  ASSERT_TRUE(given.ok()) << given.error().message;
  EXPECT_FALSE(given->from_allan);
  EXPECT_EQ(given->samples, 3000u);
  EXPECT_NEAR(given->length_s, 30.0, 1e-9);
  // The still-period mean is the gyro bias (Tedaldi's sign: raw = ... - bias).
  EXPECT_LT((given->gyro_bias_raw + cfg.truth.gyro.bias).norm(), 5.0 * given->gyro_bias_sigma.norm());

  opt.init_still_s = 0.0;
  auto automatic = find_still_start(rec.samples, *scan, det, opt, &warnings);
  ASSERT_TRUE(automatic.ok()) << automatic.error().message;
  EXPECT_TRUE(automatic->from_allan);
  EXPECT_GT(automatic->length_s, 20.0);
  EXPECT_LE(automatic->length_s, cfg.still_s + 1.0);
  EXPECT_TRUE(warnings.empty());

  opt.init_still_s = 1e6;
  auto too_long = find_still_start(rec.samples, *scan, det, opt, &warnings);
  ASSERT_FALSE(too_long.ok());
  EXPECT_EQ(too_long.error().code, Errc::kInvalidArgument);
  EXPECT_NE(too_long.error().message.find("longer than the recording"), std::string::npos);
}

TEST(StaticSteps, NormalPseudoInverseDropsTheNullSpace) {
  Eigen::MatrixXd J(6, 3);
  J << 1, 2, 0, 0, 1, 1, 3, 0, 1, 1, 1, 1, 0, 2, 5, 4, 1, 0;
  EXPECT_TRUE(normal_pseudo_inverse(J).isApprox((J.transpose() * J).inverse(), 1e-12));
  // A column that repeats another: the covariance has no component along the null direction.
  J.col(2) = J.col(0);
  const Eigen::MatrixXd P = normal_pseudo_inverse(J);
  EXPECT_TRUE(P.allFinite());
  EXPECT_LT((P * Eigen::Vector3d(1, 0, -1)).norm(), 1e-12);
  EXPECT_TRUE((J.transpose() * J * P * J.transpose() * J).isApprox(J.transpose() * J, 1e-12));
}

TEST(StaticCalibration, BadInputsAreRefused) {
  StaticCalibrationOptions opt;
  opt.gravity_mps2 = 1.0;
  const Status valid = opt.validate();
  ASSERT_FALSE(valid.ok());
  EXPECT_EQ(valid.error().code, Errc::kInvalidArgument);
  EXPECT_NE(valid.error().message.find("gravity"), std::string::npos);
  std::vector<ImuSample> few(10);
  auto r = calibrate_static(few, StaticCalibrationOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInsufficientData);
  std::vector<ImuSample> backwards(2000);
  for (std::size_t i = 0; i < backwards.size(); ++i) backwards[i].t_ns = 1000 - static_cast<TimeNs>(i);
  r = calibrate_static(backwards, StaticCalibrationOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kCorrupt);
}

}  // namespace
}  // namespace imucal::calib
