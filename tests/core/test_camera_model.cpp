// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <random>

#include "core/camera_model.hpp"

namespace imucal {
namespace {

CameraModel radtan_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics << 458.654, 457.296, 367.215, 248.375;  // EuRoC cam0
  c.distortion_coeffs << -0.28340811, 0.07395907, 0.00019359, 1.76187114e-05;
  c.width = 752;
  c.height = 480;
  return c;
}

CameraModel equi_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kEquidistant;
  // TUM-VI cam0 coefficients with a narrower field of view: the model (like cv::fisheye) maps
  // rays with theta < 90 deg only.
  c.intrinsics << 300.0, 300.5, 321.5, 238.7;
  c.distortion_coeffs << 0.0034823, 0.000715, -0.0020532, 0.000202935;
  c.width = 640;
  c.height = 480;
  return c;
}

void expect_round_trip(const CameraModel& camera) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int checked = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector2d px(u(rng) * (camera.width - 1), u(rng) * (camera.height - 1));
    Eigen::Vector3d ray;
    ASSERT_TRUE(camera.unproject(px, &ray)) << px.transpose();
    EXPECT_NEAR(ray.norm(), 1.0, 1e-14);
    const auto proj = camera.project(ray * (0.5 + 3.0 * u(rng)));
    ASSERT_TRUE(proj.valid()) << px.transpose();
    EXPECT_NEAR((proj.px - px).norm(), 0.0, 1e-8) << px.transpose();
    ++checked;
  }
  EXPECT_EQ(checked, 2000);
  // And point -> pixel -> ray: the ray is parallel to the point.
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d p(u(rng) - 0.5, u(rng) - 0.5, 0.8 + u(rng));
    const auto proj = camera.project(p);
    if (!proj.valid()) continue;
    Eigen::Vector3d ray;
    ASSERT_TRUE(camera.unproject(proj.px, &ray));
    EXPECT_LT((ray - p.normalized()).norm(), 1e-11);
  }
}

TEST(CameraModel, RadtanUnprojectInvertsProject) { expect_round_trip(radtan_camera()); }

TEST(CameraModel, EquidistantUnprojectInvertsProject) { expect_round_trip(equi_camera()); }

TEST(CameraModel, ZeroDistortionIsPinhole) {
  for (auto model : {DistortionModel::kRadtan, DistortionModel::kEquidistant}) {
    CameraModel c = radtan_camera();
    c.distortion_model = model;
    c.distortion_coeffs.setZero();
    const auto proj = c.project(Eigen::Vector3d(0.1, -0.2, 2.0));
    if (model == DistortionModel::kRadtan) {
      EXPECT_NEAR(proj.px.x(), 458.654 * 0.05 + 367.215, 1e-12);
      EXPECT_NEAR(proj.px.y(), 457.296 * -0.1 + 248.375, 1e-12);
    } else {
      // Equidistant without coefficients is r_d = atan(r), not the pinhole r.
      const double r = std::hypot(0.05, -0.1);
      EXPECT_NEAR(proj.px.x(), 458.654 * 0.05 * std::atan(r) / r + 367.215, 1e-12);
    }
  }
}

TEST(CameraModel, Validity) {
  const CameraModel c = radtan_camera();
  EXPECT_TRUE(c.project(Eigen::Vector3d(0, 0, 1)).valid());
  const auto behind = c.project(Eigen::Vector3d(0, 0, -1));
  EXPECT_FALSE(behind.in_front);
  EXPECT_FALSE(behind.valid());
  const auto outside = c.project(Eigen::Vector3d(1.5, 0, 1));  // beyond the 752 px width
  EXPECT_TRUE(outside.in_front);
  EXPECT_FALSE(outside.in_image);
  // Far outside the field of view the barrel distortion folds back (r_d decreases with r): the
  // pixel can land on the sensor, but the point is not seen there.
  CameraModel barrel = c;
  barrel.distortion_coeffs << -0.3, 0.0, 0.0, 0.0;  // r_d = r (1 - 0.3 r^2) peaks at r = 1.054
  const auto folded = barrel.project(Eigen::Vector3d(1.6, 0.0, 1.0));
  EXPECT_TRUE(folded.in_image);
  EXPECT_FALSE(folded.in_front);
  EXPECT_FALSE(folded.valid());
  EXPECT_TRUE(barrel.project(Eigen::Vector3d(1.0, 0.0, 1.0)).valid());
  // Image bounds follow the pixel-centre convention.
  CameraModel p = c;
  p.distortion_coeffs.setZero();
  const double fu = p.intrinsics[0];
  const double pu = p.intrinsics[2];
  EXPECT_TRUE(p.project(Eigen::Vector3d((-0.49 - pu) / fu, 0, 1)).in_image);
  EXPECT_FALSE(p.project(Eigen::Vector3d((-0.51 - pu) / fu, 0, 1)).in_image);
  EXPECT_TRUE(p.project(Eigen::Vector3d((751.49 - pu) / fu, 0, 1)).in_image);
  EXPECT_FALSE(p.project(Eigen::Vector3d((751.5 - pu) / fu, 0, 1)).in_image);
}

