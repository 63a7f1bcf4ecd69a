// imucal allan LOG: noise figures of a still recording from the overlapping Allan deviation,
// written as a Kalibr imu.yaml and as JSON with the curves (docs/static-calibration.md).

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "calib/allan.hpp"
#include "calib/static_detector.hpp"
#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

struct AllanCliOptions {
  std::string log_path;
  std::string stream;
  std::string rostopic = "/imu0";
  bool allow_motion = false;
  bool allow_damaged = false;
  std::string yaml_path;
  std::string json_path;
};

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw CliExit{kExitIo, "could not write " + path + ": check the folder exists and is writable"};
}

nlohmann::json sensor_json(const calib::AllanCurve& curve, const std::vector<calib::AllanNoise>& fits,
                           const std::string& unit) {
  using nlohmann::json;
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

void run(const AllanCliOptions& o) {
  auto log = log::SessionLogReader::open(o.log_path);
  if (!log.ok()) fail(log.error(), "cannot read " + o.log_path);
  const auto& reader = **log;
  if (reader.health().damaged && !o.allow_damaged) {
    throw CliExit{kExitInput, o.log_path + " is damaged (" + reader.health().damage_message +
                                  "); pass --allow-damaged to use what is readable"};
  }
  auto id = reader.find_imu_stream(o.stream);
  if (!id.ok()) fail(id.error(), "no IMU stream in " + o.log_path);
  const ImuStreamInfo info = reader.imu_streams().at(*id);
  auto samples = reader.read_imu(*id);
  if (!samples.ok()) fail(samples.error(), "cannot read the IMU samples of " + o.log_path);
  const auto& s = *samples;
  if (s.size() < 1000) {
    throw CliExit{kExitData, "the stream has " + std::to_string(s.size()) +
                                 " samples: record at least several minutes with the rig at rest (hours for "
                                 "the random walk)"};
  }

  // The longest run without gaps, resets or saturation: the Allan deviation needs even sampling.
  std::vector<TimeNs> dts;
  for (std::size_t i = 1; i < s.size(); ++i) dts.push_back(s[i].t_ns - s[i - 1].t_ns);
  std::nth_element(dts.begin(), dts.begin() + static_cast<std::ptrdiff_t>(dts.size() / 2), dts.end());
  const TimeNs period_ns = dts[dts.size() / 2];
  if (period_ns <= 0) throw CliExit{kExitInput, "the timestamps of " + o.log_path + " do not increase"};
  const double rate_hz = 1e9 / static_cast<double>(period_ns);
  std::size_t best0 = 0, best1 = 0, run0 = 0;
  int breaks = 0;
  for (std::size_t i = 0; i <= s.size(); ++i) {
    const bool brk = i == s.size() ||
                     (s[i].flags & (kImuFlagGapBefore | kImuFlagDeviceReset | kImuFlagAccelSaturated |
                                    kImuFlagGyroSaturated)) ||
                     (i > 0 && (s[i].t_ns - s[i - 1].t_ns > period_ns * 3 / 2 || s[i].t_ns <= s[i - 1].t_ns));
    if (brk) {
      if (i < s.size()) ++breaks;
      if (i - run0 > best1 - best0) {
        best0 = run0;
        best1 = i;
      }
      run0 = (i < s.size() && (s[i].flags & (kImuFlagAccelSaturated | kImuFlagGyroSaturated))) ? i + 1 : i;
    }
  }
  if (breaks > 0) {
    spdlog::warn(
        "the log has {} gap(s), reset(s) or saturated sample(s): using the longest clean run, {:.1f} s of "
        "{:.1f} s",
        breaks, (best1 - best0) / rate_hz, s.size() / rate_hz);
  }
  std::vector<Eigen::Vector3d> accel, gyro;
  for (std::size_t i = best0; i < best1; ++i) {
    accel.push_back(info.accel.to_si(s[i].accel));
    gyro.push_back(info.gyro.to_si(s[i].gyro));
  }
  if (info.units == ImuUnits::kRaw) {
    spdlog::info(
        "raw counts converted to SI with the log's nominal scales (accel {} g, gyro {} deg/s full scale)",
        info.accel_full_scale_g, info.gyro_full_scale_dps);
  }

  // The recording must be still: motion inflates every figure.
  if (!o.allow_motion) {
    const auto var = calib::variance_magnitude_sq(accel, static_cast<std::size_t>(std::max(3.0, rate_hz)));
    std::vector<double> sorted = var;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                     sorted.end());
    const double median = sorted[sorted.size() / 2];
    for (std::size_t i = 0; i < var.size(); ++i) {
      if (var[i] > 25.0 * median) {
        throw CliExit{kExitData,
                      "the rig moves at t = " + std::to_string((i) / rate_hz) +
                          " s of the clean run: the Allan deviation needs a still recording. Record "
                          "again with the rig at rest, or pass --allow-motion to accept it"};
      }
    }
  }

  auto ca = calib::allan_deviation(accel, rate_hz);
  if (!ca.ok()) fail(ca.error(), "accelerometer Allan deviation");
  auto cg = calib::allan_deviation(gyro, rate_hz);
  if (!cg.ok()) fail(cg.error(), "gyroscope Allan deviation");
  std::vector<calib::AllanNoise> fa, fg;
  for (int a = 0; a < 3; ++a) {
    fa.push_back(calib::fit_allan_noise(*ca, a));
    fg.push_back(calib::fit_allan_noise(*cg, a));
  }
  auto worst = [](const std::vector<calib::AllanNoise>& f, double calib::AllanNoise::*m) {
    return std::max({f[0].*m, f[1].*m, f[2].*m});
  };
  const double a_nd = worst(fa, &calib::AllanNoise::noise_density);
  const double a_rw = worst(fa, &calib::AllanNoise::random_walk);
  const double g_nd = worst(fg, &calib::AllanNoise::noise_density);
  const double g_rw = worst(fg, &calib::AllanNoise::random_walk);
  const bool rw_bound = fa[0].random_walk_is_bound || fa[1].random_walk_is_bound ||
                        fa[2].random_walk_is_bound || fg[0].random_walk_is_bound ||
                        fg[1].random_walk_is_bound || fg[2].random_walk_is_bound;
  if (rw_bound) {
    spdlog::warn(
        "the recording is too short to show the random-walk slope: the random walks are upper bounds "
        "from the longest averaging time (record for hours to measure them)");
  }

  if (!o.yaml_path.empty()) {
    YAML::Emitter y;
    y.SetDoublePrecision(8);
    y << YAML::Comment("Kalibr IMU noise model: worst axis, from imucal allan " + o.log_path);
    y << YAML::BeginMap;
    y << YAML::Key << "accelerometer_noise_density" << YAML::Value << a_nd;
    y << YAML::Key << "accelerometer_random_walk" << YAML::Value << a_rw;
    y << YAML::Key << "gyroscope_noise_density" << YAML::Value << g_nd;
    y << YAML::Key << "gyroscope_random_walk" << YAML::Value << g_rw;
    y << YAML::Key << "rostopic" << YAML::Value << o.rostopic;
    y << YAML::Key << "update_rate" << YAML::Value << rate_hz;
    y << YAML::EndMap;
    write_text(o.yaml_path, std::string(y.c_str()) + "\n");
  }
  if (!o.json_path.empty()) {
    nlohmann::json j;
    j["log"] = o.log_path;
    j["stream"] = info.name;
    j["rate_hz"] = rate_hz;
    j["duration_s"] = static_cast<double>(accel.size()) / rate_hz;
    j["accelerometer"] = sensor_json(*ca, fa, "m/s^2");
    j["gyroscope"] = sensor_json(*cg, fg, "rad/s");
    j["kalibr"] = {{"accelerometer_noise_density", a_nd},
                   {"accelerometer_random_walk", a_rw},
                   {"gyroscope_noise_density", g_nd},
                   {"gyroscope_random_walk", g_rw},
                   {"rostopic", o.rostopic},
                   {"update_rate", rate_hz}};
    j["random_walk_is_upper_bound"] = rw_bound;
    write_text(o.json_path, j.dump(2) + "\n");
  }
  std::cout << "Allan deviation of " << o.log_path << " (" << info.name << ", " << accel.size() / rate_hz
            << " s at " << rate_hz << " Hz)\n";
  for (int a = 0; a < 3; ++a) {
    std::cout << "  accel "
              << "xyz"[a] << ": noise density " << fa[a].noise_density << " m/s^2/sqrt(Hz), random walk "
              << (fa[a].random_walk_is_bound ? "<= " : "") << fa[a].random_walk
              << " m/s^3/sqrt(Hz), bias instability " << (fa[a].bias_instability_is_bound ? "<= " : "")
              << fa[a].bias_instability << " m/s^2\n";
  }
  for (int a = 0; a < 3; ++a) {
    std::cout << "  gyro  "
              << "xyz"[a] << ": noise density " << fg[a].noise_density << " rad/s/sqrt(Hz), random walk "
              << (fg[a].random_walk_is_bound ? "<= " : "") << fg[a].random_walk
              << " rad/s^2/sqrt(Hz), bias instability " << (fg[a].bias_instability_is_bound ? "<= " : "")
              << fg[a].bias_instability << " rad/s\n";
  }
}

void setup(CLI::App& root) {
  CLI::App* cmd =
      root.add_subcommand("allan", "Noise figures of a still recording (Allan deviation), Kalibr imu.yaml");
  auto o = std::make_shared<AllanCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) of the rig at rest")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  cmd->add_option("--rostopic", o->rostopic, "rostopic written to imu.yaml");
  cmd->add_flag("--allow-motion", o->allow_motion, "Do not refuse a recording in which the rig moves");
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Use what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path, "Write the Kalibr imu.yaml");
  cmd->add_option("--json", o->json_path, "Write the figures and the curves as JSON");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(35, setup);

}  // namespace
}  // namespace imucal::cli
