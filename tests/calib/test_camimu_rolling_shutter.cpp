// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU solve with a rolling shutter (calib/camimu_calibration.hpp, CamImuShutterOptions)
// on recordings of a generator that shares no code with the simulator
// (tests/support/rs_analytic_rig.hpp: an analytic trajectory and IMU, each corner projected at the
// time its own row was read). The camera enters as global-shutter with no line delay to start from,
// as a user's camera file would.

#include <gtest/gtest.h>

#include <cmath>

#include "calib/camimu_calibration.hpp"
#include "calib/so3.hpp"
#include "tests/support/rs_analytic_rig.hpp"

namespace imucal::calib {
namespace {

CamImuOptions rs_options() {
  CamImuOptions o;
  o.threads = 2;
  o.model = CamImuModelKind::kBasic;  // the generator's IMU has biases only
  return o;
}

/// The camera as a user's file gives it: the true lens, the shutter not known.
std::vector<CamImuCameraInput> as_unknown_shutter(const test::RsAnalyticRig& rig) {
  CamImuCameraInput cam = rig.camera;
  cam.camera.shutter = Shutter{};
  return {cam};
}

void expect_extrinsics_within(const CamImuCameraResult& c, const test::RsAnalyticRig& rig, double k) {
  const Eigen::Vector3d dt = c.T_cam_imu.translation() - rig.T_cam_imu.translation();
  const Eigen::Vector3d dr = so3::log(c.T_cam_imu.linear() * rig.T_cam_imu.linear().transpose());
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(std::abs(dt(i)), k * c.translation_sigma_m(i)) << "translation " << i << ": " << dt.transpose();
    EXPECT_LE(std::abs(dr(i)), k * c.rotation_sigma_rad(i)) << "rotation " << i << ": " << dr.transpose();
  }
  EXPECT_LE(std::abs(c.timeshift_cam_imu_s - rig.timeshift_s), k * c.timeshift_sigma_s)
      << c.timeshift_cam_imu_s << " against " << rig.timeshift_s;
}

TEST(CamImuRollingShutter, TheEvidencePicksRollingAndTheLineDelayAndExtrinsicsHoldTheTruth) {
  test::RsAnalyticOptions ro;
  ro.seed = 3;
  ro.line_delay_s = 30e-6;  // 480 rows: 14.4 ms of readout
  const auto rig = test::make_rs_analytic_rig(ro);
  auto r = calibrate_camimu(rig.imu, as_unknown_shutter(rig), rig.target, rs_options());
  ASSERT_TRUE(r.ok()) << r.error().message;
  const CamImuCameraResult& c = r->cameras[0];
  ASSERT_TRUE(c.camera.shutter.rolling()) << c.shutter_choice;
  EXPECT_EQ(c.shutter_choice.rfind("rolling, chosen by the evidence", 0), 0u) << c.shutter_choice;
  // The test frees the line delay on the frames that carry most of its information; the rolling
  // solution is then solved on every frame.
  EXPECT_NE(c.shutter_choice.find("; tested on the "), std::string::npos) << c.shutter_choice;
  const double ld = c.camera.shutter.line_delay_s;
  ASSERT_TRUE(std::isfinite(c.line_delay_sigma_s));
  EXPECT_LE(std::abs(ld - 30e-6), 3.0 * c.line_delay_sigma_s) << ld << " +- " << c.line_delay_sigma_s;
  EXPECT_LE(std::abs(ld - 30e-6), 1e-6);
  expect_extrinsics_within(c, rig, 3.0);

  // The global model on the same data: clearly worse (the corners' RMS), and its extrinsics or
  // offset off by more than their sigmas say.
  CamImuOptions g = rs_options();
  g.shutter.mode = CamImuShutterOptions::Mode::kGlobal;
  auto gr = calibrate_camimu(rig.imu, as_unknown_shutter(rig), rig.target, g);
  ASSERT_TRUE(gr.ok()) << gr.error().message;
  EXPECT_FALSE(gr->cameras[0].camera.shutter.rolling());
  EXPECT_EQ(c.frames, gr->cameras[0].frames) << "the rolling solution is on every frame";
  EXPECT_GT(gr->cameras[0].reprojection_rms_px, 1.5 * c.reprojection_rms_px);
  const double shift_error = std::abs(gr->cameras[0].timeshift_cam_imu_s - rig.timeshift_s);
  EXPECT_GT(shift_error, 10.0 * gr->cameras[0].timeshift_sigma_s);
}

TEST(CamImuRollingShutter, AGlobalShutterStaysGlobalAndAForcedLineDelayIsZeroWithinItsSigma) {
  test::RsAnalyticOptions ro;
  ro.seed = 4;
  ro.line_delay_s = 0.0;
  const auto rig = test::make_rs_analytic_rig(ro);
  auto r = calibrate_camimu(rig.imu, as_unknown_shutter(rig), rig.target, rs_options());
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->cameras[0].camera.shutter.rolling());
  EXPECT_EQ(r->cameras[0].shutter_choice.rfind("global, chosen by the evidence", 0), 0u)
      << r->cameras[0].shutter_choice;
  EXPECT_NE(r->cameras[0].shutter_choice.find("; tested on the "), std::string::npos)
      << r->cameras[0].shutter_choice;
  expect_extrinsics_within(r->cameras[0], rig, 3.0);

  CamImuOptions f = rs_options();
  f.shutter.mode = CamImuShutterOptions::Mode::kRolling;
  auto fr = calibrate_camimu(rig.imu, as_unknown_shutter(rig), rig.target, f);
  ASSERT_TRUE(fr.ok()) << fr.error().message;
  const CamImuCameraResult& c = fr->cameras[0];
  ASSERT_TRUE(c.camera.shutter.rolling());
  EXPECT_LE(std::abs(c.camera.shutter.line_delay_s), 3.0 * c.line_delay_sigma_s)
      << c.camera.shutter.line_delay_s << " +- " << c.line_delay_sigma_s;
}

TEST(CamImuRollingShutter, AHeldLineDelayStaysAndTheReadoutDirectionMatters) {
  test::RsAnalyticOptions ro;
  ro.seed = 5;
  ro.duration_s = 24.0;
  ro.line_delay_s = 30e-6;
  ro.readout = Shutter::Readout::kBottomToTop;
  ro.stamp_row = Shutter::StampRow::kMiddle;
  const auto rig = test::make_rs_analytic_rig(ro);
  // The camera file knows the readout and the stamped row; the line delay is held at the truth.
  CamImuOptions o = rs_options();
  o.shutter.line_delay_s = 30e-6;
  auto held = calibrate_camimu(rig.imu, {rig.camera}, rig.target, o);
  ASSERT_TRUE(held.ok()) << held.error().message;
  EXPECT_DOUBLE_EQ(held->cameras[0].camera.shutter.line_delay_s, 30e-6);
  EXPECT_FALSE(std::isfinite(held->cameras[0].line_delay_sigma_s));
  expect_extrinsics_within(held->cameras[0], rig, 3.0);
  // Estimated with the readout direction the wrong way round: a negative line delay says so.
  CamImuCameraInput wrong = rig.camera;
  wrong.camera.shutter.readout = Shutter::Readout::kTopToBottom;
  o.shutter.line_delay_s.reset();
  o.shutter.mode = CamImuShutterOptions::Mode::kRolling;
  auto flipped = calibrate_camimu(rig.imu, {wrong}, rig.target, o);
  ASSERT_TRUE(flipped.ok()) << flipped.error().message;
  EXPECT_LT(flipped->cameras[0].camera.shutter.line_delay_s, -20e-6);
}

}  // namespace
}  // namespace imucal::calib
