// SPDX-License-Identifier: BSD-3-Clause
// imucal config check FILE [--json]: validate a rig configuration and print it normalized.

#include <iostream>
#include <memory>

#include "core/rig_config.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct ConfigOptions {
  std::string path;
  bool json = false;
};

void setup(CLI::App& root) {
  CLI::App* config = root.add_subcommand("config", "Rig configuration files (docs/config.md)");
  config->require_subcommand(1);
  auto o = std::make_shared<ConfigOptions>();
  CLI::App* check = config->add_subcommand(
      "check", "Validate a rig configuration and print it normalized (every key, defaults filled in)");
  check->add_option("FILE", o->path, "Rig configuration YAML")->required();
  check->add_flag("--json", o->json, "Print JSON instead of YAML");
  check->callback([o] {
    auto cfg = load_rig_config(o->path);
    if (!cfg.ok()) throw CliExit{kExitInput, cfg.error().message};
    std::cout << (o->json ? rig_config_to_json(*cfg) : rig_config_to_yaml(*cfg));
  });
}

const CommandRegistrar registrar(90, setup);

}  // namespace
}  // namespace imucal::cli
