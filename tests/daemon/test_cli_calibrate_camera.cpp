// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate camera on the committed camera-IMU fixture: the intrinsics against the
// simulator's truth within the reported sigmas, stored detections reused, output-file rules, the
// target's sources, and a log imported from a EuRoC folder (PNG frames).

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
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

// The input log is never written: the detections go to the cache, keyed by the frames' content,
// and the next run reuses them from there (from any copy of the log).
TEST(CliCalibrateCamera, FixtureWithinThreeSigmasOfTruthAndDetectionsReused) {
  const std::string dir = scratch_dir();
  const test::ScopedCacheDir cache(dir + "/cache");
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  const std::string before = read_file(log);
  auto r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/cam.yaml"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("detections stored in " + dir + "/cache/detections/"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("target from target metadata"), std::string::npos) << r.out;
  expect_truth_within_three_sigmas(dir + "/cam.yaml");
  EXPECT_TRUE(read_file(log) == before) << "the input log was modified";
  // Progress reaches a file too: standard error is not a terminal here.
  EXPECT_NE(r.err.find("detecting the target: done after"), std::string::npos) << r.err;

  // The second run, on another copy, reads the cached detections and finds the same camera.
  std::filesystem::create_directories(dir + "/copy");
  const std::string copy = test::copy_fixture("camimu.imulog", dir + "/copy");
  r = run_cli({"calibrate", "camera", copy, "-o", dir + "/again.yaml", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["detections"]["reused"].get<bool>());
  EXPECT_NE(j["detections"]["reused_from"].get<std::string>().find(dir + "/cache/detections/"),
            std::string::npos);
  EXPECT_TRUE(read_file(log) == before) << "the input log was modified";
  const YAML::Node first = YAML::LoadFile(dir + "/cam.yaml")["cam0"];
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(j["intrinsics"][i].get<double>(), first["intrinsics"][i].as<double>(), 1e-9);
    EXPECT_NEAR(j["distortion_coeffs"][i].get<double>(), first["distortion_coeffs"][i].as<double>(), 1e-12);
  }
  EXPECT_EQ(j["views_used"].get<int>(), first["imucal"]["views_used"].as<int>());
  // The solve takes 400 of the views with the target, spread over the recording; the rest are
  // counted apart from the rejected ones.
  EXPECT_EQ(j["views_total"].get<int>(), 400);
  EXPECT_EQ(j["views_total"].get<int>() + j["views_not_chosen"].get<int>(),
            j["frames_with_target"].get<int>());
  EXPECT_GT(j["views_not_chosen"].get<int>(), 0);
  EXPECT_EQ(first["imucal"]["views_not_chosen"].as<int>(), j["views_not_chosen"].get<int>());
  // The self-check (the halves, by default): this rendered recording's halves agree.
  EXPECT_EQ(j["self_check"]["verdict"], "agree") << j["self_check"].dump(1);
  EXPECT_EQ(j["self_check"]["parts"], 2);
  EXPECT_EQ(j["self_check"]["parameters"].size(), 8u);  // fu fv pu pv k1 k2 p1 p2
  EXPECT_TRUE(j["self_check"]["sigmas_scaled"].empty());
}