TEST(CameraModel, UnprojectRejectsPixelsOutsideTheInvertibleRegion) {
  CameraModel c = equi_camera();
  // theta_d = 3 rad cannot be reached with theta < pi/2 by this nearly linear model.
  Eigen::Vector3d ray;
  EXPECT_FALSE(c.unproject(Eigen::Vector2d(c.intrinsics[2] + 3.0 * c.intrinsics[0], c.intrinsics[3]), &ray));
  CameraModel r = radtan_camera();
  r.distortion_coeffs << -0.3, 0.0, 0.0, 0.0;  // r_d <= 0.703
  // Beyond the fold of the barrel distortion there is no preimage.
  EXPECT_FALSE(r.unproject(Eigen::Vector2d(r.intrinsics[2] + 2.0 * r.intrinsics[0], r.intrinsics[3]), &ray));
}

TEST(CameraModel, YamlRoundTripKalibrNames) {
  for (const CameraModel& c : {radtan_camera(), equi_camera()}) {
    const std::string text = camera_to_yaml_text(c);
    EXPECT_NE(text.find("camera_model: pinhole"), std::string::npos) << text;
    EXPECT_NE(text.find("distortion_model: " + std::string(distortion_model_name(c.distortion_model))),
              std::string::npos)
        << text;
    auto back = parse_camera_yaml(text, "test");
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->distortion_model, c.distortion_model);
    EXPECT_EQ(back->intrinsics, c.intrinsics);
    EXPECT_EQ(back->distortion_coeffs, c.distortion_coeffs);
    EXPECT_EQ(back->width, c.width);
    EXPECT_EQ(back->height, c.height);
  }
}

// imucal's shutter keys: written only for a rolling shutter, read back exactly; a camera map
// without them is global; the row times follow the readout direction and the stamped row.
TEST(CameraModel, RollingShutterKeysRoundTripAndGiveEachRowItsTime) {
  EXPECT_EQ(camera_to_yaml_text(radtan_camera()).find("shutter"), std::string::npos);
  CameraModel c = radtan_camera();
  c.shutter.kind = Shutter::Kind::kRolling;
  c.shutter.line_delay_s = 29.5e-6;
  c.shutter.readout = Shutter::Readout::kBottomToTop;
  c.shutter.stamp_row = Shutter::StampRow::kMiddle;
  auto back = parse_camera_yaml(camera_to_yaml_text(c), "test");
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(back->shutter.rolling());
  EXPECT_DOUBLE_EQ(back->shutter.line_delay_s, 29.5e-6);
  EXPECT_EQ(back->shutter.readout, Shutter::Readout::kBottomToTop);
  EXPECT_EQ(back->shutter.stamp_row, Shutter::StampRow::kMiddle);
  // Bottom to top, stamped at the middle row: the last image row is read first.
  const int h = c.height;
  EXPECT_DOUBLE_EQ(c.shutter.row_offset(h - 1, h), -0.5 * (h - 1));
  EXPECT_DOUBLE_EQ(c.shutter.row_offset(0, h), 0.5 * (h - 1));
  EXPECT_DOUBLE_EQ(c.shutter.readout_s(h), 29.5e-6 * (h - 1));
  Shutter first;
  first.kind = Shutter::Kind::kRolling;
  first.line_delay_s = 1e-5;
  EXPECT_DOUBLE_EQ(first.row_time(100.0, h), 1e-3);
  EXPECT_DOUBLE_EQ(Shutter{}.row_time(100.0, h), 0.0);  // global

  const std::string base =
      "camera_model: pinhole\ndistortion_model: radtan\nintrinsics: [450, 450, 188, 120]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [376, 240]\n";
  auto global = parse_camera_yaml(base + "shutter: global\n", "cam.yaml");
  ASSERT_TRUE(global.ok());
  EXPECT_FALSE(global->shutter.rolling());
  auto no_delay = parse_camera_yaml(base + "shutter: rolling\n", "cam.yaml");
  ASSERT_FALSE(no_delay.ok());
  EXPECT_NE(no_delay.error().message.find("needs line_delay_s"), std::string::npos);
  // Microseconds written as seconds: 30 s per row.
  auto micro = parse_camera_yaml(base + "shutter: rolling\nline_delay_s: 30\n", "cam.yaml");
  ASSERT_FALSE(micro.ok());
  EXPECT_NE(micro.error().message.find("3.0e-05"), std::string::npos) << micro.error().message;
  auto dir =
      parse_camera_yaml(base + "shutter: rolling\nline_delay_s: 3e-5\nreadout_direction: left\n", "cam.yaml");
  ASSERT_FALSE(dir.ok());
  EXPECT_NE(dir.error().message.find("top_to_bottom or bottom_to_top"), std::string::npos);
}

