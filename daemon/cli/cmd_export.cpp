// SPDX-License-Identifier: BSD-3-Clause
// imucal export euroc LOG DIR | export bag LOG BAG: a session log as an EuRoC/ASL folder or a
// ROS 1 bag (docs/datasets.md).

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

  auto b = std::make_shared<ExportOptions>();
  auto compression = std::make_shared<std::string>("none");
  CLI::App* bag = exp->add_subcommand(
      "bag", "ROS 1 bag as Kalibr reads it: /imuN (sensor_msgs/Imu), /camN/image_raw (sensor_msgs/Image)");
  bag->add_option("LOG", b->log_path, "Session log (.imulog)")->required();
  bag->add_option("BAG", b->dir, "Output bag file")->required();
  bag->add_option("--compression", *compression, "Chunk compression: none, bz2 or lz4 (default none)")
      ->check(CLI::IsMember({"none", "bz2", "lz4"}));
  bag->add_flag("--force", b->force, "Replace BAG if it exists");
  bag->add_flag("--allow-damaged", b->allow_damaged, "Export what is readable from a damaged log");
  bag->callback([b, compression] {
    if (auto s = app::check_not_input(b->dir, {b->log_path}); !s.ok()) fail(s.error());
    Progress progress("exporting", 1.0);
    log::OutputOptions options;
    options.force = b->force;
    options.progress = [&progress](double fraction) { progress.update(fraction); };
    const auto kind = *compression == "bz2"   ? log::BagCompression::kBz2
                      : *compression == "lz4" ? log::BagCompression::kLz4
                                              : log::BagCompression::kNone;
    auto summary = log::export_bag(b->log_path, b->dir, options, b->allow_damaged, kind);
    progress.finish();
    if (!summary.ok()) fail(summary.error(), "export failed");
    std::cout << "exported " << summary->imu_samples << " IMU samples and " << summary->frames
              << " frames to " << b->dir << "\n";
    for (const auto& note : summary->notes) std::cout << "note: " << note << "\n";
  });
}

const CommandRegistrar registrar(41, setup);

}  // namespace
}  // namespace imucal::cli
