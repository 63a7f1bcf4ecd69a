// imucal calibrate camera on the committed camera-IMU fixture: the intrinsics against the
// simulator's truth within the reported sigmas, stored detections reused, output-file rules, the
// target's sources, and a log imported from a EuRoC folder (PNG frames).

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/camera_model.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::read_file;
using test::run_cli;
using test::scratch_dir;
using test::source_path;

/// A copy of the fixture: the command stores its detections in the log it reads.
CameraModel truth_camera() {
  const YAML::Node truth = YAML::LoadFile(source_path("fixtures/camimu.truth.yaml"));
  auto camera = camera_from_yaml(truth["camera"]["cam0"], "camimu.truth.yaml");
  EXPECT_TRUE(camera.ok());
  return *camera;
}

/// Every parameter of the result file within 3 of its reported sigmas of the truth.
void expect_truth_within_three_sigmas(const std::string& yaml_path) {
  const YAML::Node cam0 = YAML::LoadFile(yaml_path)["cam0"];
  auto est = camera_from_yaml(cam0, yaml_path);
  ASSERT_TRUE(est.ok()) << est.error().message;
  const CameraModel truth = truth_camera();
  EXPECT_EQ(est->width, truth.width);
  EXPECT_EQ(est->height, truth.height);
  EXPECT_EQ(est->distortion_model, DistortionModel::kRadtan);
  for (int i = 0; i < 4; ++i) {
    const double s = cam0["imucal"]["intrinsics_sigma"][i].as<double>();
    EXPECT_GT(s, 0.0);
    EXPECT_LE(std::abs(est->intrinsics[i] - truth.intrinsics[i]), 3.0 * s)
        << "intrinsics[" << i << "] " << est->intrinsics[i] << " truth " << truth.intrinsics[i] << " sigma "
        << s;
    const double sd = cam0["imucal"]["distortion_coeffs_sigma"][i].as<double>();
    EXPECT_GT(sd, 0.0);
    EXPECT_LE(std::abs(est->distortion_coeffs[i] - truth.distortion_coeffs[i]), 3.0 * sd)
        << "distortion[" << i << "] " << est->distortion_coeffs[i] << " truth " << truth.distortion_coeffs[i]
        << " sigma " << sd;
  }
  EXPECT_TRUE(cam0["imucal"]["focal_well_determined"].as<bool>());
  EXPECT_GE(cam0["imucal"]["views_used"].as<int>(), 100);
  EXPECT_LT(cam0["imucal"]["reprojection_rms_px"].as<double>(), 0.2);
}

TEST(CliCalibrateCamera, FixtureWithinThreeSigmasOfTruthAndDetectionsReused) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  auto r = run_cli({"calibrate", "camera", log, "-o", dir + "/cam.yaml"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("detections stored in the log"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("target from target metadata"), std::string::npos) << r.out;
  expect_truth_within_three_sigmas(dir + "/cam.yaml");

  // The second run reads the stored detections and finds the same camera.
  r = run_cli({"calibrate", "camera", log, "-o", dir + "/again.yaml", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["detections"]["reused"].get<bool>());
  const YAML::Node first = YAML::LoadFile(dir + "/cam.yaml")["cam0"];
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(j["intrinsics"][i].get<double>(), first["intrinsics"][i].as<double>(), 1e-9);
    EXPECT_NEAR(j["distortion_coeffs"][i].get<double>(), first["distortion_coeffs"][i].as<double>(), 1e-12);
  }
  EXPECT_EQ(j["views_used"].get<int>(), first["imucal"]["views_used"].as<int>());
}

TEST(CliCalibrateCamera, OutputRules) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  const std::string out = dir + "/cam.yaml";
  { std::ofstream(out) << "keep me\n"; }
  // Refusals come before any work: the log is not searched (no detections are stored).
  auto r = run_cli({"calibrate", "camera", log, "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("pass --force"), std::string::npos) << r.err;
  EXPECT_EQ(read_file(out), "keep me\n");
  r = run_cli({"calibrate", "camera", log, "-o", log, "--force"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("input"), std::string::npos) << r.err;
  const std::string target = dir + "/target.yaml";
  {
    std::ofstream(target) << "target_type: checkerboard\ntargetCols: 7\ntargetRows: 6\n"
                             "rowSpacingMeters: 0.05\ncolSpacingMeters: 0.05\n";
  }
  r = run_cli({"calibrate", "camera", log, "--target", target, "-o", target, "--force"});
  EXPECT_EQ(r.exit_code, 2);
  r = run_cli({"calibrate", "camera", log, "-o", out, "--model", "omni"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(read_file(out), "keep me\n");
  r = run_cli({"calibrate", "camera", log, "--camera", "cam9", "-o", dir + "/x.yaml"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("cam9"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/x.yaml"));
}

// A damaged log is refused, or with --allow-damaged calibrated from its readable part and left
// exactly as it was (no detections are written into it).
TEST(CliCalibrateCamera, DamagedLogIsNeverWritten) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  std::filesystem::resize_file(log, std::filesystem::file_size(log) * 7 / 10);
  const std::string before = read_file(log);
  auto r = run_cli({"calibrate", "camera", log, "-o", dir + "/cam.yaml"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("--allow-damaged"), std::string::npos) << r.err;
  r = run_cli({"calibrate", "camera", log, "--allow-damaged", "-o", dir + "/cam.yaml", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("detections not stored in the log: it is damaged"), std::string::npos) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_FALSE(j["detections"]["stored"].get<bool>());
  EXPECT_GT(j["views_used"].get<int>(), 5);
  EXPECT_EQ(read_file(log), before);
  EXPECT_FALSE(std::filesystem::exists(log + "-journal"));
}

// A log imported from a EuRoC folder has PNG frames and no target: it needs --target, then it
// calibrates like the log it was exported from.
TEST(CliCalibrateCamera, EurocImportNeedsTargetAndCalibratesTheSame) {
  const std::string dir = scratch_dir();
  auto r = run_cli({"export", "euroc", source_path("fixtures/camimu.imulog"), dir + "/euroc"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string log = dir + "/imported.imulog";
  r = run_cli({"import", "euroc", dir + "/euroc", "-o", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;

  r = run_cli({"calibrate", "camera", log, "-o", dir + "/cam.yaml"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("pass --target"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/cam.yaml"));

  const std::string target = dir + "/target.yaml";
  {
    std::ofstream(target) << "target_type: checkerboard\ntargetCols: 7\ntargetRows: 6\n"
                             "rowSpacingMeters: 0.05\ncolSpacingMeters: 0.05\n";
  }
  r = run_cli({"calibrate", "camera", log, "--target", target, "--threads", "2", "-o", dir + "/cam.yaml"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  expect_truth_within_three_sigmas(dir + "/cam.yaml");
  EXPECT_EQ(YAML::LoadFile(dir + "/cam.yaml")["cam0"]["imucal"]["target_source"].as<std::string>(), target);
}

}  // namespace
}  // namespace imucal
