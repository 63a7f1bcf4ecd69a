// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/cli/calibrate_group.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/target.hpp"
#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {

CLI::App* calibrate_group(CLI::App& root) {
  auto found = root.get_subcommands([](CLI::App* app) { return app->get_name() == "calibrate"; });
  if (!found.empty()) return found.front();
  CLI::App* group =
      root.add_subcommand("calibrate", "Estimate a calibration from a session log, or check given ones");
  group->require_subcommand(1);
  return group;
}

void add_gravity_options(CLI::App* cmd, GravityArgs* args) {
  auto* g = cmd->add_option("--gravity", args->gravity, "Local gravity magnitude, m/s^2")
                ->check(CLI::Range(9.7, 9.9));
  auto* lat =
      cmd->add_option("--latitude", args->latitude_deg, "Geodetic latitude, deg (WGS-84 normal gravity)")
          ->check(CLI::Range(-90.0, 90.0));
  cmd->add_option("--height", args->height_m, "Ellipsoidal height, m (with --latitude)")
      ->check(CLI::Range(-1000.0, 10000.0))
      ->needs(lat);
  g->excludes(lat);
}

app::GravityChoice resolve_gravity(const GravityArgs& args) {
  const app::GravityChoice gravity = app::choose_gravity(args.gravity, args.latitude_deg, args.height_m);
  if (gravity.standard_assumed) {
    spdlog::warn("no --gravity or --latitude given: using standard gravity 9.80665 m/s^2 (up to 0.3% off)");
  }
  return gravity;
}

app::TargetChoice resolve_target(const std::string& target_path, const std::string& log_path) {
  if (!target_path.empty()) {
    auto t = load_target_yaml(target_path);
    if (!t.ok()) throw CliExit{kExitInput, "--target: " + t.error().message};
    return {*t, target_path};
  }
  auto reader = log::SessionLogReader::open(log_path);
  if (!reader.ok()) fail(reader.error());
  auto t = app::target_from_log_metadata((*reader)->metadata());
  if (!t.ok()) {
    if (t.error().code == Errc::kNotFound) {
      throw CliExit{kExitUsage, log_path +
                                    " names no calibration target (neither its rig configuration nor its "
                                    "metadata has one): pass --target TARGET.yaml (Kalibr target YAML)"};
    }
    fail(t.error(), log_path);
  }
  return *t;
}

void add_shutter_options(CLI::App* cmd, ShutterArgs* args, const std::string& shutter_help) {
  cmd->add_option("--shutter", args->shutter, shutter_help)
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "global", "rolling"}));
  cmd->add_option(
         "--line-delay", args->line_delay_us,
         "Hold a rolling shutter's line delay at this value, microseconds per row (the sensor mode's "
         "readout time / rows, from its datasheet or libcamera)")
      ->check(CLI::Range(-1000.0, 1000.0));
  cmd->add_option("--readout", args->readout,
                  "Rolling shutter readout direction: top_to_bottom or bottom_to_top (default: the camera "
                  "file's, else top_to_bottom)")
      ->check(CLI::IsMember({"top_to_bottom", "bottom_to_top"}));
  cmd->add_option(
         "--stamp-row", args->stamp_row,
         "The row a frame's stamp refers to: first, middle or last (default: the camera file's, else "
         "what the log says of the stream's stamps: end-of-frame the last row, mid-exposure the first)")
      ->check(CLI::IsMember({"first", "middle", "last"}));
}

calib::ShutterSolveOptions shutter_solve_options(const ShutterArgs& args) {
  using Mode = calib::ShutterSolveOptions::Mode;
  if (args.line_delay_us && args.shutter == "global")
    throw CliExit{kExitUsage, "--line-delay is for a rolling shutter: drop --shutter global"};
  calib::ShutterSolveOptions o;
  o.mode = args.shutter == "global"    ? Mode::kGlobal
           : args.shutter == "rolling" ? Mode::kRolling
                                       : Mode::kAuto;
  if (args.line_delay_us) o.line_delay_s = 1e-6 * *args.line_delay_us;
  return o;
}

