// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>
#include <stdlib.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/imu_model.hpp"
#include "log/session_log.hpp"
#include "tests/calib/test_static_synth.hpp"
#include "tests/support/test_helpers.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;
using test::vec3;

/// Writes a synthetic static recording (raw counts centred at 32768) as a session log.
std::string write_log(const std::string& dir, const test::SynthConfig& cfg,
                      const std::string& name = "static.imulog") {
  const auto rec = test::make_static_recording(cfg);
  const std::string path = dir + "/" + name;
  auto w = log::SessionLogWriter::create(path);
  EXPECT_TRUE(w.ok()) << w.error().message;
  ImuStreamInfo info;
  info.units = cfg.raw_counts ? ImuUnits::kRaw : ImuUnits::kSi;
  info.rate_hz = cfg.rate_hz;
  if (cfg.raw_counts) {
    info.accel = test::counts_conversion(cfg.accel_lsb, cfg.accel_offset);
    info.gyro = test::counts_conversion(cfg.gyro_lsb, cfg.gyro_offset);
    info.accel_full_scale_g = 4;
    info.gyro_full_scale_dps = 500;
  }
  auto id = (*w)->add_imu_stream(info);
  EXPECT_TRUE(id.ok());
  EXPECT_TRUE((*w)->append_imu(*id, rec.samples).ok());
  EXPECT_TRUE((*w)->close().ok());
  return path;
}

TEST(CliCalibrateStatic, RawLogToYamlAndJson) {
  const std::string dir = test::scratch_dir();
  test::SynthConfig cfg;
  cfg.seed = 31;
  cfg.truth = test::random_truth(31);
  cfg.raw_counts = true;
  const std::string log = write_log(dir, cfg);
  const auto r = run_cli({"calibrate", "static", log, "--latitude", "47.37", "--height", "408", "-o",
                          dir + "/result.yaml", "--json", dir + "/result.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("distinct attitudes"), std::string::npos) << r.out;

  const auto j = nlohmann::json::parse(test::read_file(dir + "/result.json"));
  EXPECT_EQ(j["convention"], "corrected = misalignment * diag(scale) * (raw - bias)");
  EXPECT_EQ(j["input_units"], "raw");
  // Truth in counts, JSON convention: scale = K * lsb, bias = offset - b / lsb.
  const Eigen::Vector3d accel_scale = cfg.truth.accel.scale * cfg.accel_lsb;
  const Eigen::Vector3d accel_bias =
      Eigen::Vector3d::Constant(cfg.accel_offset) - cfg.truth.accel.bias / cfg.accel_lsb;
  const Eigen::Vector3d gyro_scale = cfg.truth.gyro.scale * cfg.gyro_lsb;
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(vec3(j["accel"]["scale"])[i], accel_scale[i], 4.5 * vec3(j["accel"]["sigma"]["scale"])[i]);
    EXPECT_NEAR(vec3(j["accel"]["bias"])[i], accel_bias[i], 4.5 * vec3(j["accel"]["sigma"]["bias"])[i]);
    EXPECT_NEAR(vec3(j["gyro"]["scale"])[i], gyro_scale[i], 4.5 * vec3(j["gyro"]["sigma"]["scale"])[i]);
    EXPECT_GT(vec3(j["accel"]["bias"])[i], 32000.0);  // raw counts centred at 32768
  }
  ASSERT_EQ(j["accel"]["misalignment"].size(), 3u);
  EXPECT_DOUBLE_EQ(j["accel"]["misalignment"][1][0].get<double>(), 0.0);  // upper triangular
  EXPECT_NEAR(j["gyro"]["misalignment"][1][0].get<double>(), cfg.truth.gyro.T(1, 0),
              4.5 * j["gyro"]["sigma"]["misalignment"][1][0].get<double>());
  EXPECT_NEAR(j["gravity"].get<double>(), 9.8072, 1e-3);  // WGS-84 at 47.37 deg, 408 m
  EXPECT_GE(j["threshold_multiplier"].get<int>(), 2);
  EXPECT_GE(j["static_intervals"].size(), 30u);
  EXPECT_FALSE(j["quality"]["accel_gravity_magnitude"]["before"].is_null());
  EXPECT_LT(j["quality"]["gyro_gravity_direction"]["after"]["mean_rad"].get<double>(),
            j["quality"]["gyro_gravity_direction"]["before"]["mean_rad"].get<double>());

  const YAML::Node y = YAML::LoadFile(dir + "/result.yaml");
  ASSERT_TRUE(y["canonical"]["A_a"]);
  EXPECT_EQ(y["canonical"]["A_a"].size(), 3u);
  EXPECT_NEAR(y["canonical"]["b_a"][0].as<double>(), accel_bias[0],
              5.0 * vec3(j["accel"]["sigma"]["bias"])[0]);
  // The synthetic gyro has no g-sensitivity: the estimate is not distinguishable from zero (its
  // Wald statistic below the chi-square 95 % point of 9 entries), so it is neglected and says so.
  ASSERT_TRUE(j["gsens"]["wald_statistic"].is_number()) << j["gsens"].dump();
  EXPECT_LT(j["gsens"]["wald_statistic"].get<double>(), 16.919);
  EXPECT_EQ(j["gsens"]["mode"], "off");
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(y["canonical"]["G"][r][c].as<double>(), 0.0);
  EXPECT_NE(r.out.find("not distinguishable from zero"), std::string::npos) << r.out;
}

TEST(CliCalibrateStatic, InitOptionsAndErrors) {
  const std::string dir = test::scratch_dir();
  test::SynthConfig cfg;
  cfg.seed = 32;
  cfg.truth = test::random_truth(32);
  const std::string log = write_log(dir, cfg);
  // SI log, init given per axis and for all axes.
  auto r = run_cli({"calibrate", "static", log, "--gravity", "9.80665", "--accel-scale-init", "1,1,1",
                    "--gyro-scale-init", "1", "--init-still", "45", "--json", dir + "/r.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/r.json"));
  EXPECT_EQ(j["init_still_source"], "given");
  // Malformed init value: usage error naming the option.
  r = run_cli({"calibrate", "static", log, "--accel-scale-init", "1,2"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--accel-scale-init"), std::string::npos) << r.err;
  // --gravity and --latitude exclude each other.
  r = run_cli({"calibrate", "static", log, "--gravity", "9.81", "--latitude", "10"});
  EXPECT_EQ(r.exit_code, 2);
}

TEST(CliCalibrateStatic, FewPosesGiveScalesAndBiasesAndTooFewExitWithDataError) {
  const std::string dir = test::scratch_dir();
  test::SynthConfig cfg;
  cfg.poses = 6;  // 7 attitudes with the still start, tilted, not on the six faces
  cfg.truth = test::random_truth(33);
  const std::string log = write_log(dir, cfg);
  auto r = run_cli({"calibrate", "static", log, "--json", dir + "/r.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/r.json"));
  EXPECT_EQ(j["accel_model"]["form"], "scale-bias");
  EXPECT_EQ(j["accel_fixed"].size(), 3u);
  EXPECT_TRUE(j["accel"]["sigma"]["misalignment"][0][1].is_null());
  EXPECT_NE(r.err.find("the accelerometer misalignment was not determined"), std::string::npos) << r.err;
  // The scales within their sigmas, which include the 1 % misalignment held at zero.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(j["accel"]["scale"][i].get<double>(), cfg.truth.accel.scale[i],
                4.5 * j["accel"]["sigma"]["scale"][i].get<double>())
        << i;
  }

  cfg.poses = 4;
  const std::string dir2 = dir + "/four";
  std::filesystem::create_directories(dir2);
  const std::string log2 = write_log(dir2, cfg);
  r = run_cli({"calibrate", "static", log2, "--json", dir2 + "/r.json"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.err.find("the full accelerometer model needs 9, scales and biases alone 6"), std::string::npos)
      << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir2 + "/r.json"));
}

