// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The `calibrate` parent subcommand. Each method (static, camera, camimu, gsens) adds its own
// subcommand to it from its cmd_*.cpp:
//   void setup(CLI::App& root) { CLI::App* cmd = calibrate_group(root)->add_subcommand(...); }

#include <CLI/CLI.hpp>
#include <optional>

#include "app/initial_guess.hpp"
#include "app/results/camera_results.hpp"
#include "calib/shutter_options.hpp"
#include "core/camera_model.hpp"
#include "core/split_check.hpp"

namespace imucal::cli {

/// The `calibrate` subcommand of `root`, created on the first call.
CLI::App* calibrate_group(CLI::App& root);

/// A rolling shutter as `calibrate camera` and `calibrate camimu` take it: --shutter (its help,
/// `shutter_help`, is the command's own), --line-delay, --readout, --stamp-row (empty: the camera
/// file's, where there is one).
struct ShutterArgs {
  std::string shutter = "auto";
  std::optional<double> line_delay_us;
  std::string readout;
  std::string stamp_row;
};
void add_shutter_options(CLI::App* cmd, ShutterArgs* args, const std::string& shutter_help);
/// The solve's options; --line-delay with --shutter global is a usage error (exit 2).
calib::ShutterSolveOptions shutter_solve_options(const ShutterArgs& args);
/// --readout and --stamp-row, where given, into `shutter`.
void apply_shutter_args(const ShutterArgs& args, Shutter* shutter);

/// Local gravity as the calibrate commands take it: --gravity, or --latitude [--height].
struct GravityArgs {
  std::optional<double> gravity;
  std::optional<double> latitude_deg;
  double height_m = 0.0;
};
void add_gravity_options(CLI::App* cmd, GravityArgs* args);
/// The gravity the arguments give; warns on stderr when standard gravity is assumed.
app::GravityChoice resolve_gravity(const GravityArgs& args);

/// The calibration target of the camera commands: `--target` when given, else the one the log
/// names. Ends the command (CliExit) when the file is bad or the log names none.
app::TargetChoice resolve_target(const std::string& target_path, const std::string& log_path);

/// Where the camera commands keep the target detections of a log's frames: never in the log
/// unless asked (--store-detections), else in the user's cache (docs/cli.md, "Stored detections").
struct DetectionStoreArgs {
  bool no_reuse = false;
  bool store_in_log = false;
  bool no_cache = false;
};
void add_detection_store_options(CLI::App* cmd, DetectionStoreArgs* args);
/// The user's cache folder: $IMUCAL_CACHE_DIR, else $XDG_CACHE_HOME/imucal, else
/// $HOME/.cache/imucal; empty when none is set.
std::string user_cache_dir();

/// The detection cache folder: $IMUCAL_CACHE_DIR, else $XDG_CACHE_HOME/imucal, else
/// $HOME/.cache/imucal, with "/detections" appended; empty with --no-cache or when none is set.
std::string detection_cache_dir(const DetectionStoreArgs& args);
/// "reused from the log", "stored in FILE", "not stored" for the summaries.
std::string detections_in_words(const std::string& reused_from, const std::string& stored_in);

/// --self-check K: the parts of the recording calibrated apart and compared (2 by default: the
/// halves; 0: none).
void add_self_check_option(CLI::App* cmd, int* parts);
/// The self-check's verdict in a summary (`indent` before each line), and the parameters that
/// differ most when the parts disagree; nothing when it was not run.
void print_self_check(const SplitCheck& check, const std::string& indent);

}  // namespace imucal::cli