void apply_shutter_args(const ShutterArgs& args, Shutter* shutter) {
  if (args.readout == "bottom_to_top") shutter->readout = Shutter::Readout::kBottomToTop;
  if (args.readout == "top_to_bottom") shutter->readout = Shutter::Readout::kTopToBottom;
  if (args.stamp_row == "first") shutter->stamp_row = Shutter::StampRow::kFirst;
  if (args.stamp_row == "middle") shutter->stamp_row = Shutter::StampRow::kMiddle;
  if (args.stamp_row == "last") shutter->stamp_row = Shutter::StampRow::kLast;
}

void add_detection_store_options(CLI::App* cmd, DetectionStoreArgs* args) {
  cmd->add_flag(
      "--no-reuse", args->no_reuse,
      "Search the frames again even when detections for these frames and this target are stored (the "
      "new ones replace them)");
  cmd->add_flag(
      "--store-detections", args->store_in_log,
      "Store the detections in the log itself (it is otherwise never written; the default keeps them "
      "in the detection cache)");
  cmd->add_flag("--no-cache", args->no_cache,
                "Neither read nor write the cache of detections and of bag imports ($IMUCAL_CACHE_DIR, "
                "$XDG_CACHE_HOME/imucal or ~/.cache/imucal)");
}

std::string user_cache_dir() {
  auto env = [](const char* name) {
    const char* v = std::getenv(name);
    return v != nullptr ? std::string(v) : std::string();
  };
  std::string base = env("IMUCAL_CACHE_DIR");
  if (base.empty() && !env("XDG_CACHE_HOME").empty()) base = env("XDG_CACHE_HOME") + "/imucal";
  if (base.empty() && !env("HOME").empty()) base = env("HOME") + "/.cache/imucal";
  return base;
}

std::string detection_cache_dir(const DetectionStoreArgs& args) {
  if (args.no_cache) return {};
  const std::string base = user_cache_dir();
  return base.empty() ? std::string() : base + "/detections";
}

std::string detections_in_words(const std::string& reused_from, const std::string& stored_in) {
  if (!reused_from.empty()) return "reused from " + reused_from;
  if (!stored_in.empty()) return "stored in " + stored_in;
  return "not stored";
}

void add_self_check_option(CLI::App* cmd, int* parts) {
  cmd->add_option(
         "--self-check", *parts,
         "Calibrate this many consecutive parts of the recording apart and compare them against their "
         "sigmas (2: the halves; 0 or 1: no self-check)")
      ->check(CLI::Range(0, 8))
      ->capture_default_str();
}

void print_self_check(const SplitCheck& c, const std::string& indent) {
  if (c.verdict == SplitCheck::Verdict::kNotRun) return;
  std::printf("%sself-check: %s (%.1f s)\n", indent.c_str(), c.summary.c_str(), c.wall_s);
  if (c.verdict != SplitCheck::Verdict::kDisagree) return;
  std::vector<const SplitCheckParameter*> worst;
  for (const auto& p : c.parameters)
    if (std::isfinite(p.worst_z)) worst.push_back(&p);
  std::sort(worst.begin(), worst.end(), [](auto* a, auto* b) { return a->worst_z > b->worst_z; });
  for (std::size_t i = 0; i < worst.size() && i < 3 && worst[i]->worst_z > c.z_limit; ++i) {
    std::string parts;
    for (std::size_t k = 0; k < worst[i]->values.size(); ++k) {
      char text[80];
      std::snprintf(text, sizeof text, "%s%.4g +- %.2g", k ? ", " : "", worst[i]->values[k],
                    worst[i]->sigmas[k]);
      parts += text;
    }
    std::printf("%s  %s: %s %s (%.1f combined sigmas apart)\n", indent.c_str(), worst[i]->name.c_str(),
                parts.c_str(), worst[i]->unit.c_str(), worst[i]->worst_z);
  }
  std::printf("%s  %s\n", indent.c_str(), c.advice.c_str());
}

}  // namespace imucal::cli
