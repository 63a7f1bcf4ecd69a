// SPDX-License-Identifier: BSD-3-Clause
// `imucal calibrate static` on six-face recordings of the virtual rig (`imucal sim gsens`): what
// the holds determine is fitted within its sigmas of the truth, what they do not is named and has
// no sigma, and a recording with too few faces is refused naming the faces it lacks.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using nlohmann::json;
using test::run_cli;

/// A `sim gsens` recording and its truth, written once per set of options.
struct SixFace {
  std::string dir, log, truth, json_path;
  double duration_s = 0.0;
};

SixFace record(const std::string& name, const std::vector<std::string>& extra) {
  const std::string dir = test::scratch_dir();
  SixFace f{dir, dir + "/" + name + ".imulog", dir + "/" + name + ".truth.yaml", dir + "/" + name + ".json"};
  std::vector<std::string> args = {"sim", "gsens", "--seed", "3", "-o", f.log};
  args.insert(args.end(), extra.begin(), extra.end());
  const auto r = run_cli(args);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::size_t at = r.out.find(" s at ");
  const std::size_t from = r.out.rfind('(', at);
  if (at != std::string::npos && from != std::string::npos)
    f.duration_s = std::stod(r.out.substr(from + 1, at - from - 1));
  return f;
}

struct Check {
  int compared = 0;
  std::vector<std::string> held;  // parameters whose sigma is null
};

/// Every parameter of `triad` ("accel" or "gyro") with a sigma lies within k sigmas of the
/// truth's Tedaldi form (counts); biases also allow for their random walk over half the
/// recording (the estimate is a mean over the session, the truth the turn-on value).
/// `only_gyro_shape`: scales and misalignments only.
Check expect_triad_within(const json& j, const YAML::Node& truth, const std::string& triad, double k,
                          double duration_s, bool only_shape = false) {
  Check c;
  const YAML::Node t = truth["tedaldi"]["counts"];
  const bool accel = triad == "accel";
  const YAML::Node T = t[accel ? "T_a" : "T_g"], K = t[accel ? "K_a" : "K_g"], b = t[accel ? "b_a" : "b_g"];
  const json& e = j[triad];
  const auto check = [&](const std::string& what, const json& est, const json& sigma, double tru,
                         double extra) {
    if (sigma.is_null()) {
      c.held.push_back(what);
      return;
    }
    const double s = std::hypot(sigma.get<double>(), extra);
    EXPECT_GT(s, 0.0) << triad << " " << what;
    EXPECT_NEAR(est.get<double>(), tru, k * s) << triad << " " << what;
    ++c.compared;
  };
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) {
      if (r == col || (accel && r > col)) continue;
      check("T" + std::to_string(r) + std::to_string(col), e["misalignment"][r][col],
            e["sigma"]["misalignment"][r][col], T[r][col].as<double>(), 0.0);
    }
  }
  for (int i = 0; i < 3; ++i)
    check("scale " + std::to_string(i), e["scale"][i], e["sigma"]["scale"][i], K[i].as<double>(), 0.0);
  if (only_shape) return c;
  const double q = truth["imu"][triad]["bias_random_walk"].as<double>();
  for (int i = 0; i < 3; ++i) {
    const double walk = q * std::sqrt(duration_s / 2.0) / K[i].as<double>();
    check("bias " + std::to_string(i), e["bias"][i], e["sigma"]["bias"][i], -b[i].as<double>(), walk);
  }
  return c;
}

