// SPDX-License-Identifier: BSD-3-Clause
// imucal allan LOG: noise figures of a still recording from the overlapping Allan deviation,
// written as a Kalibr imu.yaml and as JSON with the curves (docs/static-calibration.md).

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "app/results/allan_results.hpp"
#include "app/results/output_checks.hpp"
#include "app/stream_stats.hpp"
#include "app/streams.hpp"
#include "daemon/cli/bag_input.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct AllanCliOptions {
  std::string log_path;
  std::vector<std::string> topics;  // LOG a ROS bag: the topics to import
  std::string stream;
  std::string rostopic = "/imu0";
  bool allow_motion = false;
  bool allow_damaged = false;
  bool force = false;
  std::string yaml_path;
  std::string json_path;
};

void run(const AllanCliOptions& given) {
  const app::OutputPolicy outputs{given.force, {given.log_path}};
  if (auto s = app::check_outputs({{"-o", given.yaml_path}, {"--json", given.json_path}}, outputs); !s.ok())
    fail(s.error());
  const AllanCliOptions o = with_log_of_input(given);
  auto loaded = app::load_imu_stream(
      o.log_path, o.stream, o.allow_damaged ? app::DamagePolicy::kAllow : app::DamagePolicy::kRefuse);
  if (!loaded.ok()) fail(loaded.error());
  const ImuStreamInfo& info = loaded->info;
  const auto& s = loaded->samples;
  if (s.size() < 1000) {
    throw CliExit{kExitData, "the stream has " + std::to_string(s.size()) +
                                 " samples: record at least several minutes with the rig at rest (hours for "
                                 "the random walk)"};
  }

  // The longest run without gaps, resets or saturation: the Allan deviation needs even sampling.
  auto clean = app::longest_clean_run(s);
  if (!clean.ok()) throw CliExit{kExitInput, "the timestamps of " + given.log_path + " do not increase"};
  const double rate_hz = clean->rate_hz;
  const std::size_t best0 = clean->begin, best1 = clean->end;
  const int breaks = clean->breaks;
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
    if (const auto moved_s = app::first_motion_s(accel, rate_hz)) {
      throw CliExit{kExitData, "the rig moves at t = " + std::to_string(*moved_s) +
                                   " s of the clean run: the Allan deviation needs a still recording. Record "
                                   "again with the rig at rest, or pass --allow-motion to accept it"};
    }
  }

  auto analysed = app::analyse_allan(accel, gyro, rate_hz);
  if (!analysed.ok()) fail(analysed.error());
  app::AllanReport& report = *analysed;
  report.log_path = given.log_path;  // a bag, not its import
  report.stream = info.name;
  report.rostopic = o.rostopic;
  const auto& fa = report.accel_fits;
  const auto& fg = report.gyro_fits;
  const bool rw_bound = report.random_walk_is_upper_bound();
  if (rw_bound) {
    spdlog::warn(
        "the recording is too short to show the random-walk slope: the random walks are upper bounds "
        "from the longest averaging time (record for hours to measure them)");
  }

  if (!o.yaml_path.empty()) {
    if (auto w = app::write_text_file(o.yaml_path, app::allan_kalibr_yaml(report), outputs); !w.ok())
      fail(w.error());
  }
  if (!o.json_path.empty()) {
    if (auto w = app::write_text_file(o.json_path, app::allan_json(report), outputs); !w.ok())
      fail(w.error());
  }
  std::cout << "Allan deviation of " << given.log_path << " (" << info.name << ", " << accel.size() / rate_hz
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
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) of the rig at rest, or a ROS 1 bag")->required();
  add_bag_topics_option(cmd, &o->topics);
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  cmd->add_option("--rostopic", o->rostopic, "rostopic written to imu.yaml");
  cmd->add_flag("--allow-motion", o->allow_motion, "Do not refuse a recording in which the rig moves");
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Use what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path, "Write the Kalibr imu.yaml");
  cmd->add_option("--json", o->json_path, "Write the figures and the curves as JSON");
  cmd->add_flag("--force", o->force, "Replace result files that exist (never the log)");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(35, setup);

}  // namespace
}  // namespace imucal::cli
