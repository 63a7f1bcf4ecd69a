// SPDX-License-Identifier: BSD-3-Clause
// The camera calibration's solver-free pieces: the target a log names, stored detections' key
// and text, the result YAML (read back as a Kalibr camera) and JSON.

#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <tuple>

#include "app/camimu_inputs.hpp"
#include "app/results/camera_results.hpp"
#include "core/rig_config.hpp"

namespace imucal::app {
namespace {

TargetDescription board(int cols = 7) {
  TargetDescription t;
  t.cols = cols;
  t.rows = 6;
  t.col_spacing_m = 0.05;
  t.row_spacing_m = 0.05;
  return t;
}

TEST(CameraResults, TargetFromTheRigConfigurationFirst) {
  RigConfig config;
  CameraConfig cam;
  cam.name = "cam0";
  config.cameras.push_back(cam);
  TargetDescription grid;
  grid.type = TargetDescription::Type::kAprilgrid;
  grid.tag_cols = 6;
  grid.tag_rows = 6;
  grid.tag_size_m = 0.088;
  grid.tag_spacing = 0.3;
  config.target = grid;
  std::map<std::string, std::string> meta = {{"rig_config", rig_config_to_json(config)},
                                             {"target", target_to_yaml(board())}};
  auto t = target_from_log_metadata(meta);
  ASSERT_TRUE(t.ok()) << t.error().message;
  EXPECT_EQ(t->source, "rig_config metadata");
  EXPECT_EQ(t->target.type, TargetDescription::Type::kAprilgrid);
  EXPECT_EQ(t->target.tag_cols, 6);
  EXPECT_DOUBLE_EQ(t->target.tag_size_m, 0.088);

  // A rig configuration without a target: the simulator's target key.
  config.target.reset();
  config.cameras.clear();
  meta["rig_config"] = rig_config_to_json(config);
  t = target_from_log_metadata(meta);
  ASSERT_TRUE(t.ok()) << t.error().message;
  EXPECT_EQ(t->source, "target metadata");
  EXPECT_EQ(t->target.cols, 7);

  meta.erase("target");
  t = target_from_log_metadata(meta);
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.error().code, Errc::kNotFound);
  ASSERT_EQ(t.error().remedies.size(), 1u);
  EXPECT_EQ(t.error().remedies[0].option, "target");

  meta["target"] = "target_type: checkerboard\ntargetCols: -3\n";
  t = target_from_log_metadata(meta);
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.error().code, Errc::kCorrupt);
}

TEST(CameraResults, DetectionKeyFollowsTargetAndOptions) {
  const calib::DetectionOptions o;
  EXPECT_EQ(detection_key(board(), o), detection_key(board(), o));
  EXPECT_NE(detection_key(board(), o), detection_key(board(8), o));
  calib::DetectionOptions no_subpixel;
  no_subpixel.subpixel = false;
  EXPECT_NE(detection_key(board(), o), detection_key(board(), no_subpixel));
}

TEST(CameraResults, DetectionTextRoundTripsExactly) {
  calib::TargetObservation o;
  o.t_ns = 123;
  o.width = 376;
  o.height = 240;
  o.ids = {0, 5, 41};
  o.px = {{0.1, 1.0 / 3.0}, {375.49999999999994, 2e-300}, {-0.5, 239.123456789012345}};
  auto back = decode_detection(encode_detection(o), 123);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->t_ns, 123);
  EXPECT_EQ(back->width, 376);
  EXPECT_EQ(back->height, 240);
  EXPECT_EQ(back->ids, o.ids);
  ASSERT_EQ(back->px.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(back->px[i], o.px[i]);  // bit-exact

  EXPECT_EQ(decode_detection("{\"width\":1}", 5).error().code, Errc::kCorrupt);
  EXPECT_FALSE(decode_detection(R"({"width":1,"height":1,"ids":[1,2],"px":[1,2,3]})", 5).ok());
  EXPECT_FALSE(decode_detection("not json", 5).ok());
}

