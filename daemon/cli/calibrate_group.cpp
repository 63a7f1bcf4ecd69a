#include "daemon/cli/calibrate_group.hpp"

#include <spdlog/spdlog.h>

#include <cstdlib>
#include <string>

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
                "Neither read nor write the detection cache ($IMUCAL_CACHE_DIR, $XDG_CACHE_HOME/imucal or "
                "~/.cache/imucal)");
}

std::string detection_cache_dir(const DetectionStoreArgs& args) {
  if (args.no_cache) return {};
  auto env = [](const char* name) {
    const char* v = std::getenv(name);
    return v != nullptr ? std::string(v) : std::string();
  };
  std::string base = env("IMUCAL_CACHE_DIR");
  if (base.empty() && !env("XDG_CACHE_HOME").empty()) base = env("XDG_CACHE_HOME") + "/imucal";
  if (base.empty() && !env("HOME").empty()) base = env("HOME") + "/.cache/imucal";
  return base.empty() ? std::string() : base + "/detections";
}

std::string detections_in_words(const std::string& reused_from, const std::string& stored_in) {
  if (!reused_from.empty()) return "reused from " + reused_from;
  if (!stored_in.empty()) return "stored in " + stored_in;
  return "not stored";
}

}  // namespace imucal::cli
