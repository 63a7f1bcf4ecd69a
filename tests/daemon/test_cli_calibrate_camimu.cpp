// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate camimu: argument and output-file errors before any work, and the committed
// camera-IMU fixture calibrated against the simulator's truth (extrinsics, time offset, IMU
// intrinsics) within a few of the reported sigmas.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/imu_model.hpp"
#include "tests/support/test_helpers.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using nlohmann::json;
using test::read_file;
using test::run_cli;
using test::scratch_dir;
using test::source_path;
using test::vec3;

YAML::Node truth() { return YAML::LoadFile(source_path("fixtures/camimu.truth.yaml")); }

/// The truth's camera as the camchain YAML `calibrate camera` would write for it.
std::string camera_yaml(const std::string& dir) {
  YAML::Node cam = truth()["camera"]["cam0"];
  YAML::Node out;
  for (const char* key :
       {"camera_model", "intrinsics", "distortion_model", "distortion_coeffs", "resolution"})
    out["cam0"][key] = cam[key];
  out["cam0"]["rostopic"] = "/cam0/image_raw";
  const std::string path = dir + "/camera.yaml";
  YAML::Emitter e;
  e.SetDoublePrecision(17);
  e << out;
  std::ofstream(path) << e.c_str() << "\n";
  return path;
}

TEST(CliCalibrateCamimu, ArgumentErrorsComeBeforeAnyWork) {
  const std::string dir = scratch_dir();
  const std::string log = source_path("fixtures/camimu.imulog");
  const std::string cam = camera_yaml(dir);
  auto r = run_cli({"calibrate", "camimu", log, "--camera", dir + "/missing.yaml", "-o", dir + "/out"});
  EXPECT_EQ(r.exit_code, 3);  // a missing input, as in every command
  EXPECT_NE(r.err.find("missing.yaml"), std::string::npos) << r.err;

  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--fix", "S_a,Bg", "-o", dir + "/out"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("'Bg' is not a block"), std::string::npos) << r.err;

  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--model", "full", "-o", dir + "/out"});
  EXPECT_EQ(r.exit_code, 2);

  // A camera file that is not a camchain: exit 3, named.
  { std::ofstream(dir + "/notcam.yaml") << "foo: 1\n"; }
  r = run_cli({"calibrate", "camimu", log, "--camera", dir + "/notcam.yaml", "-o", dir + "/out"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("no cam0"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out"));

  // A result in the folder is not replaced without --force; the log is never an output.
  std::filesystem::create_directories(dir + "/out");
  { std::ofstream(dir + "/out/result.json") << "keep me\n"; }
  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "-o", dir + "/out"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("pass --force"), std::string::npos) << r.err;
  EXPECT_EQ(read_file(dir + "/out/result.json"), "keep me\n");
  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "-o", log});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("is a file"), std::string::npos) << r.err;
}

// One range per option (calib::CamImuLimits): the flags' checks and the solver's validate() agree,
// and the options are refused before the camera module loads (here it cannot: its folder does
// not exist, so an option error that came after the loading would be a module error).
TEST(CliCalibrateCamimu, OptionsAreRefusedWithTheSolversRangesBeforeTheModuleLoads) {
  const std::string dir = scratch_dir();
  const std::string log = source_path("fixtures/camimu.imulog");
  const std::string cam = camera_yaml(dir);
  const std::string out = dir + "/out";
  const test::ScopedModuleDir no_module(dir + "/no-module-here");
  // The flag's range is the solver's (0 or 0.005-0.5 s), named as such.
  auto r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--knot-spacing", "0.001", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--knot-spacing: '0.001' must be 0 or in 0.005 - 0.5"), std::string::npos) << r.err;
  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--knot-spacing", "0.1", "--bias-knot-spacing",
               "0.06", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("at least the knot spacing"), std::string::npos) << r.err;
  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--imu-max-rate", "10", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("'10' must be 0 or in 20 - 100000"), std::string::npos) << r.err;
  // The flags' own ranges are the solver's: a spline order it does not run is refused by name.
  for (const char* order : {"3", "7"}) {
    r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--spline-order", order, "-o", out});
    EXPECT_EQ(r.exit_code, 2) << order;
    EXPECT_NE(r.err.find("not in range 4 to 6"), std::string::npos) << r.err;
  }
  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--corner-sigma", "60", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_FALSE(std::filesystem::exists(out));
  // Valid options reach the module, whose absence is then the error.
  r = run_cli({"calibrate", "camimu", log, "--camera", cam, "--knot-spacing", "0.02", "-o", out});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("libimucal_camera.so"), std::string::npos) << r.err;
}