CameraCalibrationReport sample_report() {
  CameraCalibrationReport r;
  r.log_path = "x.imulog";
  r.stream.name = "cam0";
  r.target = board();
  r.target_source = "target metadata";
  r.frames = 10;
  r.frames_with_target = 9;
  auto& res = r.intrinsics;
  res.camera.distortion_model = DistortionModel::kRadtan;
  res.camera.width = 376;
  res.camera.height = 240;
  res.camera.intrinsics = {200.25, 199.75, 188.5, 117.125};
  res.camera.distortion_coeffs = {-0.28, 0.07, 0.0002, -0.0003};
  res.intrinsics_sigma = {0.1, 0.1, 0.05, 0.05};
  res.distortion_sigma = {0.001, 0.002, 1e-5, 1e-5};
  res.covariance_ok = true;
  res.covariance.setIdentity();
  res.views_total = 9;
  res.views_used = 8;
  res.views.resize(9);
  res.views[0].rejected_because = "too few points (3)";
  res.views[1].used = true;
  res.coverage = 0.75;
  res.coverage_cols = 10;
  res.coverage_rows = 6;
  res.coverage_counts.assign(60, 1);
  res.focal_well_determined = true;
  r.warnings = {"a warning"};
  return r;
}

TEST(CameraResults, YamlIsAKalibrCamchainWithImucalKeys) {
  const std::string text = camera_result_yaml(sample_report());
  const YAML::Node root = YAML::Load(text);
  ASSERT_TRUE(root["cam0"]);
  auto camera = camera_from_yaml(root["cam0"], "result");
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  EXPECT_EQ(camera->intrinsics, sample_report().intrinsics.camera.intrinsics);
  EXPECT_EQ(camera->distortion_coeffs, sample_report().intrinsics.camera.distortion_coeffs);
  EXPECT_EQ(camera->width, 376);
  EXPECT_EQ(root["cam0"]["rostopic"].as<std::string>(), "/cam0/image_raw");
  const YAML::Node q = root["cam0"]["imucal"];
  EXPECT_DOUBLE_EQ(q["intrinsics_sigma"][0].as<double>(), 0.1);
  EXPECT_DOUBLE_EQ(q["distortion_coeffs_sigma"][1].as<double>(), 0.002);
  EXPECT_EQ(q["views_used"].as<int>(), 8);
  EXPECT_EQ(q["views_rejected"].as<int>(), 1);
  EXPECT_TRUE(q["focal_well_determined"].as<bool>());
  EXPECT_EQ(q["target"]["targetCols"].as<int>(), 7);
  EXPECT_EQ(q["warnings"][0].as<std::string>(), "a warning");
}

// The intrinsics' covariance goes into the camera file, and calibrate camimu reads it back to
// propagate it; a file with sigmas only (an older imucal's) is read without one, and says why.
TEST(CameraResults, TheIntrinsicsCovarianceRoundTripsThroughTheCameraFile) {
  const auto dir = std::filesystem::temp_directory_path() / ("imucal_cov_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto write_text = [&](const std::string& name, const std::string& text) {
    const std::string path = (dir / name).string();
    std::ofstream(path) << text;
    return path;
  };
  // A pinhole and an omnidirectional camera: the file holds the model's own parameters in
  // Kalibr's order (omni: xi first), the reader puts them back in the solves' 10 x 10 layout.
  for (const bool omni : {false, true}) {
    SCOPED_TRACE(omni ? "omni-radtan" : "pinhole-radtan");
    auto r = sample_report();
    if (omni) {
      r.intrinsics.camera.projection = ProjectionModel::kOmni;
      r.intrinsics.camera.projection_params = {0.9, 0.0};
    }
    const std::vector<int> used = kalibr_parameter_indices(r.intrinsics.camera.kind());
    const auto n = static_cast<int>(used.size());
    ASSERT_EQ(n, omni ? 9 : 8);
    Eigen::MatrixXd A(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) A(i, j) = std::sin(1.0 + i + 3.0 * j);
    const Eigen::MatrixXd packed = A * A.transpose() * 1e-3;
    r.intrinsics.covariance.setZero();
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) r.intrinsics.covariance(used[i], used[j]) = packed(i, j);
    r.intrinsics.covariance(9, 9) = std::numeric_limits<double>::quiet_NaN();  // p2 not determined
    const std::string text = camera_result_yaml(r);
    const YAML::Node file = YAML::Load(text)["cam0"]["imucal"]["intrinsics_covariance"];
    ASSERT_EQ(static_cast<int>(file.size()), n);
    EXPECT_DOUBLE_EQ(file[0][0].as<double>(), r.intrinsics.covariance(used[0], used[0]));
    auto cams = read_camchain(write_text("full.yaml", text));
    ASSERT_TRUE(cams.ok()) << cams.error().message;
    const Eigen::MatrixXd& C = (*cams)[0].intrinsics_covariance;
    ASSERT_EQ(C.rows(), 10);
    EXPECT_TRUE(std::isnan(C(9, 9)));
    for (int i = 0; i < 9; ++i)
      for (int j = 0; j < 9; ++j) EXPECT_DOUBLE_EQ(C(i, j), r.intrinsics.covariance(i, j)) << i << " " << j;
    EXPECT_NE((*cams)[0].intrinsics_covariance_source.find("the covariance of"), std::string::npos);

    YAML::Node root = YAML::Load(text);
    root["cam0"]["imucal"].remove("intrinsics_covariance");
    cams = read_camchain(write_text("sigmas.yaml", YAML::Dump(root)));
    ASSERT_TRUE(cams.ok()) << cams.error().message;
    EXPECT_EQ((*cams)[0].intrinsics_covariance.size(), 0);
    EXPECT_NE((*cams)[0].intrinsics_covariance_source.find("not their covariance"), std::string::npos)
        << (*cams)[0].intrinsics_covariance_source;

    root["cam0"]["imucal"]["intrinsics_covariance"] = std::vector<double>{1.0, 2.0};
    cams = read_camchain(write_text("bad.yaml", YAML::Dump(root)));
    ASSERT_FALSE(cams.ok());
    const std::string expected = omni ? "9 rows of 9" : "8 rows of 8";
    EXPECT_NE(cams.error().message.find(expected), std::string::npos) << cams.error().message;
  }
  std::filesystem::remove_all(dir);
}

