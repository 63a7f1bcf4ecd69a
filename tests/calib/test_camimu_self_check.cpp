// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU sigmas against errors the residual model leaves out: the cluster-robust
// covariance over time blocks, and the self-check that calibrates the halves of a recording
// apart (app/camimu_self_check.hpp, core/split_check.hpp).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "app/camimu_self_check.hpp"
#include "calib/camimu_calibration.hpp"
#include "tests/calib/camimu_synth.hpp"

namespace imucal {
namespace {

calib::CamImuOptions self_check_options(double cluster_s) {
  calib::CamImuOptions o;
  o.threads = 2;
  o.model = CamImuModelKind::kBasic;
  o.shutter.mode = calib::ShutterSolveOptions::Mode::kGlobal;
  o.knot_spacing_s = 0.05;
  o.covariance_cluster_s = cluster_s;
  return o;
}

// Every frame's corners share a 0.5 px offset (a detector's bias): the plain covariance knows
// only the corners' independent 0.1 px noise, the cluster-robust one sees the shared error.
TEST(CamImuSigmas, TheClusterRobustSigmasGrowWithErrorsSharedByAFrame) {
  test::CamImuSynthOptions so;
  so.seed = 8;
  so.duration_s = 20.0;
  so.corner_sigma_px = 0.1;
  so.frame_shared_px = 0.5;
  so.imu_errors = false;
  const auto synth = test::make_camimu_synth(so);
  auto plain = calib::calibrate_camimu(synth.imu, synth.cameras, synth.target, self_check_options(0.0));
  auto robust = calib::calibrate_camimu(synth.imu, synth.cameras, synth.target, self_check_options(1.0));
  ASSERT_TRUE(plain.ok()) << plain.error().message;
  ASSERT_TRUE(robust.ok()) << robust.error().message;
  const auto& p = plain->cameras[0];
  const auto& r = robust->cameras[0];
  EXPECT_EQ(plain->quality.covariance_clusters, 0);
  EXPECT_GE(robust->quality.covariance_clusters, 19);
  const double err = (r.T_cam_imu.translation() - synth.T_cam_imu.translation()).norm();
  std::printf("translation sigma plain %.3f mm, robust %.3f mm; error %.3f mm\n",
              p.translation_sigma_m.norm() * 1e3, r.translation_sigma_m.norm() * 1e3, err * 1e3);
  EXPECT_GT(r.translation_sigma_m.norm(), 1.5 * p.translation_sigma_m.norm());
  EXPECT_GT(r.timeshift_sigma_s, 1.5 * p.timeshift_sigma_s);
  // Never below the plain one.
  for (int a = 0; a < 3; ++a) EXPECT_GE(r.rotation_sigma_rad(a), p.rotation_sigma_rad(a) * (1 - 1e-9));
}

// The held intrinsics' covariance, rank one (one direction l: the focal lengths 0.2 px longer
// and the principal point 0.1 px right), reaches the sigmas as what moving the intrinsics by l
// does to the result: solving again with the camera moved by l shifts the extrinsics by the
// propagated share, axis by axis (with the weights held, so that only l differs).
TEST(CamImuSigmas, HeldIntrinsicsReachTheSigmasAsTheirEffectOnTheResult) {
  test::CamImuSynthOptions so;
  so.seed = 12;
  so.duration_s = 20.0;
  so.corner_sigma_px = 0.1;
  so.imu_errors = false;
  auto synth = test::make_camimu_synth(so);
  Eigen::VectorXd l = Eigen::VectorXd::Zero(10);  // [fu fv pu pv, projection (2), distortion (4)]
  l.head<3>() << 0.2, 0.2, 0.1;
  synth.cameras[0].intrinsics_covariance = l * l.transpose();
  synth.cameras[0].intrinsics_covariance_source = "a test covariance";
  auto options = self_check_options(0.0);
  options.corner_sigma_px = 0.1;
  options.imu_noise_from_residuals = false;
  auto held = calib::calibrate_camimu(synth.imu, synth.cameras, synth.target, options);
  ASSERT_TRUE(held.ok()) << held.error().message;
  auto moved_cameras = synth.cameras;
  moved_cameras[0].camera.intrinsics += l.head<4>();
  auto moved = calib::calibrate_camimu(synth.imu, moved_cameras, synth.target, options);
  ASSERT_TRUE(moved.ok()) << moved.error().message;
  auto without = options;
  without.propagate_intrinsics = false;
  auto bare = calib::calibrate_camimu(synth.imu, synth.cameras, synth.target, without);
  ASSERT_TRUE(bare.ok()) << bare.error().message;

  const auto& h = held->cameras[0];
  EXPECT_NE(h.intrinsics_uncertainty.find("propagated: a test covariance"), std::string::npos)
      << h.intrinsics_uncertainty;
  ASSERT_TRUE(h.translation_sigma_from_intrinsics_m.allFinite());
  const Eigen::Vector3d shift = moved->cameras[0].T_cam_imu.translation() - h.T_cam_imu.translation();
  const Eigen::Vector3d share = h.translation_sigma_from_intrinsics_m;
  std::printf("moved by l: translation shift [%.3f %.3f %.3f] mm, propagated share [%.3f %.3f %.3f] mm\n",
              shift.x() * 1e3, shift.y() * 1e3, shift.z() * 1e3, share.x() * 1e3, share.y() * 1e3,
              share.z() * 1e3);
  int largest = 0;
  share.maxCoeff(&largest);
  EXPECT_GT(share(largest), 0.1 * bare->cameras[0].translation_sigma_m(largest));  // l matters here
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(std::abs(shift(a)), share(a), 0.15 * share(largest) + 1e-5) << a;
  // The total is the data's sigma and the share in quadrature; without propagation, no share.
  for (int a = 0; a < 3; ++a) {
    const double data = bare->cameras[0].translation_sigma_m(a);
    EXPECT_NEAR(h.translation_sigma_m(a), std::hypot(data, share(a)), 0.02 * h.translation_sigma_m(a));
  }
  EXPECT_FALSE(bare->cameras[0].translation_sigma_from_intrinsics_m.allFinite());
  EXPECT_NE(bare->cameras[0].intrinsics_uncertainty.find("not propagated"), std::string::npos);
}

struct SelfCheckRun {
  CamImuCalibrationResult full;
  SplitCheck check;
};

SelfCheckRun run_self_check(const test::CamImuSynthOptions& so) {
  const auto synth = test::make_camimu_synth(so);
  const auto options = self_check_options(1.0);
  auto full = calib::calibrate_camimu(synth.imu, synth.cameras, synth.target, options);
  EXPECT_TRUE(full.ok()) << full.error().message;
  if (!full.ok()) return {};
  SelfCheckRun run{*full,
                   app::camimu_self_check(synth.imu, synth.cameras, synth.target, options, *full, 2, 2)};
  std::printf("%s\n", run.check.summary.c_str());
  return run;
}

TEST(CamImuSelfCheck, TheHalvesOfAConsistentRecordingAgree) {
  test::CamImuSynthOptions so;
  so.seed = 12;
  so.duration_s = 30.0;
  so.imu_errors = false;
  const SelfCheckRun run = run_self_check(so);
  const SplitCheck& c = run.check;
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kAgree) << c.summary;
  ASSERT_EQ(c.spans_s.size(), 2u);
  EXPECT_NEAR(c.spans_s[1].first, 0.5 * c.spans_s[1].second, 0.1);
  EXPECT_EQ(c.part_errors, (std::vector<std::string>{"", ""}));
  EXPECT_GE(c.parameters.size(), 7u);  // rotation, translation, time offset
  EXPECT_EQ(c.dof, static_cast<int>(c.parameters.size()));
  EXPECT_TRUE(c.advice.empty());
}

// From the middle on, the camera sits 20 mm further along its x axis (the halves' translation
// sigmas are near 2 mm on this short recording): each half is consistent
// in itself, the halves are not with each other.
TEST(CamImuSelfCheck, FlagsARecordingWhoseHalvesDisagree) {
  test::CamImuSynthOptions so;
  so.seed = 12;
  so.duration_s = 30.0;
  so.imu_errors = false;
  so.moved_at_s = 15.0;
  so.moved_by_m = Eigen::Vector3d(0.02, 0.0, 0.0);
  const SelfCheckRun run = run_self_check(so);
  const SplitCheck& c = run.check;
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kDisagree) << c.summary;
  EXPECT_EQ(c.worst, "cam0 translation x");
  EXPECT_GT(c.worst_z, 5.0);
  EXPECT_FALSE(c.advice.empty());
  const auto it = std::find_if(c.parameters.begin(), c.parameters.end(),
                               [](const SplitCheckParameter& p) { return p.name == "cam0 translation x"; });
  ASSERT_NE(it, c.parameters.end());
  EXPECT_NEAR(it->values[1] - it->values[0], 20.0, 3.0 * std::hypot(it->sigmas[0], it->sigmas[1]));  // mm
}

}  // namespace
}  // namespace imucal