/// The estimate of a rotation against the truth as a small-angle vector (rad).
Eigen::Vector3d rotation_error(const Eigen::Matrix3d& est, const Eigen::Matrix3d& truth) {
  const Eigen::AngleAxisd aa(est * truth.transpose());
  return aa.angle() * aa.axis();
}

Eigen::Matrix4d matrix4(const YAML::Node& rows) {
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = rows[r][c].as<double>();
  return m;
}

/// |est - truth| <= k sigma for every entry, with the values in the message.
void expect_within(const char* what, const Eigen::Vector3d& err, const Eigen::Vector3d& sigma, double k) {
  for (int i = 0; i < 3; ++i) {
    EXPECT_GT(sigma[i], 0.0) << what << "[" << i << "]";
    EXPECT_LE(std::abs(err[i]), k * sigma[i])
        << what << "[" << i << "] error " << err[i] << " sigma " << sigma[i];
  }
}

/// The truth's IMU in the Krebs form on nominal SI (its body frame is the Krebs body frame).
KrebsImuModel truth_krebs() {
  const YAML::Node c = truth()["canonical"]["si"];
  CanonicalImuModel m;
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) {
      m.A_a(r, k) = c["A_a"][r][k].as<double>();
      m.A_g(r, k) = c["A_g"][r][k].as<double>();
      m.G(r, k) = c["G"][r][k].as<double>();
    }
  }
  auto k = krebs_from_canonical(m);
  EXPECT_TRUE(k.ok());
  EXPECT_LT((k->R_canonical_body - Eigen::Matrix3d::Identity()).norm(), 1e-9);
  return k->model;
}

