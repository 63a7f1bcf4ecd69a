// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;

constexpr double kAccelDensity = 3.92e-3;  // MPU-6000 datasheet, (m/s^2)/sqrt(Hz)
constexpr double kGyroDensity = 8.73e-5;   // (rad/s)/sqrt(Hz)

/// A still recording in raw counts (16-bit, centred at 32768) with white noise.
std::string write_still_log(const std::string& dir, double duration_s, bool with_motion) {
  const double rate = 100.0, lsb_a = 9.80665 / 8192.0, lsb_g = M_PI / 180.0 / 65.5;
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<ImuSample> samples;
  const long n = std::lround(duration_s * rate);
  for (long i = 0; i < n; ++i) {
    ImuSample s;
    s.t_ns = i * 10'000'000;
    const bool moving = with_motion && i > n / 2 && i < n / 2 + 200;
    for (int a = 0; a < 3; ++a) {
      const double f =
          (a == 2 ? 9.80665 : 0.0) + kAccelDensity * std::sqrt(rate) * g(rng) + (moving ? 3.0 : 0.0);
      const double w = 0.01 * (a + 1) + kGyroDensity * std::sqrt(rate) * g(rng);
      s.accel[a] = 32768.0 + f / lsb_a;  // unquantised counts keep the test exact
      s.gyro[a] = 32768.0 + w / lsb_g;
    }
    samples.push_back(s);
  }
  const std::string path = dir + "/still.imulog";
  auto w = log::SessionLogWriter::create(path);
  EXPECT_TRUE(w.ok());
  ImuStreamInfo info;
  info.units = ImuUnits::kRaw;
  info.rate_hz = rate;
  info.accel.scale.setConstant(lsb_a);
  info.accel.offset.setConstant(32768.0);
  info.gyro.scale.setConstant(lsb_g);
  info.gyro.offset.setConstant(32768.0);
  auto id = (*w)->add_imu_stream(info);
  EXPECT_TRUE((*w)->append_imu(*id, samples).ok());
  EXPECT_TRUE((*w)->close().ok());
  return path;
}

TEST(CliAllan, KalibrYamlAndJson) {
  const std::string dir = test::scratch_dir();
  const std::string log = write_still_log(dir, 300.0, false);
  const auto r = run_cli(
      {"allan", log, "--rostopic", "/mpu/imu", "-o", dir + "/imu.yaml", "--json", dir + "/allan.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const YAML::Node y = YAML::LoadFile(dir + "/imu.yaml");
  EXPECT_NEAR(y["accelerometer_noise_density"].as<double>(), kAccelDensity, 0.1 * kAccelDensity);
  EXPECT_NEAR(y["gyroscope_noise_density"].as<double>(), kGyroDensity, 0.1 * kGyroDensity);
  EXPECT_GT(y["accelerometer_random_walk"].as<double>(), 0.0);
  EXPECT_GT(y["gyroscope_random_walk"].as<double>(), 0.0);
  EXPECT_EQ(y["rostopic"].as<std::string>(), "/mpu/imu");
  EXPECT_NEAR(y["update_rate"].as<double>(), 100.0, 1e-9);
  EXPECT_NE((r.out + r.err).find("upper bound"), std::string::npos)
      << r.out << r.err;  // 5 min: no random walk

  const auto j = nlohmann::json::parse(test::read_file(dir + "/allan.json"));
  ASSERT_EQ(j["gyroscope"]["axes"].size(), 3u);
  EXPECT_TRUE(j["gyroscope"]["axes"][0]["random_walk_is_upper_bound"].get<bool>());
  const auto& tau = j["accelerometer"]["curve"]["tau_s"];
  ASSERT_GE(tau.size(), 10u);
  EXPECT_DOUBLE_EQ(tau[0].get<double>(), 0.01);
  EXPECT_DOUBLE_EQ(tau[1].get<double>(), 0.02);
  EXPECT_EQ(j["accelerometer"]["curve"]["adev_z"].size(), tau.size());
}

TEST(CliAllan, MotionIsRefused) {
  const std::string dir = test::scratch_dir();
  const std::string log = write_still_log(dir, 120.0, true);
  const auto r = run_cli({"allan", log, "-o", dir + "/imu.yaml"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.err.find("moves"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace imucal