TEST(CliCalibrateFaces, SimGsensCalibratesWhatSixFacesDetermineAndNamesTheRest) {
  const SixFace f = record("gsens", {});
  ASSERT_GT(f.duration_s, 100.0);
  const auto r = run_cli({"calibrate", "static", f.log, "--gravity", "9.80665", "--json", f.json_path});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(test::read_file(f.json_path));
  const YAML::Node truth = YAML::LoadFile(f.truth);
  EXPECT_EQ(j["accel_model"]["form"], "faces") << j["accel_model"].dump();
  EXPECT_TRUE(j["accel_fixed"].empty());
  // The accelerometer: all nine parameters from the six faces.
  const Check a = expect_triad_within(j, truth, "accel", 3.0, f.duration_s);
  EXPECT_EQ(a.compared, 9);
  // The gyroscope: five 90-180 deg turns determine some of it; the rest is held and named, with
  // no sigma, in the JSON, on stdout and in a warning.
  const Check g = expect_triad_within(j, truth, "gyro", 3.0, f.duration_s);
  EXPECT_GE(g.compared, 5);
  ASSERT_FALSE(g.held.empty());
  EXPECT_EQ(j["gyro_fixed"].size(), g.held.size()) << j["gyro_fixed"].dump();
  EXPECT_NE(r.out.find("not determined, held at nominal: accelerometer none; gyroscope misalignment"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.err.find("do not determine the gyroscope's"), std::string::npos) << r.err;
  // The g-sensitivity, from the six holds.
  EXPECT_EQ(j["gsens"]["mode"], "estimate");
  const YAML::Node G = truth["tedaldi"]["canonical_si"]["G"];
  for (int i = 0; i < 3; ++i) {
    for (int c = 0; c < 3; ++c) {
      const double s = j["gsens"]["G_sigma"][i][c].get<double>();
      EXPECT_GT(s, 0.0);
      EXPECT_NEAR(j["gsens"]["G"][i][c].get<double>(), G[i][c].as<double>(), 3.0 * s) << "G " << i << c;
    }
  }
}

TEST(CliCalibrateFaces, RevisitedFacesCalibrateTheWholeGyroscope) {
  const SixFace f = record("revisits", {"--revisits", "30"});
  const auto r = run_cli({"calibrate", "static", f.log, "--gravity", "9.80665", "--json", f.json_path});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(test::read_file(f.json_path));
  const YAML::Node truth = YAML::LoadFile(f.truth);
  EXPECT_EQ(j["accel_model"]["form"], "faces");
  EXPECT_TRUE(j["gyro_fixed"].empty()) << j["gyro_fixed"].dump();
  const Check g = expect_triad_within(j, truth, "gyro", 3.0, f.duration_s, true);
  EXPECT_EQ(g.compared, 9);
  expect_triad_within(j, truth, "accel", 3.0, f.duration_s);

  // Scales and biases alone: the misalignment is held at zero, named, without sigma, and the
  // scales stay within their (widened) sigmas although the true misalignment is 1-3 %.
  const std::string sb = f.dir + "/sb.json";
  const auto r2 = run_cli(
      {"calibrate", "static", f.log, "--gravity", "9.80665", "--accel-model", "scale-bias", "--json", sb});
  ASSERT_EQ(r2.exit_code, 0) << r2.err;
  const json k = json::parse(test::read_file(sb));
  EXPECT_EQ(k["accel_model"]["form"], "scale-bias");
  EXPECT_EQ(k["accel_fixed"].size(), 3u);
  const Check a = expect_triad_within(k, truth, "accel", 3.0, f.duration_s);
  EXPECT_EQ(a.held.size(), 3u);
  EXPECT_EQ(a.compared, 6);
}

TEST(CliCalibrateFaces, ThreeFacesAreRefusedNamingTheFacesMissing) {
  const SixFace f = record("three", {"--faces", "+z,-y,+x"});
  const auto r = run_cli({"calibrate", "static", f.log, "--gravity", "9.80665"});
  EXPECT_EQ(r.exit_code, 4) << r.err;
  for (const char* face : {"-X up (resting on its +X face)", "+Y up (resting on its -Y face)",
                           "-Z up (resting on its +Z face)"}) {
    EXPECT_NE(r.err.find(face), std::string::npos) << face << "\n" << r.err;
  }
  for (const char* held : {"+Z up", "-Y up", "+X up"}) EXPECT_EQ(r.err.find(held), std::string::npos) << held;
  EXPECT_NE(r.err.find("scales and biases alone 6"), std::string::npos) << r.err;
  // Forced to the known-orientation form, the same recording says what that form lacks.
  const auto r2 = run_cli({"calibrate", "static", f.log, "--gravity", "9.80665", "--accel-model", "faces"});
  EXPECT_EQ(r2.exit_code, 4);
  EXPECT_NE(r2.err.find("needs a pose on each of the six faces"), std::string::npos) << r2.err;
}

}  // namespace
}  // namespace imucal