TEST(CliCalibrateCamimu, FixtureWithinFewSigmasOfTruth) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  const std::string out = dir + "/out";
  // A thermal model of the same IMU (a warm-up recorded with the fixture's truth): the samples are
  // corrected to its reference temperature, which the results state; the extrinsics and the
  // intrinsics below do not depend on it.
  const std::string warm = dir + "/warm.imulog", thermal = dir + "/thermal.yaml";
  auto sim = run_cli({"sim", "still", "--seed", "5", "--truth", source_path("fixtures/camimu.truth.yaml"),
                      "--duration", "1200", "--imu-rate", "10", "--temp-profile", "warmup", "--temp-start",
                      "26", "--temp-final", "40", "-o", warm});
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  auto th = run_cli({"calibrate", "thermal", warm, "-o", thermal});
  ASSERT_EQ(th.exit_code, 0) << th.err;
  auto r = run_cli({"calibrate", "camimu", log, "--camera", camera_yaml(dir), "-o", out, "--threads", "2",
                    "--thermal", thermal});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("timeshift_cam_imu"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("the samples were corrected with the thermal model"), std::string::npos) << r.out;
  const double ref = YAML::LoadFile(thermal)["reference_temperature_c"].as<double>();
  EXPECT_DOUBLE_EQ(YAML::LoadFile(out + "/calibration.yaml")["reference_temperature_c"].as<double>(), ref);
  EXPECT_EQ(YAML::LoadFile(out + "/calibration.yaml")["thermal"]["gyro"].size(), 3u);
  EXPECT_NE(r.err.find("iteration"), std::string::npos) << r.err;  // the solver's progress
  const YAML::Node tcam = truth()["camera"]["cam0"];

  const YAML::Node cam0 = YAML::LoadFile(out + "/camchain-imucam.yaml")["cam0"];
  ASSERT_TRUE(cam0["T_cam_imu"]);
  const Eigen::Matrix4d T = matrix4(cam0["T_cam_imu"]);
  const Eigen::Matrix4d T_truth = matrix4(tcam["T_cam_imu"]);
  const json j = json::parse(read_file(out + "/result.json"));
  EXPECT_DOUBLE_EQ(j["reference_temperature_c"].get<double>(), ref);
  EXPECT_EQ(j["inputs"]["thermal"], thermal);
  const json& c = j["cameras"][0];
  constexpr double k = 4.0;
  expect_within("rotation", rotation_error(T.topLeftCorner<3, 3>(), T_truth.topLeftCorner<3, 3>()),
                vec3(c["rotation_sigma_rad"]), k);
  expect_within("translation", T.topRightCorner<3, 1>() - T_truth.topRightCorner<3, 1>(),
                vec3(c["translation_sigma_m"]), k);
  const double shift = cam0["timeshift_cam_imu"].as<double>();
  const double shift_sigma = c["timeshift_sigma_s"].get<double>();
  EXPECT_GT(shift_sigma, 0.0);
  EXPECT_LE(std::abs(shift - tcam["timeshift_cam_imu"].as<double>()), k * shift_sigma)
      << "timeshift " << shift << " truth " << tcam["timeshift_cam_imu"].as<double>() << " sigma "
      << shift_sigma;

  const KrebsImuModel t = truth_krebs();
  const json& est = j["imu"]["krebs"];
  const json& sig = j["imu"]["krebs_sigma"];
  expect_within("S_a", vec3(est["S_a"]) - t.S_a, vec3(sig["S_a"]), k);
  expect_within("M_a", vec3(est["M_a"]) - t.M_a, vec3(sig["M_a"]), k);
  expect_within("S_g", vec3(est["S_g"]) - t.S_g, vec3(sig["S_g"]), k);
  expect_within("M_g", vec3(est["M_g"]) - t.M_g, vec3(sig["M_g"]), k);
  Eigen::Matrix3d C;
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) C(row, col) = est["C_bg"][row][col].get<double>();
  expect_within("C_bg", rotation_error(C, t.C_bg), vec3(sig["C_bg_rad"]), k);
  for (int row = 0; row < 3; ++row) {
    Eigen::Vector3d e, s;
    for (int col = 0; col < 3; ++col) {
      e[col] = est["B_g"][row][col].get<double>() - t.B_g(row, col);
      s[col] = sig["B_g"][row][col].get<double>();
    }
    expect_within("B_g row", e, s, k);
  }
  // The self-check (on by default): the halves of this consistent recording agree, and say so.
  const json& sc = j["self_check"];
  EXPECT_EQ(sc["verdict"], "agree") << sc.dump(1);
  EXPECT_EQ(sc["parts"], 2);
  EXPECT_GE(sc["parameters"].size(), 7u);
  EXPECT_NE(r.out.find("self-check: the two halves agree within their sigmas"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("self-check: calibrating 2 parts of the recording apart"), std::string::npos) << r.err;
  EXPECT_GT(j["quality"]["covariance_clusters"].get<int>(), 10);
  // The canonical record is read by `calibrate check` and the static readers.
  EXPECT_EQ(YAML::LoadFile(out + "/calibration.yaml")["input_units"].as<std::string>(), "raw");
  EXPECT_EQ(YAML::LoadFile(out + "/imu-imucam.yaml")["imu0"]["model"].as<std::string>(),
            "scale-misalignment");
  // imu.yaml is the IMU file as Kalibr's --imu takes it (flat), for the next run.
  const YAML::Node imu = YAML::LoadFile(out + "/imu.yaml");
  EXPECT_FALSE(imu["imu0"]);
  for (const char* key : {"accelerometer_noise_density", "accelerometer_random_walk",
                          "gyroscope_noise_density", "gyroscope_random_walk", "rostopic", "update_rate"})
    EXPECT_TRUE(imu[key]) << key;
  EXPECT_EQ(imu["update_rate"].as<double>(), 200.0);  // the fixture's nominal rate
}

