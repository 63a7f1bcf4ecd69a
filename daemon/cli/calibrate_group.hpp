#pragma once
// The `calibrate` parent subcommand. Each method (static, camera, camimu, gsens) adds its own
// subcommand to it from its cmd_*.cpp:
//   void setup(CLI::App& root) { CLI::App* cmd = calibrate_group(root)->add_subcommand(...); }

#include <CLI/CLI.hpp>

namespace imucal::cli {

/// The `calibrate` subcommand of `root`, created on the first call.
CLI::App* calibrate_group(CLI::App& root);

}  // namespace imucal::cli
