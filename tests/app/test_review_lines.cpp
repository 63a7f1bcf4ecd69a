// SPDX-License-Identifier: BSD-3-Clause
// The review's text before the write (app/session/review_lines.hpp): every quantity the record
// stores in its unit with its sigma, and the change from the stored record in the same units.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "app/session/review_lines.hpp"

namespace imucal::app::session {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

std::string joined(const std::vector<std::string>& lines) {
  std::string out;
  for (const auto& line : lines) out += line + "\n";
  return out;
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

/// A static result on raw counts: scales 0.2 % above the nominal conversion, misalignment, an
/// estimated G; one sigma not determined.
StaticCalibrationResult a_static_result(const ImuStreamInfo& info) {
  StaticCalibrationResult r;
  r.model.accel.scale = info.accel.scale * 1.002;
  r.model.gyro.scale = info.gyro.scale * 0.999;
  r.model.accel.T = accel_misalignment(Eigen::Vector3d(1.5e-3, -0.5e-3, 2e-3));
  Eigen::Matrix<double, 6, 1> gamma;
  gamma << 1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3;
  r.model.gyro.T = gyro_misalignment(gamma);
  r.accel_sigma.scale = info.accel.scale * 1e-4;
  r.accel_sigma.scale[2] = std::numeric_limits<double>::quiet_NaN();
  r.gyro_sigma.scale = info.gyro.scale * 2e-4;
  r.accel_sigma.T(0, 1) = 0.1e-3;
  r.accel_sigma.T(0, 2) = 0.2e-3;
  r.accel_sigma.T(1, 2) = 0.3e-3;
  r.gyro_sigma.T = Eigen::Matrix3d::Constant(0.05e-3);
  r.canonical.A_a = r.model.accel.TK();
  r.canonical.A_g = r.model.gyro.TK();
  r.canonical.b_a = Eigen::Vector3d(-350, 80, -90);
  r.canonical.b_g = Eigen::Vector3d(-5, 140, -120);
  r.accel_sigma.bias = Eigen::Vector3d::Constant(0.9);
  r.gyro_sigma.bias = Eigen::Vector3d::Constant(0.08);
  r.gsens_mode = GSensitivityMode::kEstimate;
  r.canonical.G(0, 2) = 1e-4;  // rad/s per m/s^2
  r.gsens_sigma = Eigen::Matrix3d::Constant(3e-6);
  return r;
}

ImuStreamInfo raw_counts() {
  ImuStreamInfo info;
  info.units = ImuUnits::kRaw;
  info.accel.scale = Eigen::Vector3d::Constant(kStandardGravity / 16384.0);
  info.gyro.scale = Eigen::Vector3d::Constant(kDeg / 131.0);
  return info;
}

TEST(ReviewLines, TheImuShowsScalesMisalignmentAndGSensitivityWithSigmas) {
  const ImuStreamInfo info = raw_counts();
  const std::string text = joined(imu_review_lines(a_static_result(info), info));
  // Scales against the driver's conversion: +2.000 e-3 and -1.000 e-3, sigmas 0.1 and 0.2 e-3.
  EXPECT_TRUE(has(text, "Accel scale against nominal (e-3): 2.000 2.000 2.000 +- 0.100 0.100 not determined"))
      << text;
  EXPECT_TRUE(has(text, "Gyro scale against nominal (e-3): -1.000 -1.000 -1.000 +- 0.200 0.200 0.200"))
      << text;
  // Tedaldi's angles in mrad with the sigma of their entry of T.
  EXPECT_TRUE(
      has(text, "Accel misalignment (mrad): yz 1.500 +- 0.100, zy -0.500 +- 0.200, zx 2.000 +- 0.300"))
      << text;
  EXPECT_TRUE(has(text,
                  "Gyro misalignment (mrad): yz 1.000 +- 0.050, zy 2.000 +- 0.050, xz 3.000 +- 0.050, "
                  "zx 4.000 +- 0.050, xy 5.000 +- 0.050, yx 6.000 +- 0.050"))
      << text;
  // G in deg/s per g: 1e-4 rad/s per m/s^2 is 0.0562 deg/s per g.
  EXPECT_TRUE(has(text, "G-sensitivity (deg/s per g), estimated:")) << text;
  EXPECT_TRUE(has(text, "  x: 0.0000 0.0000 0.0562 +- 0.0017 0.0017 0.0017")) << text;
  EXPECT_TRUE(has(text, "counts)")) << text;  // the biases in counts beside on raw input
}

TEST(ReviewLines, AGSensitivityNotEstimatedIsSaidSoWithoutASigmaOfZero) {
  const ImuStreamInfo info = raw_counts();
  StaticCalibrationResult r = a_static_result(info);
  r.gsens_mode = GSensitivityMode::kOff;
  r.canonical.G.setZero();
  EXPECT_TRUE(
      has(joined(imu_review_lines(r, info)), "G-sensitivity: not estimated (gsens off): stored as 0"));
  r.gsens_mode = GSensitivityMode::kFixed;
  r.gsens_sigma.setZero();
  const std::string text = joined(imu_review_lines(r, info));
  EXPECT_TRUE(has(text, "given, held")) << text;
  EXPECT_FALSE(has(text, "+- 0.0000")) << text;
}

calib::ThermalResult a_thermal_result() {
  calib::ThermalResult t;
  t.determined = true;
  t.reference_c = 40.0;
  t.temp_min_c = 25.0;
  t.temp_max_c = 55.0;
  t.bins = 30;
  for (int a = 0; a < 3; ++a) {
    calib::ThermalAxisFit& g = t.gyro[a];
    g.determined = true;
    g.order = 2;
    g.coeffs = Eigen::Vector3d(0.0, 1e-4 * kDeg, -2e-6 * kDeg);  // c0, c1 (deg/s/K), c2
    g.covariance = Eigen::Matrix3d::Zero();
    g.covariance(1, 1) = std::pow(3e-6 * kDeg, 2);
    g.covariance(2, 2) = std::pow(4e-8 * kDeg, 2);
  }
  t.accel[0].determined = true;
  t.accel[0].order = 1;
  t.accel[0].coeffs = Eigen::Vector2d(9.8, 0.002 * kStandardGravity * 1e-3);  // 0.002 mg/K
  t.accel[0].covariance = Eigen::Matrix2d::Zero();
  t.accel[1].reason = "no order could be fitted";
  t.accel[2].reason = "no order could be fitted";
  return t;
}

TEST(ReviewLines, TheThermalModelShowsItsCoefficientsWithSigmas) {
  const std::string text = joined(thermal_review_lines(a_thermal_result()));
  EXPECT_TRUE(has(text, "  gyro x: c1 0.0001 +- 3e-06 deg/s/K, c2 -2e-06 +- 4e-08 deg/s/K^2")) << text;
  // A covariance of 0 was not computed: not determined, never a sigma of 0.
  EXPECT_TRUE(has(text, "  accel x: c1 0.002 +- not determined mg/K")) << text;
  EXPECT_TRUE(has(text, "  accel y: not determined (no order could be fitted)")) << text;
  EXPECT_TRUE(has(text, "sensitivity against temperature: not determined")) << text;
}

CameraRecord a_camera() {
  CameraRecord c;
  c.name = "cam0";
  c.T_cam_imu(0, 3) = 0.05;
  c.rotation_sigma_rad = Eigen::Vector3d::Constant(1e-4);
  c.translation_sigma_m = Eigen::Vector3d::Constant(1e-3);
  c.timeshift_cam_imu_s = 3.62e-3;
  c.timeshift_sigma_s = 0.05e-3;
  c.line_delay_s = 29.5e-6;
  c.line_delay_sigma_s = std::numeric_limits<double>::quiet_NaN();
  CameraIntrinsicsRecord k;
  k.camera.projection = ProjectionModel::kPinhole;
  k.camera.distortion_model = DistortionModel::kRadtan;
  k.camera.intrinsics = Eigen::Vector4d(458.65, 457.30, 367.22, 248.38);
  k.camera.distortion_coeffs = Eigen::Vector4d(-0.2834, 0.0740, 0.0002, 0.00002);
  k.camera.width = 752;
  k.camera.height = 480;
  k.intrinsics_sigma = {0.21, 0.2, 0.15, std::numeric_limits<double>::quiet_NaN()};
  k.distortion_coeffs_sigma = {0.0011, 0.0009, 0.00004, 0.00005};
  c.intrinsics = k;
  return c;
}

TEST(ReviewLines, ACameraShowsItsIntrinsicsAndLineDelayWithSigmas) {
  const std::string text = joined(camera_review_lines(a_camera(), 0.21));
  EXPECT_TRUE(has(text, "translation 50.00 0.00 0.00 +- 1.00 1.00 1.00 mm")) << text;
  EXPECT_TRUE(has(text, "time offset 3.620 +- 0.050 ms, line delay 29.500 +- not determined us per row"))
      << text;
  EXPECT_TRUE(has(text,
                  "  intrinsics (pinhole-radtan, 752x480): fu 458.65 +- 0.21 px, fv 457.30 +- 0.20 px, "
                  "pu 367.22 +- 0.15 px, pv 248.38 +- not determined px"))
      << text;
  EXPECT_TRUE(has(text, "  distortion: k1 -0.2834 +- 0.0011, k2 0.07400 +- 0.00090, p1 0.000200 +- 0.000040"))
      << text;
  CameraRecord bare = a_camera();
  bare.intrinsics.reset();
  EXPECT_TRUE(has(joined(camera_review_lines(bare, 0.21)), "intrinsics: not stored with this camera"));
}

TEST(ReviewLines, TheChangeOfACameraIncludesItsIntrinsics) {
  const CameraRecord old = a_camera();
  CameraRecord now = old;
  now.T_cam_imu(1, 3) += 0.002;
  now.intrinsics->camera.intrinsics[0] += 1.25;
  now.intrinsics->camera.distortion_coeffs[1] += 0.003;
  const std::string line = camera_change_line(now, old);
  EXPECT_TRUE(has(line, "translation 0.00 2.00 0.00 mm (2.00 mm)")) << line;
  EXPECT_TRUE(has(line, "line delay 0.000 us per row")) << line;
  EXPECT_TRUE(has(line, "fu fv pu pv 1.25 0.00 0.00 0.00 px, other figures 0.003 (largest)")) << line;
  CameraRecord other = now;
  other.intrinsics->camera.distortion_model = DistortionModel::kEquidistant;
  EXPECT_TRUE(has(camera_change_line(other, old), "pinhole-radtan 752x480 before, pinhole-equi 752x480 now"));
  CameraRecord without = old;
  without.intrinsics.reset();
  EXPECT_TRUE(has(camera_change_line(now, without), "intrinsics not in the stored record"));
}

ThermalModel a_thermal_model(double slope) {
  ThermalModel m;
  m.reference_c = 40.0;
  m.min_c = 20.0;
  m.max_c = 60.0;
  for (int a = 0; a < 3; ++a) {
    m.gyro[a].determined = true;
    m.gyro[a].coeffs = Eigen::VectorXd::Constant(1, slope);
    m.gyro[a].sigma = Eigen::VectorXd::Constant(1, 1e-6);
    m.accel[a].determined = true;
    m.accel[a].coeffs = Eigen::VectorXd::Constant(1, 0.0);
    m.accel[a].sigma = Eigen::VectorXd::Constant(1, 1e-6);
  }
  return m;
}

TEST(ReviewLines, TheThermalChangeComparesTheModelledDriftOverTheCommonRange) {
  ImuStreamInfo si;
  // The same slope about another reference: no difference in the drift.
  ThermalModel stored = a_thermal_model(1e-4 * kDeg);
  stored.reference_c = 30.0;
  const std::string same = joined(thermal_change_lines(a_thermal_model(1e-4 * kDeg), stored, si));
  EXPECT_TRUE(has(same, "over 20.0 .. 60.0 C: gyro 0.0000 0.0000 0.0000 deg/s")) << same;
  // A slope 1e-4 deg/s/K steeper, over 20 C on either side of the anchor at 40 C: 0.0020 deg/s.
  stored.gyro[1].coeffs[0] = 2e-4 * kDeg;
  stored.min_c = 30.0;
  const std::string steeper = joined(thermal_change_lines(a_thermal_model(1e-4 * kDeg), stored, si));
  EXPECT_TRUE(has(steeper, "over 30.0 .. 60.0 C: gyro 0.0000 0.0020 0.0000 deg/s")) << steeper;
  stored.min_c = 61.0;
  stored.max_c = 70.0;
  EXPECT_TRUE(has(joined(thermal_change_lines(a_thermal_model(1e-4 * kDeg), stored, si)), "do not overlap"));
  EXPECT_TRUE(
      has(joined(thermal_change_lines(a_thermal_model(0.0), std::nullopt, si)), "none stored before"));
}

TEST(ReviewLines, TheImuChangeIncludesMisalignmentAndGSensitivity) {
  CanonicalImuModel old;
  old.A_a = Eigen::Matrix3d::Identity();
  old.A_g = Eigen::Matrix3d::Identity();
  CanonicalImuModel now = old;
  now.A_g(0, 1) = 2e-3;  // 2 mrad
  now.G(2, 0) = 1e-4;    // 0.0562 deg/s per g
  const std::string text = joined(imu_change_lines(now, old, false));
  EXPECT_TRUE(has(
      text, "misalignment: accel 0.000 mrad, gyro 2.000 mrad (largest); G-sensitivity 0.0562 deg/s per g"))
      << text;
  EXPECT_FALSE(has(text, "counts")) << text;
}

}  // namespace
}  // namespace imucal::app::session