/// Every sigma in a JSON tree is null (not determined) or positive: never 0.
void expect_no_zero_sigma(const json& j, const std::string& where) {
  if (j.is_object()) {
    for (const auto& [key, value] : j.items()) {
      const bool sigma = key.find("sigma") != std::string::npos && key != "corner_sigma_px" &&
                         key.find("_sigma_given") == std::string::npos && key != "accel_sigma_mps2" &&
                         key != "gyro_sigma_radps";
      if (sigma) {
        const auto walk = [&](const json& v, const auto& self) -> void {
          if (v.is_array() || v.is_object()) {
            for (const auto& x : v) self(x, self);
          } else if (v.is_number()) {
            EXPECT_GT(v.get<double>(), 0.0) << where << "." << key << " holds a zero sigma";
          } else {
            EXPECT_TRUE(v.is_null() || v.is_string()) << where << "." << key;
          }
        };
        walk(value, walk);
      } else {
        expect_no_zero_sigma(value, where + "." + key);
      }
    }
  } else if (j.is_array()) {
    for (const auto& x : j) expect_no_zero_sigma(x, where);
  }
}

TEST(CliCalibrateCamimu, AWeaklyExcitedRecordingGivesSigmasNeverZerosAndNamesWhatThePriorSet) {
  const std::string dir = scratch_dir();
  const std::string log = dir + "/weak.imulog";
  auto sim = run_cli({"sim", "camimu", "--seed", "4", "--duration", "20", "--excitation", "0.2", "-o", log});
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  YAML::Node cam;
  cam["cam0"] = YAML::LoadFile(dir + "/weak.truth.yaml")["camera"]["cam0"];
  for (const char* key : {"T_cam_imu", "timeshift_cam_imu", "rate_hz", "exposure_ns", "timestamp"})
    cam["cam0"].remove(key);
  YAML::Emitter e;
  e.SetDoublePrecision(17);
  e << cam;
  std::ofstream(dir + "/camera.yaml") << e.c_str() << "\n";
  const std::string out = dir + "/out";
  auto r = run_cli({"calibrate", "camimu", log, "--camera", dir + "/camera.yaml", "--model", "extended", "-o",
                    out, "--threads", "2", "--self-check", "0"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find("self-check"), std::string::npos) << r.out;  // --self-check 0: none
  // The prior held what the recording could not tell, and the command says which.
  EXPECT_NE(r.err.find("set mostly by the prior"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("prior: MPU-6000 datasheet tolerances"), std::string::npos) << r.out;
  // No sigma on the screen is a zero: a number above 0, "not determined" or "fixed".
  for (const char* zero :
       {"+- [0.000000 ", " 0.000000]", "sigma [0.0000 ", " 0.0000] deg", " 0.00] mm", "+- 0.0000 ms"})
    EXPECT_EQ(r.out.find(zero), std::string::npos) << zero << " in\n" << r.out;
  const json j = json::parse(read_file(out + "/result.json"));
  expect_no_zero_sigma(j, "result.json");
  EXPECT_EQ(j["self_check"]["verdict"], "not run");
  ASSERT_FALSE(j["prior"].is_null());
  EXPECT_FALSE(j["prior"]["dominated"].empty());
  for (int i = 0; i < 3; ++i) EXPECT_LT(std::abs(j["imu"]["krebs"]["S_a"][i].get<double>() - 1.0), 0.1);
  // The camera's extrinsics are determined: finite sigmas.
  for (const char* key : {"rotation_sigma_rad", "translation_sigma_m"})
    for (const auto& v : j["cameras"][0][key]) EXPECT_TRUE(v.is_number()) << key;
  EXPECT_TRUE(j["cameras"][0]["timeshift_sigma_s"].is_number());

  // Stored on a rig's storage, the record keeps the sigmas, and none is a zero.
  const std::string rig = dir + "/rig.yaml";
  std::ofstream(rig) << "name: weak-rig\nimu:\n  bus: sim\nstorage:\n  backend: file\n  path: " << dir
                     << "/calibration.bin\n  size_bytes: 16384\n  offset_bytes: 0\n";
  auto w = run_cli({"store", "write", "--config", rig, out});
  ASSERT_EQ(w.exit_code, 0) << w.err;
  auto rd = run_cli({"store", "read", "--config", rig, "--json"});
  ASSERT_EQ(rd.exit_code, 0) << rd.err;
  const json stored = json::parse(rd.out);
  expect_no_zero_sigma(stored["calibration"], "stored");
  ASSERT_FALSE(stored["calibration"]["cameras"].empty());
  EXPECT_TRUE(stored["calibration"]["cameras"][0].contains("rotation_sigma_rad"));
}

}  // namespace
}  // namespace imucal
