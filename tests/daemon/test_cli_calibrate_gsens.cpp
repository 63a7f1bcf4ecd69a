// SPDX-License-Identifier: BSD-3-Clause
// `imucal calibrate gsens` on the committed six-face fixture (fixtures/gsens.imulog, its truth in
// fixtures/gsens.truth.yaml): G within the reported sigmas, the output accepted by
// `calibrate static --gsens fix`, refusals.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;

Eigen::Matrix3d yaml_matrix(const YAML::Node& n) {
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = n[r][c].as<double>();
  }
  return m;
}

Eigen::Matrix3d json_matrix(const nlohmann::json& j) {
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = j[r][c].get<double>();
  }
  return m;
}

struct GsensFixture {
  std::string log, truth;
};

GsensFixture gsens_fixture() {
  GsensFixture f{test::source_path("fixtures/gsens.imulog"), test::source_path("fixtures/gsens.truth.yaml")};
  EXPECT_TRUE(std::filesystem::exists(f.log) && std::filesystem::exists(f.truth))
      << "fixtures/gsens.imulog or its truth file is missing: run scripts/make-fixtures.sh";
  return f;
}

/// Every entry of G within 4 of its sigmas of the truth's canonical G.
void expect_within_sigmas(const nlohmann::json& j, const Eigen::Matrix3d& truth) {
  const Eigen::Matrix3d G = json_matrix(j["G"]), sigma = json_matrix(j["G_sigma"]);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_GT(sigma(r, c), 0.0);
      EXPECT_LT(sigma(r, c), 5e-5) << "G sigma " << r << c;
      EXPECT_NEAR(G(r, c), truth(r, c), 4.0 * sigma(r, c)) << "G " << r << c;
    }
  }
}

