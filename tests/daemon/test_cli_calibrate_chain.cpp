// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate camera with several cameras: a stereo pair rendered by the virtual rig
// (`imucal sim camimu --stereo`), its second camera stamping the same scene 10 ms later than the
// first under the same stamps; the joint solve must hold the truth (intrinsics, T_cn_cnm1,
// baseline, offset) within 3 of its sigmas, say that the cameras are not synchronized, and write
// a camchain that Kalibr's camera-IMU tool reads (its documented keys) and imucal's camimu reads.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/camera_model.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using ::testing::ContainsRegex;
using ::testing::HasSubstr;
using ::testing::Not;

Eigen::Matrix4d matrix_of(const YAML::Node& rows) {
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = rows[r][c].as<double>();
  return m;
}

/// A 16 s stereo recording at 15 Hz, cam1 stamped `offset_ms` late, made once per offset.
std::string stereo_log(const std::string& dir, const std::string& offset_ms) {
  const std::string log = dir + "/stereo.imulog";
  auto r = test::run_cli({"sim", "camimu", "--seed", "21", "--duration", "16", "--camera-rate", "15",
                          "--stereo", "--cam1-offset-ms", offset_ms, "-o", log});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("of 2 cameras"));
  return log;
}

TEST(CliCalibrateChain, AStereoPairTenMillisecondsApartIsCalibratedWithinItsSigmasAndFlagged) {
  const std::string dir = test::scratch_dir();
  const std::string log = stereo_log(dir, "10");
  const std::string out = dir + "/chain.yaml";
  auto r = test::run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("2 cameras in one solve"));
  EXPECT_THAT(r.err, HasSubstr("not synchronized"))
      << "the offset between identically stamped cameras is not said";
  // Every chain figure with two significant digits of its sigma: a sigma is never shown as 0.
  EXPECT_THAT(r.out, ContainsRegex("baseline [0-9.]+ mm \\+- [0-9.]*[1-9][0-9.]* mm")) << r.out;
  EXPECT_THAT(r.out, ContainsRegex("time offset: t_cam0 = t_cam1 [-+][0-9.]+ ms \\+- [0-9.]*[1-9][0-9.]* ms"))
      << r.out;

  const YAML::Node truth = YAML::LoadFile(dir + "/stereo.truth.yaml")["camera"];
  const YAML::Node chain = YAML::LoadFile(out);
  // Kalibr's camchain keys, as its camera-IMU tool reads them.
  for (const char* cam : {"cam0", "cam1"}) {
    for (const char* key : {"camera_model", "intrinsics", "distortion_model", "distortion_coeffs",
                            "resolution", "rostopic", "cam_overlaps"}) {
      EXPECT_TRUE(chain[cam][key]) << cam << " lacks " << key;
    }
  }
  EXPECT_EQ(chain["cam0"]["cam_overlaps"][0].as<int>(), 1);
  EXPECT_EQ(chain["cam1"]["cam_overlaps"][0].as<int>(), 0);
  EXPECT_FALSE(chain["cam0"]["T_cn_cnm1"]);
  ASSERT_TRUE(chain["cam1"]["T_cn_cnm1"]);

  for (const char* cam : {"cam0", "cam1"}) {
    auto est = camera_from_yaml(chain[cam], out);
    auto tru = camera_from_yaml(truth[cam], "truth");
    ASSERT_TRUE(est.ok() && tru.ok());
    for (int i = 0; i < 4; ++i) {
      const double s = chain[cam]["imucal"]["intrinsics_sigma"][i].as<double>();
      EXPECT_LE(std::abs(est->intrinsics[i] - tru->intrinsics[i]), 3.0 * s) << cam << " intrinsics " << i;
    }
  }
  const YAML::Node q = chain["cam1"]["imucal"];
  const Eigen::Matrix4d est = matrix_of(chain["cam1"]["T_cn_cnm1"]);
  const Eigen::Matrix4d tru = matrix_of(truth["cam1"]["T_cn_cnm1"]);
  for (int i = 0; i < 3; ++i) {
    const double s = q["T_cn_cnm1_translation_sigma_m"][i].as<double>();
    EXPECT_GT(s, 0.0);
    EXPECT_LE(std::abs(est(i, 3) - tru(i, 3)), 3.0 * s) << "translation " << i;
  }
  const Eigen::AngleAxisd d(
      Eigen::Matrix3d(est.topLeftCorner<3, 3>().transpose() * tru.topLeftCorner<3, 3>()));
  const Eigen::Vector3d rot = d.angle() * d.axis();
  for (int i = 0; i < 3; ++i)
    EXPECT_LE(std::abs(rot(i)), 3.0 * q["T_cn_cnm1_rotation_sigma_rad"][i].as<double>()) << "rotation " << i;
  const double baseline = tru.topRightCorner<3, 1>().norm();
  EXPECT_NEAR(q["baseline_m"].as<double>(), baseline, 3.0 * q["baseline_sigma_m"].as<double>());
  const double shift = truth["cam1"]["timeshift_cam_cam0"].as<double>();
  EXPECT_NEAR(shift, -0.010, 1e-12);
  EXPECT_NEAR(q["timeshift_cam_cam0"].as<double>(), shift, 3.0 * q["timeshift_cam_cam0_sigma"].as<double>());
  EXPECT_LT(q["timeshift_cam_cam0_sigma"].as<double>(), 0.002);

  auto j = test::run_cli({"calibrate", "camera", log, "-o", dir + "/again.yaml", "--json"});
  ASSERT_EQ(j.exit_code, 0) << j.err;
  const auto json = nlohmann::json::parse(j.out);
  ASSERT_EQ(json["cameras"].size(), 2u);
  EXPECT_EQ(json["cameras"][1]["cam_overlaps"][0].get<int>(), 0);
  EXPECT_EQ(json["cameras"][1]["linked_to"].get<std::string>(), "cam0");
  // The self-check compares both cameras' intrinsics, cam1's pose to cam0 and its time offset.
  // On these rendered frames the halves differ beyond the sigmas in cam0's k2 (4.2 combined
  // sigmas, chi-square 43.9 for 23): the renderer's corner bias, shared by the views of a half,
  // is more than the corners' independent noise; the sigmas are then scaled by the spread.
  const auto& sc = json["self_check"];
  EXPECT_EQ(sc["parameters"].size(), 8u + 8u + 7u);
  EXPECT_EQ(sc["parameters"].back()["name"], "cam1 time offset");
  ASSERT_TRUE(sc["verdict"] == "agree" || sc["verdict"] == "disagree") << sc.dump(1);
  if (sc["verdict"] == "disagree") {
    EXPECT_FALSE(sc["sigmas_scaled"].empty()) << sc.dump(1);
    EXPECT_THAT(json["warnings"].dump(), HasSubstr("self-check: the two halves disagree"));
  }
  // The camchain file says what the self-check found in comments: Kalibr takes every top-level
  // key for a camera, so the file keeps cam0 and cam1 only.
  const std::string again = test::read_file(dir + "/again.yaml");
  EXPECT_THAT(again, HasSubstr("\n# self-check: " + sc["summary"].get<std::string>() + "\n"));
  EXPECT_EQ(YAML::Load(again).size(), 2u);

  // The camera-IMU calibration with the chain: the pair's relative pose enters as a prior with the
  // chain's covariance, and the result's T_cn_cnm1 agrees with the chain's within its sigmas.
  const std::string camimu = dir + "/camimu";
  auto c = test::run_cli(
      {"calibrate", "camimu", "--self-check", "0", log, "--camera", out, "--threads", "2", "-o", camimu});
  ASSERT_EQ(c.exit_code, 0) << c.err;
  EXPECT_THAT(c.out + c.err, HasSubstr("enters from the camera chain"));
  const YAML::Node ci = YAML::LoadFile(camimu + "/camchain-imucam.yaml");
  const Eigen::Matrix4d rel =
      matrix_of(ci["cam1"]["T_cam_imu"]) * matrix_of(ci["cam0"]["T_cam_imu"]).inverse();
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(std::abs(rel(i, 3) - est(i, 3)), 3.0 * q["T_cn_cnm1_translation_sigma_m"][i].as<double>())
        << "camera-IMU translation " << i << " against the chain's";
  }
  // And each camera's time offset against the IMU differs by the chain's offset.
  const double dshift =
      ci["cam1"]["timeshift_cam_imu"].as<double>() - ci["cam0"]["timeshift_cam_imu"].as<double>();
  EXPECT_NEAR(dshift, q["timeshift_cam_cam0"].as<double>(), 0.001);

  // The report of the chain, from its JSON (with each camera's figures) and from its YAML (the
  // figures the file keeps, and a note on what it does not).
  if (!test::on_path("gnuplot")) GTEST_SKIP() << "gnuplot is not installed (Debian package gnuplot-nox)";
  std::ofstream(dir + "/chain.json") << j.out;
  auto rj = test::run_cli({"report", dir + "/chain.json", "-o", dir + "/chain-json.html"});
  ASSERT_EQ(rj.exit_code, 0) << rj.err;
  EXPECT_THAT(rj.out, HasSubstr("report (camera chain calibration)"));
  const std::string html = test::read_file(dir + "/chain-json.html");
  EXPECT_THAT(html, HasSubstr("<h2>Chain</h2>"));
  EXPECT_THAT(html, HasSubstr("Views shared by each pair of cameras"));
  for (const char* id :
       {"camera-coverage-cam0", "camera-view-rms-cam0", "camera-coverage-cam1", "camera-view-rms-cam1"})
    EXPECT_THAT(html, HasSubstr(std::string("data-plot=\"") + id + "\"")) << id;
  EXPECT_THAT(html, HasSubstr("<h2>Self-check</h2>"));
  // The baseline with its sigma, in mm, as the chain file has it (a table cell "110.021 ± 0.017").
  const double baseline_mm = 1e3 * json["cameras"][1]["baseline_m"].get<double>();
  EXPECT_THAT(html, ContainsRegex("<td>" + std::to_string(static_cast<int>(baseline_mm)) +
                                  "\\.[0-9]+ &plusmn; 0\\.[0-9]+</td>"))
      << baseline_mm;
  auto ry = test::run_cli({"report", out, "-o", dir + "/chain-yaml.html"});
  ASSERT_EQ(ry.exit_code, 0) << ry.err;
  EXPECT_THAT(ry.out, HasSubstr("drawn from the camchain YAML"));
  const std::string yhtml = test::read_file(dir + "/chain-yaml.html");
  EXPECT_THAT(yhtml, HasSubstr("<h2>Chain</h2>"));
  EXPECT_THAT(yhtml, HasSubstr("<h2>cam1 (stream cam1)</h2>"));
  EXPECT_THAT(yhtml, HasSubstr("the coverage and per-view figures need the JSON result"));
  EXPECT_THAT(yhtml, Not(HasSubstr("undetermined")));
}

TEST(CliCalibrateChain, ModelsAndCamerasAreCheckedBeforeAnyWork) {
  const std::string dir = test::scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  auto r = test::run_cli({"calibrate", "camera", "--self-check", "0", log, "--camera", "cam0", "--camera",
                          "cam0", "-o", dir + "/x.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_THAT(r.err, HasSubstr("given twice"));
  r = test::run_cli({"calibrate", "camera", "--self-check", "0", log, "--model", "pinhole-radtan", "--model",
                     "pinhole-equi", "-o", dir + "/y.yaml"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_THAT(r.err, HasSubstr("one per camera"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/y.yaml"));
}

}  // namespace
}  // namespace imucal
