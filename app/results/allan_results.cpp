// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/allan_results.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <nlohmann/json.hpp>

namespace imucal::app {
namespace {

using nlohmann::json;

double worst(const std::vector<calib::AllanNoise>& f, double calib::AllanNoise::*m) {
  return std::max({f[0].*m, f[1].*m, f[2].*m});
}

json sensor_json(const calib::AllanCurve& curve, const std::vector<calib::AllanNoise>& fits,
                 const std::string& unit) {
  json j;
  j["unit"] = unit;
  json axes = json::array();
  for (int a = 0; a < 3; ++a) {
    const auto& f = fits[a];
    axes.push_back(
        {{"axis", std::string(1, "xyz"[a])},
         {"noise_density", f.noise_density},
         {"random_walk", f.random_walk},
         {"random_walk_is_upper_bound", f.random_walk_is_bound},
         {"bias_instability", f.bias_instability},
         {"bias_instability_tau_s", f.bias_instability_tau_s},
         {"bias_instability_is_upper_bound", f.bias_instability_is_bound},
         {"lines",
          {{"white_noise", {{"adev", "N / sqrt(tau)"}, {"tau_s", {f.white_tau_min_s, f.white_tau_max_s}}}},
           {"random_walk", {{"adev", "K * sqrt(tau / 3)"}, {"tau_s", {f.rw_tau_min_s, f.rw_tau_max_s}}}},
           {"bias_instability", {{"adev", "0.664 * B"}, {"tau_s", f.bias_instability_tau_s}}}}}});
  }
  j["axes"] = axes;
  json c;
  c["tau_s"] = curve.tau_s;
  for (int a = 0; a < 3; ++a) {
    std::vector<double> v;
    for (const auto& d : curve.adev) v.push_back(d[a]);
    c[std::string("adev_") + "xyz"[a]] = v;
  }
  c["clusters"] = curve.clusters;
  j["curve"] = c;
  return j;
}

}  // namespace

double AllanReport::accel_noise_density() const {
  return worst(accel_fits, &calib::AllanNoise::noise_density);
}
double AllanReport::accel_random_walk() const { return worst(accel_fits, &calib::AllanNoise::random_walk); }
double AllanReport::gyro_noise_density() const { return worst(gyro_fits, &calib::AllanNoise::noise_density); }
double AllanReport::gyro_random_walk() const { return worst(gyro_fits, &calib::AllanNoise::random_walk); }

bool AllanReport::random_walk_is_upper_bound() const {
  for (int a = 0; a < 3; ++a) {
    if (accel_fits[a].random_walk_is_bound || gyro_fits[a].random_walk_is_bound) return true;
  }
  return false;
}

Result<AllanReport> analyse_allan(const std::vector<Eigen::Vector3d>& accel,
                                  const std::vector<Eigen::Vector3d>& gyro, double rate_hz) {
  AllanReport report;
  report.rate_hz = rate_hz;
  report.duration_s = static_cast<double>(accel.size()) / rate_hz;
  auto ca = calib::allan_deviation(accel, rate_hz);
  if (!ca.ok()) return ca.error().context("accelerometer Allan deviation");
  auto cg = calib::allan_deviation(gyro, rate_hz);
  if (!cg.ok()) return cg.error().context("gyroscope Allan deviation");
  report.accel_curve = std::move(*ca);
  report.gyro_curve = std::move(*cg);
  for (int a = 0; a < 3; ++a) {
    report.accel_fits.push_back(calib::fit_allan_noise(report.accel_curve, a));
    report.gyro_fits.push_back(calib::fit_allan_noise(report.gyro_curve, a));
  }
  return report;
}

std::string allan_kalibr_yaml(const AllanReport& r) {
  YAML::Emitter y;
  y.SetDoublePrecision(8);
  y << YAML::Comment("Kalibr IMU noise model: worst axis, from imucal allan " + r.log_path);
  y << YAML::BeginMap;
  y << YAML::Key << "accelerometer_noise_density" << YAML::Value << r.accel_noise_density();
  y << YAML::Key << "accelerometer_random_walk" << YAML::Value << r.accel_random_walk();
  y << YAML::Key << "gyroscope_noise_density" << YAML::Value << r.gyro_noise_density();
  y << YAML::Key << "gyroscope_random_walk" << YAML::Value << r.gyro_random_walk();
  y << YAML::Key << "rostopic" << YAML::Value << r.rostopic;
  y << YAML::Key << "update_rate" << YAML::Value << r.rate_hz;
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

std::string allan_json(const AllanReport& r) {
  json j;
  j["log"] = r.log_path;
  j["stream"] = r.stream;
  j["rate_hz"] = r.rate_hz;
  j["duration_s"] = r.duration_s;
  j["accelerometer"] = sensor_json(r.accel_curve, r.accel_fits, "m/s^2");
  j["gyroscope"] = sensor_json(r.gyro_curve, r.gyro_fits, "rad/s");
  j["kalibr"] = {{"accelerometer_noise_density", r.accel_noise_density()},
                 {"accelerometer_random_walk", r.accel_random_walk()},
                 {"gyroscope_noise_density", r.gyro_noise_density()},
                 {"gyroscope_random_walk", r.gyro_random_walk()},
                 {"rostopic", r.rostopic},
                 {"update_rate", r.rate_hz}};
  j["random_walk_is_upper_bound"] = r.random_walk_is_upper_bound();
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace imucal::app