// The row a frame's stamp refers to comes from what the log says of its camera stream's stamps,
// unless the camera file or --stamp-row named it: then a disagreement is a warning.
TEST(CameraResults, TheStampedRowComesFromTheLogsTimestampSource) {
  CameraStreamInfo stream;
  stream.name = "cam0";
  stream.timestamp_source = "end-of-frame";
  Shutter shutter;  // first row, the default
  auto [note, warning] = stamp_row_from_stream(stream, false, "cam0", &shutter);
  EXPECT_EQ(shutter.stamp_row, Shutter::StampRow::kLast);
  EXPECT_NE(note.find("end-of-frame"), std::string::npos) << note;
  EXPECT_TRUE(warning.empty());

  Shutter named;
  named.stamp_row = Shutter::StampRow::kFirst;
  std::tie(note, warning) = stamp_row_from_stream(stream, true, "cam0", &named);
  EXPECT_EQ(named.stamp_row, Shutter::StampRow::kFirst);  // the file's is kept
  EXPECT_TRUE(note.empty());
  EXPECT_NE(warning.find("--stamp-row"), std::string::npos) << warning;

  stream.timestamp_source = "mid-exposure";  // where the backends put start-of-exposure stamps
  Shutter mid;
  mid.stamp_row = Shutter::StampRow::kLast;
  std::tie(note, warning) = stamp_row_from_stream(stream, false, "cam0", &mid);
  EXPECT_EQ(mid.stamp_row, Shutter::StampRow::kFirst);
  stream.timestamp_source = "dataset";  // says nothing: left as it is
  Shutter left;
  left.stamp_row = Shutter::StampRow::kMiddle;
  std::tie(note, warning) = stamp_row_from_stream(stream, false, "cam0", &left);
  EXPECT_EQ(left.stamp_row, Shutter::StampRow::kMiddle);
  EXPECT_TRUE(note.empty() && warning.empty());
}

TEST(CameraResults, JsonCarriesViewsAndUndeterminedSigmasAsNull) {
  auto r = sample_report();
  r.intrinsics.intrinsics_sigma[0] = std::numeric_limits<double>::infinity();
  const auto j = nlohmann::json::parse(camera_result_json(r));
  EXPECT_TRUE(j["intrinsics_sigma"][0].is_null());
  EXPECT_DOUBLE_EQ(j["intrinsics_sigma"][1].get<double>(), 0.1);
  EXPECT_EQ(j["views"].size(), 9u);
  EXPECT_EQ(j["views"][0]["rejected_because"], "too few points (3)");
  EXPECT_EQ(j["coverage_grid"]["counts"].size(), 60u);
  EXPECT_EQ(j["camera_stream"], "cam0");
}

}  // namespace
}  // namespace imucal::app
