#pragma once
// The `calibrate` parent subcommand. Each method (static, camera, camimu, gsens) adds its own
// subcommand to it from its cmd_*.cpp:
//   void setup(CLI::App& root) { CLI::App* cmd = calibrate_group(root)->add_subcommand(...); }

#include <CLI/CLI.hpp>
#include <optional>

#include "app/camera_results.hpp"
#include "app/initial_guess.hpp"

namespace imucal::cli {

/// The `calibrate` subcommand of `root`, created on the first call.
CLI::App* calibrate_group(CLI::App& root);

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

}  // namespace imucal::cli