// A Kalibr user's ROS bag where a log goes: imported once into the cache and read from there; as
// with a EuRoC import, a bag names no target, so --target gives it, and the camera comes out as
// from the log it was exported from. The bag is an input like the log (never an output).
TEST(CliCalibrateCamera, ARosBagIsImportedOnceAndCalibratesLikeItsLog) {
  const std::string dir = scratch_dir();
  const test::ScopedCacheDir cache(dir + "/cache");
  const std::string bag = dir + "/camimu.bag";
  auto r = run_cli({"export", "bag", source_path("fixtures/camimu.imulog"), bag});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string bag_bytes = read_file(bag);
  const std::string target = dir + "/target.yaml";
  {
    std::ofstream(target) << "target_type: checkerboard\ntargetCols: 7\ntargetRows: 6\n"
                             "rowSpacingMeters: 0.05\ncolSpacingMeters: 0.05\n";
  }
  r = run_cli({"calibrate", "camera", "--self-check", "0", bag, "--target", target, "--threads", "2", "-o",
               dir + "/cam.yaml"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find(bag + " is a ROS bag: imported 11820 IMU samples and 1200 frames into " + dir +
                       "/cache/bags/camimu-"),
            std::string::npos)
      << r.err;
  expect_truth_within_three_sigmas(dir + "/cam.yaml");
  EXPECT_EQ(YAML::LoadFile(dir + "/cam.yaml")["cam0"]["rostopic"].as<std::string>(), "/cam0/image_raw");
  // The result names the bag the user gave, not the import in the cache.
  EXPECT_NE(read_file(dir + "/cam.yaml").find("log: " + bag + "\n"), std::string::npos)
      << read_file(dir + "/cam.yaml");
  EXPECT_EQ(read_file(dir + "/cam.yaml").find("/cache/bags/"), std::string::npos);
  // So does its report's session section, read from the import.
  r = run_cli({"report", dir + "/cam.yaml", "--log", bag, "-o", dir + "/cam.html"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(read_file(dir + "/cam.html").find("Log <code>" + bag + "</code>"), std::string::npos);
  EXPECT_EQ(read_file(dir + "/cam.html").find("/cache/bags/"), std::string::npos);
  // The next command reads the import; the bag is never an output, and is never written.
  r = run_cli({"allan", bag, "-o", dir + "/imu.yaml"});
  EXPECT_NE(r.err.find("reading the log imported from it before"), std::string::npos) << r.err;
  r = run_cli({"calibrate", "camera", "--self-check", "0", bag, "--target", target, "-o", bag, "--force"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_TRUE(read_file(bag) == bag_bytes) << "the bag was modified";
  // A topic it does not have: the bag's topics are listed.
  r = run_cli({"calibrate", "camera", bag, "--topics", "/left/image_raw", "--target", target, "-o",
               dir + "/none.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("its topics: /cam0/image_raw (sensor_msgs/Image), /imu0 (sensor_msgs/Imu)"),
            std::string::npos)
      << r.err;
  // --no-cache: the import goes into a temporary folder, never into the cache.
  const test::ScopedCacheDir other(dir + "/cache2");
  r = run_cli({"calibrate", "camera", bag, "--topics", "/left/image_raw", "--target", target, "--no-cache",
               "-o", dir + "/none.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/cache2/bags"));
}

// --store-detections keeps the old way: the detections go into the log (when it is complete and
// undamaged) and the next run reuses them from there, with no cache at all.
TEST(CliCalibrateCamera, StoreDetectionsInTheLogWhenAsked) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  auto r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/cam.yaml",
                    "--store-detections", "--no-cache"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("detections stored in the log"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  views: 400 of the "), std::string::npos) << r.out;
  // Every view with the target when asked (--max-views 0); the camera within the sigmas of the
  // one from the views spread over the recording.
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/again.yaml", "--json",
               "--no-cache", "--max-views", "0"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["detections"]["reused_from"].get<std::string>(), "the log");
  EXPECT_EQ(j["views_not_chosen"].get<int>(), 0);
  EXPECT_EQ(j["views_total"].get<int>(), j["frames_with_target"].get<int>());
  const YAML::Node spread = YAML::LoadFile(dir + "/cam.yaml")["cam0"];
  for (int i = 0; i < 4; ++i)
    EXPECT_LE(std::abs(j["intrinsics"][i].get<double>() - spread["intrinsics"][i].as<double>()),
              spread["imucal"]["intrinsics_sigma"][i].as<double>())
        << "intrinsics[" << i << "]";
}

// A target file that does not match the board stops within the first frames and says what the
// frames show, instead of searching every frame for a board that is not there.
TEST(CliCalibrateCamera, WrongTargetStopsEarlyNamingTheBoardSeen) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  const std::string target = dir + "/small.yaml";
  {
    std::ofstream(target) << "target_type: checkerboard\ntargetCols: 5\ntargetRows: 4\n"
                             "rowSpacingMeters: 0.05\ncolSpacingMeters: 0.05\n";
  }
  auto r =
      run_cli({"calibrate", "camera", "--self-check", "0", log, "--target", target, "-o", dir + "/cam.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("a checkerboard of 7 x 6 inner corners"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("the target file says a checkerboard of 5 x 4 inner corners"), std::string::npos)
      << r.err;
  // It stopped early: the progress never got near the end of the 1200 frames.
  EXPECT_EQ(r.err.find("detecting the target: done"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("detecting the target: stopped at"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/cam.yaml"));
}

// Frames whose data fail their checksum are damage: refused without --allow-damaged (exit 3),
// and with it counted as not searched, never as frames without the target.
TEST(CliCalibrateCamera, FramesFailingTheirChecksumAreDamage) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  ASSERT_TRUE(test::run_sql(log,
                            "UPDATE frames SET data_crc32 = (data_crc32 + 1) % 4294967296 WHERE rowid IN "
                            "(SELECT rowid FROM frames ORDER BY t_ns LIMIT 3 OFFSET 100)"));
  auto r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/cam.yaml"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("has damaged frames"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--allow-damaged"), std::string::npos) << r.err;
  // It stopped at the first damaged frame.
  EXPECT_NE(r.err.find("detecting the target: stopped at"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/cam.yaml"));
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "--allow-damaged", "-o", dir + "/cam.yaml",
               "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("3 of the 1200 frames of camera stream 'cam0'"), std::string::npos) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["frames_failed"].get<int>(), 3);
  EXPECT_FALSE(j["detections"]["stored"].get<bool>());
}

TEST(CliCalibrateCamera, OutputRules) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  const std::string out = dir + "/cam.yaml";
  { std::ofstream(out) << "keep me\n"; }
  // Refusals come before any work: the log is not searched (no detections are stored).
  auto r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("pass --force"), std::string::npos) << r.err;
  EXPECT_EQ(read_file(out), "keep me\n");
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", log, "--force"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("input"), std::string::npos) << r.err;
  const std::string target = dir + "/target.yaml";
  {
    std::ofstream(target) << "target_type: checkerboard\ntargetCols: 7\ntargetRows: 6\n"
                             "rowSpacingMeters: 0.05\ncolSpacingMeters: 0.05\n";
  }
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "--target", target, "-o", target, "--force"});
  EXPECT_EQ(r.exit_code, 2);
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", out, "--model", "omni"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(read_file(out), "keep me\n");
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "--camera", "cam9", "-o", dir + "/x.yaml"});
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
  auto r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/cam.yaml"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("--allow-damaged"), std::string::npos) << r.err;
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "--allow-damaged", "--store-detections", "-o",
               dir + "/cam.yaml", "--json"});
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

  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/cam.yaml"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("pass --target"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/cam.yaml"));

  const std::string target = dir + "/target.yaml";
  {
    std::ofstream(target) << "target_type: checkerboard\ntargetCols: 7\ntargetRows: 6\n"
                             "rowSpacingMeters: 0.05\ncolSpacingMeters: 0.05\n";
  }
  r = run_cli({"calibrate", "camera", "--self-check", "0", log, "--target", target, "--threads", "2", "-o",
               dir + "/cam.yaml"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  expect_truth_within_three_sigmas(dir + "/cam.yaml");
  EXPECT_EQ(YAML::LoadFile(dir + "/cam.yaml")["cam0"]["imucal"]["target_source"].as<std::string>(), target);
}

}  // namespace
}  // namespace imucal