TEST(CameraModel, ReadsKalibrCamchainEntry) {
  const std::string text = R"(
T_cam_imu:
- [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975]
- [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768]
- [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949]
- [0.0, 0.0, 0.0, 1.0]
camera_model: pinhole
distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
distortion_model: radtan
intrinsics: [458.654, 457.296, 367.215, 248.375]
resolution: [752, 480]
timeshift_cam_imu: 0.0
)";
  auto c = parse_camera_yaml(text, "camchain.yaml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->width, 752);
  EXPECT_DOUBLE_EQ(c->intrinsics[3], 248.375);
  EXPECT_DOUBLE_EQ(c->distortion_coeffs[0], -0.28340811);
}

TEST(CameraModel, BadYamlSaysWhatIsWrong) {
  auto missing = parse_camera_yaml("camera_model: pinhole\ndistortion_model: radtan\n", "cam.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("cam.yaml"), std::string::npos);
  EXPECT_NE(missing.error().message.find("intrinsics"), std::string::npos);

  auto kb = parse_camera_yaml(
      "camera_model: kb4\ndistortion_model: none\nintrinsics: [1,1,1,1]\n"
      "distortion_coeffs: []\nresolution: [10,10]\n",
      "cam.yaml");
  ASSERT_FALSE(kb.ok());
  EXPECT_NE(kb.error().message.find("pinhole, omni, eucm or ds"), std::string::npos);

  // Kalibr's omni intrinsics hold xi first: four numbers are one too few.
  auto omni = parse_camera_yaml(
      "camera_model: omni\ndistortion_model: radtan\nintrinsics: [1,1,1,1]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [10,10]\n",
      "cam.yaml");
  ASSERT_FALSE(omni.ok());
  EXPECT_NE(omni.error().message.find("[xi, fu, fv, pu, pv]"), std::string::npos) << omni.error().message;

  // fov has one coefficient, w.
  auto fov = parse_camera_yaml(
      "camera_model: pinhole\ndistortion_model: fov\nintrinsics: [1,1,1,1]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [10,10]\n",
      "cam.yaml");
  ASSERT_FALSE(fov.ok());
  EXPECT_NE(fov.error().message.find("list of 1 numbers"), std::string::npos) << fov.error().message;

  // ds with radtan is no model Kalibr has.
  auto ds_radtan = parse_camera_yaml(
      "camera_model: ds\ndistortion_model: radtan\nintrinsics: [0,0.5,1,1,1,1]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [10,10]\n",
      "cam.yaml");
  ASSERT_FALSE(ds_radtan.ok());
  EXPECT_NE(ds_radtan.error().message.find("ds-radtan"), std::string::npos) << ds_radtan.error().message;

  // Principal point outside the image: intrinsics probably for another resolution.
  auto pp = parse_camera_yaml(
      "camera_model: pinhole\ndistortion_model: radtan\nintrinsics: [450, 450, 700, 500]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [376, 240]\n",
      "cam.yaml");
  ASSERT_FALSE(pp.ok());
  EXPECT_NE(pp.error().message.find("principal point"), std::string::npos);

  // A focal length no lens has (1e308 px; a thousand times the image): refused, not taken as a
  // camera that sees nothing.
  auto far = parse_camera_yaml(
      "camera_model: pinhole\ndistortion_model: radtan\nintrinsics: [1e308, 450, 188, 120]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [376, 240]\n",
      "cam.yaml");
  ASSERT_FALSE(far.ok());
  EXPECT_NE(far.error().message.find("focal length (fu, fv) = (1e+308, 450) px"), std::string::npos)
      << far.error().message;
  auto long_lens = parse_camera_yaml(
      "camera_model: pinhole\ndistortion_model: radtan\nintrinsics: [376001, 376001, 188, 120]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [376, 240]\n",
      "cam.yaml");
  EXPECT_FALSE(long_lens.ok());
  auto longest_lens = parse_camera_yaml(
      "camera_model: pinhole\ndistortion_model: radtan\nintrinsics: [376000, 376000, 188, 120]\n"
      "distortion_coeffs: [0,0,0,0]\nresolution: [376, 240]\n",
      "cam.yaml");
  EXPECT_TRUE(longest_lens.ok());

  auto short_coeffs = parse_camera_yaml(
      "camera_model: pinhole\ndistortion_model: radtan\nintrinsics: [450, 450, 100, 100]\n"
      "distortion_coeffs: [0,0,0]\nresolution: [376, 240]\n",
      "cam.yaml");
  ASSERT_FALSE(short_coeffs.ok());
  EXPECT_NE(short_coeffs.error().message.find("distortion_coeffs"), std::string::npos);
}

}  // namespace
}  // namespace imucal
