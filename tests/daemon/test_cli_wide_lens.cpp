// SPDX-License-Identifier: BSD-3-Clause
// A wide lens through the commands: the virtual rig renders a double sphere (ds-none) camera
// (`imucal sim camimu --camera-model ds-none`), `calibrate camera --model ds-none` writes its
// parameters in Kalibr's order with their covariance and the profile check, and `calibrate
// camimu` reads that file back, propagates the covariance and finds the time offset within its
// sigmas. A wrong parameter order or model name anywhere on the way breaks the reprojection.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <string>

#include "core/camera_model.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using ::testing::HasSubstr;

TEST(CliWideLens, ADoubleSphereCameraIsCalibratedAndItsFileCarriesTheCameraImuSolve) {
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/ds.imulog";
  auto r = test::run_cli({"sim", "camimu", "--seed", "5", "--duration", "12", "--camera-rate", "10",
                          "--camera-model", "ds-none", "-o", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const YAML::Node truth = YAML::LoadFile(dir + "/ds.truth.yaml")["camera"]["cam0"];
  ASSERT_EQ(truth["camera_model"].as<std::string>(), "ds");

  const std::string cam = dir + "/ds.yaml";
  r = test::run_cli({"calibrate", "camera", "--model", "ds-none", "--self-check", "0", log, "-o", cam});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("model ds-none"));
  EXPECT_THAT(r.out, HasSubstr("xi"));
  const YAML::Node c0 = YAML::LoadFile(cam)["cam0"];
  EXPECT_EQ(c0["camera_model"].as<std::string>(), "ds");
  EXPECT_EQ(c0["distortion_model"].as<std::string>(), "none");
  ASSERT_EQ(c0["intrinsics"].size(), 6u);  // xi alpha fu fv pu pv
  const YAML::Node q = c0["imucal"];
  ASSERT_EQ(q["intrinsics_covariance"].size(), 6u);
  EXPECT_EQ(q["intrinsics_covariance"][0].size(), 6u);
  EXPECT_GT(q["intrinsics_covariance"][0][0].as<double>(), 0.0);
  EXPECT_TRUE(std::isfinite(q["profile_chi2"].as<double>()));
  EXPECT_GE(q["profile_sigma_stretch"].as<double>(), 1.0);
  EXPECT_LT(q["reprojection_rms_px"].as<double>(), 0.1);
  // The image scale near the centre, f / (1 + xi), is what the views fix best.
  const auto scale = [](const YAML::Node& k) { return k[2].as<double>() / (1.0 + k[0].as<double>()); };
  EXPECT_NEAR(scale(c0["intrinsics"]), scale(truth["intrinsics"]), 0.02 * scale(truth["intrinsics"]));

  const std::string out = dir + "/camimu";
  r = test::run_cli({"calibrate", "camimu", "--self-check", "0", log, "--camera", cam, "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const YAML::Node ci = YAML::LoadFile(out + "/camchain-imucam.yaml")["cam0"];
  EXPECT_EQ(ci["camera_model"].as<std::string>(), "ds");
  EXPECT_THAT(ci["imucal"]["intrinsics_uncertainty"].as<std::string>(), HasSubstr("propagated"));
  EXPECT_LT(ci["imucal"]["reprojection_rms_px"].as<double>(), 0.1);
  const double shift = ci["timeshift_cam_imu"].as<double>();
  const double sigma = ci["imucal"]["timeshift_sigma_s"].as<double>();
  EXPECT_GT(sigma, 0.0);
  EXPECT_LE(std::abs(shift - truth["timeshift_cam_imu"].as<double>()), 3.0 * sigma)
      << shift << " truth " << truth["timeshift_cam_imu"].as<double>() << " sigma " << sigma;
}

}  // namespace
}  // namespace imucal
