// SPDX-License-Identifier: BSD-3-Clause
// imucal export euroc LOG DIR: a session log as an EuRoC/ASL folder (docs/datasets.md).

#include <iostream>
#include <memory>

#include "app/results/output_checks.hpp"
#include "daemon/cli/command.hpp"
#include "log/dataset_io.hpp"

namespace imucal::cli {
namespace {

struct ExportOptions {
  std::string log_path;
  std::string dir;
  bool force = false;
  bool allow_damaged = false;
};

void setup(CLI::App& root) {
  CLI::App* exp = root.add_subcommand("export", "Export a session log to a dataset format");
  exp->require_subcommand(1);
  auto o = std::make_shared<ExportOptions>();
  CLI::App* cmd = exp->add_subcommand("euroc", "EuRoC/ASL folder: DIR/mav0/imuN/, DIR/mav0/camN/");
  cmd->add_option("LOG", o->log_path, "Session log (.imulog)")->required();
  cmd->add_option("DIR", o->dir, "Output folder (created)")->required();
  cmd->add_flag("--force", o->force, "Replace DIR if it already holds a dataset");
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Export what is readable from a damaged log");
  cmd->callback([o] {
    // DIR is replaced with --force: never when it holds the log.
    if (auto s = app::check_not_input(o->dir, {o->log_path}); !s.ok()) fail(s.error());
    Progress progress("exporting", 1.0);
    log::OutputOptions options;
    options.force = o->force;
    options.progress = [&progress](double fraction) { progress.update(fraction); };
    auto summary = log::export_euroc(o->log_path, o->dir, options, o->allow_damaged);
    progress.finish();
    if (!summary.ok()) fail(summary.error(), "export failed");
    std::cout << "exported " << summary->imu_samples << " IMU samples and " << summary->frames
              << " frames to " << o->dir << "/mav0\n";
    for (const auto& note : summary->notes) std::cout << "note: " << note << "\n";
  });
}

const CommandRegistrar registrar(41, setup);

}  // namespace
}  // namespace imucal::cli