TEST(CliCalibrateStatic, MissingFileIsAUsageError) {
  const auto r = run_cli({"calibrate", "static", "/nonexistent/x.imulog"});
  EXPECT_NE(r.exit_code, 0);
}

/// The committed fixture: the estimate agrees with the truth file within the reported sigma.
TEST(CliCalibrateStatic, FixtureRecoversTruth) {
  const std::string log = test::source_path("fixtures/static.imulog");
  const std::string truth_path = test::source_path("fixtures/static.truth.yaml");
  ASSERT_TRUE(std::filesystem::exists(log) && std::filesystem::exists(truth_path))
      << "fixtures/static.imulog or its truth file is missing: run scripts/make-fixtures.sh";
  const std::string dir = test::scratch_dir();
  const auto r = run_cli({"calibrate", "static", log, "--gravity", "9.80665", "--json", dir + "/r.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/r.json"));
  const YAML::Node t = YAML::LoadFile(truth_path)["tedaldi"]["counts"];
  ASSERT_TRUE(t) << "truth file has no tedaldi.counts section";
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(vec3(j["accel"]["scale"])[i], t["K_a"][i].as<double>(),
                4.0 * vec3(j["accel"]["sigma"]["scale"])[i])
        << "accel scale " << i;
    // The simulated bias wanders (random walk): compare with its mean over the recording.
    const YAML::Node si = YAML::LoadFile(truth_path)["tedaldi"]["si"];
    const double lsb = si["b_a"][i].as<double>() / t["b_a"][i].as<double>();
    const double bias_mean =
        YAML::LoadFile(truth_path)["recording"]["accel_bias_mean_mps2"][i].as<double>() / lsb;
    EXPECT_NEAR(vec3(j["accel"]["bias"])[i], bias_mean, 4.0 * vec3(j["accel"]["sigma"]["bias"])[i])
        << "accel bias " << i;
    EXPECT_NEAR(vec3(j["gyro"]["scale"])[i], t["K_g"][i].as<double>(),
                4.0 * vec3(j["gyro"]["sigma"]["scale"])[i])
        << "gyro scale " << i;
    for (int k = 0; k < 3; ++k) {
      if (i == k) continue;
      const double s_a = j["accel"]["sigma"]["misalignment"][i][k].get<double>();
      const double s_g = j["gyro"]["sigma"]["misalignment"][i][k].get<double>();
      if (s_a > 0) {
        EXPECT_NEAR(j["accel"]["misalignment"][i][k].get<double>(), t["T_a"][i][k].as<double>(), 4.0 * s_a)
            << "accel T " << i << k;
      }
      EXPECT_NEAR(j["gyro"]["misalignment"][i][k].get<double>(), t["T_g"][i][k].as<double>(), 4.0 * s_g)
          << "gyro T " << i << k;
    }
  }
}

