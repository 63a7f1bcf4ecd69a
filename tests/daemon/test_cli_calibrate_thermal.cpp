// SPDX-License-Identifier: BSD-3-Clause
// `imucal calibrate thermal` on a still warm-up recorded by `imucal sim still --temp-profile`:
// the YAML's coefficients against the seed's truth within their sigmas, the reference and range,
// and the refusal of a span too small. Then `calibrate static --thermal` on a static protocol
// recorded while the same IMU warms: its biases are those at the model's reference temperature,
// and the record `store write` keeps carries the model.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "sim/imu_error_model.hpp"
#include "sim/truth.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;

test::CommandResult sim_warm_up(const std::string& log, const std::string& start,
                                const std::string& final_c) {
  return run_cli({"sim",          "still", "--seed",         "7",      "--duration",    "2400",
                  "--imu-rate",   "20",    "--temp-profile", "warmup", "--temp-start",  start,
                  "--temp-final", final_c, "--temp-tau",     "600",    "--temp-coeffs", "2",
                  "-o",           log});
}

TEST(CliCalibrateThermal, WarmUpRecoversTheSeedsCoefficientsWithinSigmas) {
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/warmup.imulog", out = dir + "/thermal.yaml";
  auto sim = sim_warm_up(log, "20", "60");
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  auto r = run_cli({"calibrate", "thermal", log, "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("gyro x: order"), std::string::npos) << r.out;

  const YAML::Node y = YAML::LoadFile(out);
  const double ref = y["reference_temperature_c"].as<double>();
  const double lo = y["valid_range_c"][0].as<double>(), hi = y["valid_range_c"][1].as<double>();
  EXPECT_NEAR(lo, 20.0, 1.0);
  EXPECT_NEAR(hi, 59.0, 1.0);
  EXPECT_NEAR(ref, 0.5 * (lo + hi), 1e-9);
  EXPECT_EQ(y["gyro"]["unit"].as<std::string>(), "rad/s");
  EXPECT_EQ(y["accel"]["unit"].as<std::string>(), "m/s^2");

  sim::ImuModelParams truth = sim::ImuModelParams::draw(7);
  truth.draw_temperature_coefficients(7, 2);
  truth.temp_start_c = 20.0;
  for (const char* sensor : {"gyro", "accel"}) {
    for (int a = 0; a < 3; ++a) {
      const YAML::Node axis = y[sensor][std::string(1, "xyz"[a])];
      ASSERT_TRUE(axis["determined"].as<bool>()) << sensor << a;
      const int order = axis["order"].as<int>();
      EXPECT_GE(order, 1) << sensor << a;
      EXPECT_EQ(axis["coefficients"].size(), static_cast<std::size_t>(order + 1));
      EXPECT_EQ(axis["covariance"].size(), static_cast<std::size_t>(order + 1));
      const Eigen::Vector4d c =
          std::string(sensor) == "gyro" ? truth.gyro_bias_temp_poly(a) : truth.accel_bias_temp_poly(a);
      // The truth's linear term about the fit's reference: c1 + 2 c2 (ref - 20).
      const double c1 = c[1] + 2.0 * c[2] * (ref - truth.temp_ref_c());
      if (order >= 2) {
        EXPECT_NEAR(axis["coefficients"][1].as<double>(), c1, 4.0 * axis["sigmas"][1].as<double>())
            << sensor << a;
        EXPECT_NEAR(axis["coefficients"][2].as<double>(), c[2], 4.0 * axis["sigmas"][2].as<double>())
            << sensor << a;
      }
      EXPECT_GT(axis["uncompensated_drift"].as<double>(), 0.0);
    }
  }
}

TEST(CliCalibrateThermal, SpanTooSmallIsNotDetermined) {
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/flat.imulog", out = dir + "/thermal.yaml";
  auto sim = sim_warm_up(log, "35", "36");
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  auto r = run_cli({"calibrate", "thermal", log, "-o", out});
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_NE(r.err.find("not determined"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("warmed by more"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));

  auto help = run_cli({"calibrate", "thermal", "--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("--min-span"), std::string::npos);
}

TEST(CliCalibrateThermal, AFileThatIsNoThermalModelIsRefusedAndNothingIsWritten) {
  const std::string dir = test::scratch_dir();
  const std::string out = dir + "/static.yaml";
  auto r = run_cli({"calibrate", "static", test::source_path("fixtures/static.imulog"), "--thermal",
                    test::source_path("fixtures/static.truth.yaml"), "-o", out});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("not a thermal model"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("calibrate thermal -o"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// Temperatures no die reaches, met where a user's files bring them in. Before: one sample at
// 1e308 deg C in a warm-up gave a model with a reference of 7e61 deg C and exit 0, and
// `calibrate static --thermal` then applied that model.
TEST(CliCalibrateThermal, TemperaturesNoDieReachesAreRefusedInTheWarmUpTheScaleLogsAndTheModel) {
  const std::string dir = test::scratch_dir();
  const std::string warm = dir + "/warmup.imulog", thermal = dir + "/thermal.yaml";
  ASSERT_EQ(sim_warm_up(warm, "20", "60").exit_code, 0);
  ASSERT_EQ(run_cli({"calibrate", "thermal", warm, "-o", thermal}).exit_code, 0);
  const std::string one_hot =
      "update imu_samples set temperature=1e308 where rowid=(select min(rowid)+100 from imu_samples)";

  const std::string bad_warm = dir + "/bad-warmup.imulog";
  std::filesystem::copy_file(warm, bad_warm);
  ASSERT_TRUE(test::run_sql(bad_warm, one_hot));
  const std::string out = dir + "/out.yaml";
  auto r = run_cli({"calibrate", "thermal", bad_warm, "-o", out});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("which no die reaches"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));

  const std::string bad_poses = test::copy_fixture("static.imulog", dir);
  ASSERT_TRUE(test::run_sql(bad_poses, one_hot));
  r = run_cli({"calibrate", "thermal", warm, "--scale-from", bad_poses, "--scale-from",
               test::source_path("fixtures/static.imulog"), "-o", out});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("--scale-from " + bad_poses), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("which no die reaches"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));

  // A model whose reference, or range, no die reaches: `calibrate static --thermal` refuses it.
  for (const auto& [key, value] :
       {std::pair{"reference_temperature_c", "7e61"}, std::pair{"valid_range_c", "[20, 1e308]"}}) {
    SCOPED_TRACE(key);
    YAML::Node model = YAML::LoadFile(thermal);
    model[key] = YAML::Load(value);
    const std::string bad_model = dir + "/bad-thermal.yaml";
    std::ofstream(bad_model) << model;
    r = run_cli({"calibrate", "static", test::source_path("fixtures/static.imulog"), "--thermal", bad_model,
                 "-o", out});
    EXPECT_EQ(r.exit_code, 3) << r.err;
    EXPECT_NE(r.err.find("must be die temperatures"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out));
  }
}

/// b_a, b_g (counts) of a canonical block of a result YAML.
Eigen::Vector3d canonical_vec(const YAML::Node& y, const char* key) {
  const YAML::Node v = y["canonical"][key];
  return {v[0].as<double>(), v[1].as<double>(), v[2].as<double>()};
}

TEST(CliCalibrateThermal, StaticWithTheModelGivesTheBiasesAtItsReferenceAndTheStoredRecordCarriesIt) {
  const std::string dir = test::scratch_dir();
  const std::string warm = dir + "/warmup.imulog", thermal = dir + "/thermal.yaml";
  auto sim = sim_warm_up(warm, "20", "60");
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  auto t = run_cli({"calibrate", "thermal", warm, "-o", thermal});
  ASSERT_EQ(t.exit_code, 0) << t.err;
  const double ref = YAML::LoadFile(thermal)["reference_temperature_c"].as<double>();

  // The static protocol of the same IMU (its truth file: coefficients and warm-up from 20 deg C):
  // the die warms by about 13 deg C while the poses are taken.
  const std::string truth = sim::truth_path_for(warm), stat = dir + "/static.imulog";
  auto st = run_cli({"sim", "static", "--seed", "7", "--truth", truth, "-o", stat});
  ASSERT_EQ(st.exit_code, 0) << st.err;
  const std::string plain = dir + "/plain.yaml", hot = dir + "/hot.yaml";
  auto a = run_cli({"calibrate", "static", stat, "-o", plain});
  ASSERT_EQ(a.exit_code, 0) << a.err;
  auto b = run_cli({"calibrate", "static", stat, "--thermal", thermal, "-o", hot});
  ASSERT_EQ(b.exit_code, 0) << b.err;
  EXPECT_NE(b.out.find("the samples were corrected to the thermal model's reference temperature"),
            std::string::npos)
      << b.out;
  // The biases' sigmas are the static fit's: what the model adds is said beside them.
  EXPECT_NE(
      b.err.find("the biases' sigmas leave out the thermal model's own uncertainty at the samples' mean "
                 "temperature"),
      std::string::npos)
      << b.err;

  // The truth at the reference temperature, in counts.
  auto params = sim::load_imu_params(truth);
  ASSERT_TRUE(params.ok()) << params.error().message;
  sim::ImuModelParams at_ref = *params;
  at_ref.gyro_bias += params->gyro_bias_temp(ref);
  at_ref.accel_bias += params->accel_bias_temp(ref);
  const CanonicalImuModel want = sim::canonical_correction(at_ref, true);

  const YAML::Node yp = YAML::LoadFile(plain), yh = YAML::LoadFile(hot);
  EXPECT_FALSE(yp["thermal"]);
  ASSERT_TRUE(yh["thermal"]);
  EXPECT_DOUBLE_EQ(yh["reference_temperature_c"].as<double>(), ref);
  EXPECT_DOUBLE_EQ(yh["thermal"]["reference_c"].as<double>(), ref);
  const Eigen::Vector3d plain_g = canonical_vec(yp, "b_g") - want.b_g,
                        hot_g = canonical_vec(yh, "b_g") - want.b_g;
  const Eigen::Vector3d plain_a = canonical_vec(yp, "b_a") - want.b_a,
                        hot_a = canonical_vec(yh, "b_a") - want.b_a;
  std::cout << "gyro bias error at " << ref << " deg C, counts: without the model " << plain_g.transpose()
            << ", with it " << hot_g.transpose() << "\naccelerometer: without " << plain_a.transpose()
            << ", with " << hot_a.transpose() << "\n";
  EXPECT_LT(hot_g.norm(), 0.3 * plain_g.norm());
  EXPECT_LT(hot_a.norm(), 0.5 * plain_a.norm());

  // The stored record carries the model (version 2) and reads back.
  const std::string config = dir + "/rig.yaml";
  std::ofstream(config) << "name: warm-rig\nimu:\n  bus: sim\nstorage:\n  backend: file\n  path: " << dir
                        << "/calibration.bin\n  size_bytes: 8192\n  offset_bytes: 0\n";
  auto w = run_cli({"store", "write", "--config", config, hot});
  ASSERT_EQ(w.exit_code, 0) << w.err;
  auto r = run_cli({"store", "read", "--json", "--config", config});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["calibration"]["version"], 2);
  EXPECT_DOUBLE_EQ(j["calibration"]["thermal"]["reference_c"].get<double>(), ref);
  EXPECT_EQ(j["calibration"]["thermal"]["gyro"].size(), 3u);
}

TEST(CliCalibrateThermal, StaticPosesAtTwoTemperaturesGiveTheScaleAgainstTemperature) {
  const std::string dir = test::scratch_dir();
  const std::string warm = dir + "/warmup.imulog", thermal = dir + "/thermal.yaml";
  auto sim = sim_warm_up(warm, "20", "60");
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  // The same IMU (the warm-up's truth) in static poses held at 22 and at 52 deg C, its scale
  // factors moving with temperature by these ppm/K.
  const Eigen::Vector3d gyro_k(300e-6, -150e-6, 80e-6), accel_k(120e-6, -60e-6, 200e-6);
  const std::string truth = sim::truth_path_for(warm);
  std::vector<std::string> poses;
  for (const auto& [seed, hold] : {std::pair{"8", "22"}, std::pair{"9", "52"}}) {
    poses.push_back(dir + "/poses-" + std::string(hold) + ".imulog");
    auto st =
        run_cli({"sim", "static", "--seed", seed, "--truth", truth, "--temp-hold", hold, "--gyro-scale-tc",
                 "300,-150,80", "--accel-scale-tc", "120,-60,200", "-o", poses.back()});
    ASSERT_EQ(st.exit_code, 0) << st.err;
  }
  // Without them the scale is not determined, and the output says how it would be.
  auto plain = run_cli({"calibrate", "thermal", warm, "-o", dir + "/plain.yaml"});
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_NE(plain.out.find("scale against temperature: not determined: a still recording in one attitude"),
            std::string::npos)
      << plain.out;
  EXPECT_NE(
      YAML::LoadFile(dir + "/plain.yaml")["scale_against_temperature"].as<std::string>().find("--scale-from"),
      std::string::npos);

  auto r = run_cli(
      {"calibrate", "thermal", warm, "--scale-from", poses[0], "--scale-from", poses[1], "-o", thermal});
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("scale against temperature from 2 static calibrations at"), std::string::npos)
      << r.out;
  const YAML::Node s = YAML::LoadFile(thermal)["scale_against_temperature"];
  ASSERT_TRUE(s.IsMap()) << YAML::Dump(s);
  ASSERT_EQ(s["points"].size(), 2u);
  EXPECT_NEAR(s["points"][0]["temperature_c"].as<double>(), 22.0, 0.05);
  EXPECT_NEAR(s["points"][1]["temperature_c"].as<double>(), 52.0, 0.05);
  for (const auto& [sensor, truth_k] : {std::pair{"gyro", gyro_k}, std::pair{"accel", accel_k}}) {
    for (int a = 0; a < 3; ++a) {
      const double k = s[std::string(sensor) + "_k"][a].as<double>();
      const double sigma = s[std::string(sensor) + "_sigma"][a].as<double>();
      std::printf("%s %c: k %.1f +- %.1f ppm/K, truth %.1f\n", sensor, "xyz"[a], k * 1e6, sigma * 1e6,
                  truth_k[a] * 1e6);
      EXPECT_GT(sigma, 0.0);
      EXPECT_LT(sigma, 60e-6) << sensor << a;  // 30 K apart: a few 1e-4 of scale sigma each
      EXPECT_LT(std::abs(k - truth_k[a]), 4.0 * sigma) << sensor << " " << a << ": " << k << " +- " << sigma;
    }
  }
  std::fflush(stdout);  // before the commands below fork
  // Static recordings too close in temperature determine nothing: said, not zeros.
  auto close = run_cli({"calibrate", "thermal", warm, "--scale-from", poses[0], "--scale-from", poses[0],
                        "-o", dir + "/close.yaml"});
  ASSERT_EQ(close.exit_code, 0) << close.err;
  EXPECT_NE(YAML::LoadFile(dir + "/close.yaml")["scale_against_temperature"].as<std::string>().find(
                "not determined: the static calibrations span 0.00 deg C"),
            std::string::npos);
  // The record keeps the scale model.
  auto st = run_cli({"calibrate", "static", poses[1], "--thermal", thermal, "-o", dir + "/hot.yaml"});
  ASSERT_EQ(st.exit_code, 0) << st.err;
  const std::string config = dir + "/rig.yaml";
  std::ofstream(config) << "name: warm-rig\nimu:\n  bus: sim\nstorage:\n  backend: file\n  path: " << dir
                        << "/calibration.bin\n  size_bytes: 8192\n  offset_bytes: 0\n";
  auto w = run_cli({"store", "write", "--config", config, dir + "/hot.yaml"});
  ASSERT_EQ(w.exit_code, 0) << w.err;
  auto rd = run_cli({"store", "read", "--json", "--config", config});
  ASSERT_EQ(rd.exit_code, 0) << rd.err;
  const auto j = nlohmann::json::parse(rd.out)["calibration"]["thermal"]["scale"];
  ASSERT_TRUE(j.is_object()) << j.dump();
  EXPECT_NEAR(j["gyro_k"][0].get<double>(), s["gyro_k"][0].as<double>(), 1e-12);
  EXPECT_EQ(j["temperatures_c"].size(), 2u);
}

}  // namespace
}  // namespace imucal
