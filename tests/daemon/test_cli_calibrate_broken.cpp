// SPDX-License-Identifier: BSD-3-Clause
// `imucal calibrate static` on the damaged fixture logs (fixtures/README.md). The gap and
// saturation fixtures keep enough usable poses (40 recorded): the result must agree with the truth
// within its reported sigma and say what was excluded. The truncated log is refused unless
// --allow-damaged, and then gives a correct result with a warning or a clear data error
// (docs/cli.md). Never a silently degraded result.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/test_helpers.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;
using test::vec3;

struct BrokenFixture {
  std::string log, truth;
};

/// The committed fixture pair; empty paths when it is missing (the caller fails: fixtures are
/// part of the repository, scripts/make-fixtures.sh regenerates them).
BrokenFixture broken_fixture(const std::string& name) {
  BrokenFixture f{test::source_path("fixtures/" + name + ".imulog"),
                  test::source_path("fixtures/" + name + ".truth.yaml")};
  if (!std::filesystem::exists(f.log) || !std::filesystem::exists(f.truth)) return {};
  return f;
}

/// Scale, bias (against the mean bias over the recording) and misalignment agree with the truth
/// within k reported sigmas.
void expect_matches_truth(const nlohmann::json& j, const std::string& truth_path, double k) {
  const YAML::Node truth = YAML::LoadFile(truth_path);
  const YAML::Node t = truth["tedaldi"]["counts"];
  const YAML::Node si = truth["tedaldi"]["si"];
  ASSERT_TRUE(t && si) << "truth file has no tedaldi section";
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(vec3(j["accel"]["scale"])[i], t["K_a"][i].as<double>(),
                k * vec3(j["accel"]["sigma"]["scale"])[i])
        << "accel scale " << i;
    const double lsb = si["b_a"][i].as<double>() / t["b_a"][i].as<double>();
    const double bias_mean = truth["recording"]["accel_bias_mean_mps2"][i].as<double>() / lsb;
    EXPECT_NEAR(vec3(j["accel"]["bias"])[i], bias_mean, k * vec3(j["accel"]["sigma"]["bias"])[i])
        << "accel bias " << i;
    EXPECT_NEAR(vec3(j["gyro"]["scale"])[i], t["K_g"][i].as<double>(),
                k * vec3(j["gyro"]["sigma"]["scale"])[i])
        << "gyro scale " << i;
    for (int c = 0; c < 3; ++c) {
      if (i == c) continue;
      const double s_a = j["accel"]["sigma"]["misalignment"][i][c].get<double>();
      const double s_g = j["gyro"]["sigma"]["misalignment"][i][c].get<double>();
      if (s_a > 0) {
        EXPECT_NEAR(j["accel"]["misalignment"][i][c].get<double>(), t["T_a"][i][c].as<double>(), k * s_a)
            << "accel T " << i << c;
      }
      EXPECT_NEAR(j["gyro"]["misalignment"][i][c].get<double>(), t["T_g"][i][c].as<double>(), k * s_g)
          << "gyro T " << i << c;
    }
  }
}

bool any_warning_contains(const nlohmann::json& j, const std::string& what) {
  for (const auto& w : j["warnings"]) {
    if (w.get<std::string>().find(what) != std::string::npos) return true;
  }
  return false;
}

/// Samples missing in the middle: the result holds, the gaps are reported, and no motion that
/// contains a gap is integrated.
TEST(CliCalibrateBroken, GapIsWarnedAndNotIntegratedAcross) {
  const BrokenFixture f = broken_fixture("broken-gap");
  ASSERT_FALSE(f.log.empty()) << "fixtures/broken-gap.imulog is missing: run scripts/make-fixtures.sh";
  const std::string dir = test::scratch_dir();
  const auto r = run_cli({"calibrate", "static", f.log, "--gravity", "9.80665", "--json", dir + "/r.json"});
  ASSERT_EQ(r.exit_code, 0) << "the gaps leave 30+ usable poses; calibration must succeed: " << r.err;
  EXPECT_NE(r.err.find("gap"), std::string::npos) << "the gap must be warned about on stderr: " << r.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/r.json"));
  EXPECT_TRUE(any_warning_contains(j, "gap")) << j["warnings"].dump();
  // The 2.5 s drop falls in a motion or a hold; either way one motion at least cannot be used.
  EXPECT_TRUE(any_warning_contains(j, "not used for the gyroscope")) << j["warnings"].dump();
  expect_matches_truth(j, f.truth, 4.5);
}

/// Motion beyond the full-scale ranges: the flagged samples are excluded and reported.
TEST(CliCalibrateBroken, SaturatedSamplesAreExcludedAndWarned) {
  const BrokenFixture f = broken_fixture("broken-saturated");
  ASSERT_FALSE(f.log.empty()) << "fixtures/broken-saturated.imulog is missing: run scripts/make-fixtures.sh";
  const std::string dir = test::scratch_dir();
  const auto r = run_cli({"calibrate", "static", f.log, "--gravity", "9.80665", "--json", dir + "/r.json"});
  ASSERT_EQ(r.exit_code, 0) << "saturation spoils some motions but leaves enough poses: " << r.err;
  EXPECT_NE(r.err.find("saturated"), std::string::npos) << r.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/r.json"));
  EXPECT_TRUE(any_warning_contains(j, "saturated")) << j["warnings"].dump();
  expect_matches_truth(j, f.truth, 4.5);
}

/// A log cut short: refused as damaged by default (exit 3, naming the way out); with
/// --allow-damaged the readable part is used, and it either calibrates correctly with a warning
/// or fails as unsuitable data (exit 4).
TEST(CliCalibrateBroken, TruncatedIsRefusedUnlessAllowed) {
  const BrokenFixture f = broken_fixture("broken-truncated");
  ASSERT_FALSE(f.log.empty()) << "fixtures/broken-truncated.imulog is missing: run scripts/make-fixtures.sh";
  const std::string dir = test::scratch_dir();
  // Work on a copy: opening a damaged log must not be allowed to touch the fixture.
  const std::string log = dir + "/truncated.imulog";
  std::filesystem::copy_file(f.log, log);
  auto r = run_cli({"calibrate", "static", log, "--gravity", "9.80665", "--json", dir + "/r.json"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("damaged"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--allow-damaged"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/r.json"));

  r = run_cli(
      {"calibrate", "static", log, "--gravity", "9.80665", "--allow-damaged", "--json", dir + "/r.json"});
  if (r.exit_code == 0) {
    const auto j = nlohmann::json::parse(test::read_file(dir + "/r.json"));
    EXPECT_TRUE(any_warning_contains(j, "damaged")) << j["warnings"].dump();
    expect_matches_truth(j, f.truth, 4.5);
  } else {
    EXPECT_EQ(r.exit_code, 4) << r.err;
    EXPECT_NE(r.err.find("imucal:"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir + "/r.json"));
  }
}

}  // namespace
}  // namespace imucal