TEST(CliCalibrate, MissingSolverModuleIsAnInstallationErrorThatNamesIt) {
  // The program loads Ceres only in the solver module; without it the command says which file
  // is missing and where it looked, and writes nothing.
  const std::string dir = test::scratch_dir();
  setenv("IMUCAL_MODULE_DIR", dir.c_str(), 1);
  const auto r = run_cli({"calibrate", "static", test::source_path("fixtures/static.imulog"), "--gravity",
                          "9.81", "-o", dir + "/r.yaml"});
  unsetenv("IMUCAL_MODULE_DIR");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("libimucal_solve.so is not in " + dir), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("IMUCAL_MODULE_DIR"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/r.yaml"));
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(CliCalibrateStatic, ResultFilesNeverReplaceTheLogAndNeedForceToReplaceAFile) {
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/static.imulog";
  std::filesystem::copy_file(test::source_path("fixtures/static.imulog"), log);
  const auto size = std::filesystem::file_size(log);
  // The log as its own output: refused, whatever --force says, and the log is untouched.
  for (const char* out : {"-o", "--json"}) {
    auto r = test::run_cli({"calibrate", "static", log, "--gravity", "9.81", out, log, "--force"});
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("is an input of this command"), std::string::npos) << r.err;
    EXPECT_EQ(std::filesystem::file_size(log), size);
  }
  auto r = test::run_cli({"allan", log, "--json", log, "--allow-motion"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(std::filesystem::file_size(log), size);
  // An existing result is kept without --force (refused before the work) and replaced with it.
  const std::string result = dir + "/result.yaml";
  std::ofstream(result) << "keep me\n";
  r = test::run_cli({"calibrate", "static", log, "--gravity", "9.81", "-o", result});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("exists; pass --force to replace it"), std::string::npos) << r.err;
  EXPECT_EQ(test::read_file(result), "keep me\n");
  r = test::run_cli({"calibrate", "static", log, "--gravity", "9.81", "-o", result, "--force"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(test::read_file(result).find("canonical:"), std::string::npos);
  // No temporary file is left beside it.
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 2) << "only the log and the result";
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(CliCalibrateStatic, GSensitivityModes) {
  const std::string dir = test::scratch_dir();
  const std::string log = test::source_path("fixtures/static.imulog");
  auto r = test::run_cli(
      {"calibrate", "static", log, "--gravity", "9.81", "--gsens", "off", "--json", dir + "/off.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(test::read_file(dir + "/off.json"));
  EXPECT_EQ(j["gsens"]["mode"], "off");
  EXPECT_EQ(j["canonical"]["G"][0][0].get<double>(), 0.0);
  std::ofstream(dir + "/g.yaml") << "G:\n  - [1.0e-4, 0, 0]\n  - [0, 2.0e-4, 0]\n  - [0, 0, 3.0e-4]\n";
  r = test::run_cli({"calibrate", "static", log, "--gravity", "9.81", "--gsens", "fix", dir + "/g.yaml",
                     "--json", dir + "/fix.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(test::read_file(dir + "/fix.json"));
  EXPECT_EQ(j["gsens"]["mode"], "fixed");
  EXPECT_DOUBLE_EQ(j["canonical"]["G"][1][1].get<double>(), 2.0e-4);
  r = test::run_cli({"calibrate", "static", log, "--gsens", "sometimes"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--gsens takes 'estimate', 'off' or 'fix FILE'"), std::string::npos) << r.err;
  std::ofstream(dir + "/bad.yaml") << "G: [1, 2, 3]\n";
  r = test::run_cli({"calibrate", "static", log, "--gsens", "fix", dir + "/bad.yaml"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("3 rows of 3"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace imucal
