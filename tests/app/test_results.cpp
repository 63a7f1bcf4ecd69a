// SPDX-License-Identifier: BSD-3-Clause
// The result schemas: documented keys of the static calibration and Allan outputs, and the
// whole-file writer.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <nlohmann/json.hpp>

#include "app/results/allan_results.hpp"
#include "app/results/output.hpp"
#include "app/results/static_results.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

calib::StaticCalibrationResult sample_result() {
  calib::StaticCalibrationResult r;
  r.model.accel.scale = Eigen::Vector3d(1.01, 0.99, 1.0);
  r.model.accel.bias = Eigen::Vector3d(0.1, -0.2, 0.3);
  r.gravity_mps2 = 9.80665;
  r.init_still_s = 50.0;
  r.threshold_multiplier = 6;
  r.distinct_attitudes = 30;
  calib::StaticIntervalInfo iv;
  iv.t0_ns = 1'000'000'000;
  iv.t1_ns = 3'000'000'000;
  iv.samples = 200;
  r.intervals = {iv};
  r.warnings = {"careful"};
  return r;
}

TEST(StaticResultWriters, YamlHasTheDocumentedKeys) {
  ImuStreamInfo info;
  info.units = ImuUnits::kRaw;
  const YAML::Node y = YAML::Load(static_result_yaml(sample_result(), info));
  for (const char* key :
       {"method", "stream", "input_units", "canonical", "convention", "accel", "gyro", "gravity",
        "init_still_s", "threshold_multiplier", "static_intervals", "distinct_attitudes", "quality"}) {
    EXPECT_TRUE(y[key]) << key;
  }
  EXPECT_EQ(y["input_units"].as<std::string>(), "raw");
  EXPECT_EQ(y["canonical"]["A_a"].size(), 3u);
  // The triads are written with the bias negated (corrected = T diag(s) (raw - bias)).
  EXPECT_DOUBLE_EQ(y["accel"]["bias"][1].as<double>(), 0.2);
  EXPECT_EQ(y["static_intervals"].as<int>(), 1);
  EXPECT_TRUE(y["quality"]["accel_gravity_magnitude_after"]);
  EXPECT_FALSE(y["quality"]["accel_gravity_magnitude_before"]);
}

TEST(StaticResultWriters, JsonHasTheDocumentedKeys) {
  const std::string text =
      static_result_json(sample_result(), ImuStreamInfo{}, "given", {{"software_version", "0.1.0"}});
  ASSERT_EQ(text.back(), '\n');
  const auto j = nlohmann::json::parse(text);
  for (const char* key : {"method",
                          "convention",
                          "input_units",
                          "stream",
                          "accel",
                          "gyro",
                          "canonical",
                          "gravity",
                          "gravity_source",
                          "init_still_s",
                          "init_still_source",
                          "threshold_multiplier",
                          "threshold",
                          "distinct_attitudes",
                          "gyro_transfers",
                          "static_intervals",
                          "quality",
                          "warnings",
                          "timings_s",
                          "log_software_version"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["gravity_source"], "given");
  EXPECT_TRUE(j["accel"].contains("tedaldi_angles"));
  EXPECT_TRUE(j["gyro"]["tedaldi_angles"].contains("gamma_yx"));
  EXPECT_EQ(j["static_intervals"][0]["t1_s"].get<double>(), 2.0);
  EXPECT_TRUE(j["quality"]["accel_gravity_magnitude"]["before"].is_null());
  EXPECT_EQ(j["warnings"][0], "careful");
}

TEST(AllanWriters, KalibrYamlAndJson) {
  std::vector<Eigen::Vector3d> accel, gyro;
  for (int i = 0; i < 4000; ++i) {
    const double n = ((i * 7919) % 101 - 50) * 1e-3;
    accel.emplace_back(n, -n, 9.81 + n);
    gyro.emplace_back(0.1 * n, 0.2 * n, -0.1 * n);
  }
  auto report = analyse_allan(accel, gyro, 100.0);
  ASSERT_TRUE(report.ok()) << report.error().message;
  report->log_path = "still.imulog";
  report->stream = "imu0";
  EXPECT_DOUBLE_EQ(report->duration_s, 40.0);
  const YAML::Node y = YAML::Load(allan_kalibr_yaml(*report));
  for (const char* key : {"accelerometer_noise_density", "accelerometer_random_walk",
                          "gyroscope_noise_density", "gyroscope_random_walk", "rostopic", "update_rate"}) {
    EXPECT_TRUE(y[key]) << key;
  }
  EXPECT_EQ(y["rostopic"].as<std::string>(), "/imu0");
  // Kalibr's file carries 8 significant digits.
  EXPECT_NEAR(y["accelerometer_noise_density"].as<double>(), report->accel_noise_density(),
              1e-7 * report->accel_noise_density());
  const auto j = nlohmann::json::parse(allan_json(*report));
  EXPECT_EQ(j["log"], "still.imulog");
  EXPECT_EQ(j["accelerometer"]["axes"].size(), 3u);
  EXPECT_TRUE(j["gyroscope"]["curve"].contains("adev_z"));
  EXPECT_EQ(j["random_walk_is_upper_bound"].get<bool>(), report->random_walk_is_upper_bound());
  EXPECT_DOUBLE_EQ(j["kalibr"]["gyroscope_random_walk"].get<double>(), report->gyro_random_walk());

  EXPECT_FALSE(
      analyse_allan({accel.begin(), accel.begin() + 4}, {gyro.begin(), gyro.begin() + 4}, 100.0).ok());
}

TEST(WriteTextFile, WritesWholeTextAndReportsFailure) {
  const std::string path = test::scratch_dir() + "/out.txt";
  ASSERT_TRUE(write_text_file(path, "first, longer\n").ok());
  // An existing file is replaced only when the policy allows it, and never when it is an input.
  auto kept = write_text_file(path, "second\n");
  ASSERT_FALSE(kept.ok());
  EXPECT_EQ(kept.error().code, Errc::kAlreadyExists);
  EXPECT_EQ(test::read_file(path), "first, longer\n");
  auto input = write_text_file(path, "second\n", {true, {path}});
  ASSERT_FALSE(input.ok());
  EXPECT_EQ(input.error().code, Errc::kInvalidArgument);
  ASSERT_TRUE(write_text_file(path, "second\n", {true, {}}).ok());
  EXPECT_EQ(test::read_file(path), "second\n");
  auto s = write_text_file(test::scratch_dir() + "/no/such/dir/out.txt", "x");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kIo);
}

}  // namespace
}  // namespace imucal::app
