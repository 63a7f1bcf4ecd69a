#include "daemon/cli/calibrate_group.hpp"

namespace imucal::cli {

CLI::App* calibrate_group(CLI::App& root) {
  auto found = root.get_subcommands([](CLI::App* app) { return app->get_name() == "calibrate"; });
  if (!found.empty()) return found.front();
  CLI::App* group =
      root.add_subcommand("calibrate", "Estimate a calibration from a session log, or check given ones");
  group->require_subcommand(1);
  return group;
}

}  // namespace imucal::cli