TEST(CliCalibrateGsens, FixtureRecoversTruthWithinSigmas) {
  const GsensFixture f = gsens_fixture();
  const std::string dir = test::scratch_dir();
  const auto r = run_cli({"calibrate", "gsens", f.log, "--gravity", "9.80665", "-o", dir + "/g.yaml",
                          "--json", dir + "/g.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("6 holds (+z"), std::string::npos) << r.out;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/g.json"));
  const YAML::Node truth = YAML::LoadFile(f.truth);
  expect_within_sigmas(j, yaml_matrix(truth["canonical"]["counts"]["G"]));
  // Faces in the script's order (docs/simulator.md): +z, -y, -z, +y, +x, -x, 30 s each.
  ASSERT_EQ(j["holds"].size(), 6u);
  const char* faces[6] = {"+z", "-y", "-z", "+y", "+x", "-x"};
  for (int k = 0; k < 6; ++k) {
    EXPECT_EQ(j["holds"][k]["face"], faces[k]);
    EXPECT_GT(j["holds"][k]["samples"].get<int>(), 2500);
  }
  EXPECT_EQ(j["input_units"], "raw");
  EXPECT_EQ(j["models"]["source"], "nominal conversion");
  EXPECT_EQ(j["degrees_of_freedom"]["dof"], 6);
  EXPECT_EQ(j["covariance"]["matrix"].size(), 12u);
  // The bias in counts, against the simulated bias's mean over the recording.
  const double lsb =
      truth["canonical"]["si"]["b_g"][0].as<double>() / truth["canonical"]["counts"]["b_g"][0].as<double>();
  for (int i = 0; i < 3; ++i) {
    const double mean = truth["recording"]["gyro_bias_mean_radps"][i].as<double>() / lsb;
    EXPECT_NEAR(j["b_g"][i].get<double>(), mean, 4.0 * j["b_g_sigma"][i].get<double>()) << "b_g " << i;
  }
  // The YAML carries what `calibrate static --gsens fix` reads: a top-level G.
  const YAML::Node y = YAML::LoadFile(dir + "/g.yaml");
  EXPECT_TRUE(yaml_matrix(y["G"]).isApprox(json_matrix(j["G"]), 1e-9));
  EXPECT_TRUE(y["G_sigma"] && y["b_g"] && y["holds"] && y["residual_rms_radps"]);
}

TEST(CliCalibrateGsens, StaticCalibrationAcceptsTheResult) {
  const GsensFixture f = gsens_fixture();
  const std::string dir = test::scratch_dir();
  auto r = run_cli({"calibrate", "gsens", f.log, "--gravity", "9.80665", "-o", dir + "/g.yaml"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run_cli({"calibrate", "static", test::source_path("fixtures/static.imulog"), "--gravity", "9.80665",
               "--gsens", "fix", dir + "/g.yaml", "--json", dir + "/static.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(test::read_file(dir + "/static.json"));
  EXPECT_EQ(j["gsens"]["mode"], "fixed");
  const YAML::Node y = YAML::LoadFile(dir + "/g.yaml");
  EXPECT_TRUE(json_matrix(j["canonical"]["G"]).isApprox(yaml_matrix(y["G"]), 1e-9));
}

TEST(CliCalibrateGsens, PriorIntrinsicsNarrowTheSigmas) {
  // The truth's canonical model as a prior calibration (the schema of calibrate static -o): no
  // share of the nominal scales' uncertainty is left in the sigmas, and G still agrees.
  const GsensFixture f = gsens_fixture();
  const std::string dir = test::scratch_dir();
  const YAML::Node c = YAML::LoadFile(f.truth)["canonical"]["counts"];
  {
    YAML::Emitter e;
    e << YAML::BeginMap << YAML::Key << "input_units" << YAML::Value << "raw" << YAML::Key << "canonical"
      << YAML::Value << c << YAML::EndMap;
    std::ofstream(dir + "/prior.yaml") << e.c_str() << "\n";
  }
  auto r = run_cli({"calibrate", "gsens", f.log, "--gravity", "9.80665", "--json", dir + "/nominal.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run_cli({"calibrate", "gsens", f.log, "--gravity", "9.80665", "--imu-intrinsics", dir + "/prior.yaml",
               "--json", dir + "/prior.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto nominal = nlohmann::json::parse(test::read_file(dir + "/nominal.json"));
  const auto prior = nlohmann::json::parse(test::read_file(dir + "/prior.json"));
  EXPECT_EQ(prior["models"]["source"], dir + "/prior.yaml");
  EXPECT_EQ(prior["models"]["gyro_rel_sigma"], 0.0);
  EXPECT_LT(json_matrix(prior["G_sigma"]).sum(), json_matrix(nominal["G_sigma"]).sum());
  expect_within_sigmas(prior, yaml_matrix(c["G"]));

  // A calibration of SI input for this raw stream is refused.
  std::ofstream(dir + "/si.yaml") << "input_units: si\ncanonical:\n"
                                  << "  A_a: [[1,0,0],[0,1,0],[0,0,1]]\n  b_a: [0,0,0]\n"
                                  << "  A_g: [[1,0,0],[0,1,0],[0,0,1]]\n  b_g: [0,0,0]\n"
                                  << "  G: [[0,0,0],[0,0,0],[0,0,0]]\n";
  r = run_cli({"calibrate", "gsens", f.log, "--imu-intrinsics", dir + "/si.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is for si input, but stream imu0 is raw"), std::string::npos) << r.err;
}

TEST(CliCalibrateGsens, RefusesALogWithoutSixFaceHoldsAndKeepsOutputs) {
  const std::string dir = test::scratch_dir();
  // The static fixture holds 40 attitudes for 1-4 s each, too short: only its still start counts.
  auto r = run_cli({"calibrate", "gsens", test::source_path("fixtures/static.imulog"), "--gravity", "9.80665",
                    "-o", dir + "/g.yaml"});
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_NE(r.err.find("none was found with +x, -x, +y, -y, -z up (found: +z 4"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("hold the rig still for about 30 s with each of the six faces up"), std::string::npos)
      << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/g.yaml"));

  const GsensFixture f = gsens_fixture();
  std::ofstream(dir + "/exists.yaml") << "x: 1\n";
  r = run_cli({"calibrate", "gsens", f.log, "-o", dir + "/exists.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--force"), std::string::npos) << r.err;
  r = run_cli({"calibrate", "gsens", f.log, "-o", f.log, "--force"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
}

}  // namespace
}  // namespace imucal
