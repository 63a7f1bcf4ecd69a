// `imucal calibrate thermal` on a still warm-up recorded by `imucal sim still --temp-profile`:
// the YAML's coefficients against the seed's truth within their sigmas, the reference and range,
// and the refusal of a span too small.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <string>

#include "sim/imu_error_model.hpp"
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

}  // namespace
}  // namespace imucal
