// SPDX-License-Identifier: BSD-3-Clause
// imucal report RESULT: one self-contained HTML page of a calibration result with its figures
// drawn by gnuplot, optionally the figures as PNG files (docs/report.md).

#include <iostream>
#include <memory>
#include <string>

#include "app/report/report.hpp"
#include "app/results/output.hpp"
#include "core/version.hpp"
#include "daemon/cli/bag_input.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

void run(const app::report::ReportOptions& given, const std::vector<std::string>& topics) {
  // A bag given as --log is read through its import (the calibration's, when the topics are the same);
  // the bag itself is an input no output may name.
  if (!given.log_path.empty()) {
    const app::OutputPolicy inputs{true, {given.log_path}};  // only "not an input": --force is checked after
    if (auto s = app::check_output(given.html_path, inputs); !s.ok()) fail(s.error());
  }
  app::report::ReportOptions options = given;
  if (!options.log_path.empty()) {
    options.log_path = log_of_input(given.log_path, topics);
    options.log_name = given.log_path;  // the page names the bag, not its import
  }
  auto summary = app::report::write_report(options);
  if (!summary.ok()) {
    // An existing output is refused in the CLI's own words.
    if (summary.error().code == Errc::kAlreadyExists)
      throw CliExit{kExitUsage, summary.error().message + ": pass --force to replace it"};
    fail(summary.error(), "report of " + options.result_path);
  }
  std::cout << "report (" << app::report::report_kind_name(summary->kind) << "): " << options.html_path
            << " (" << summary->figures << (summary->figures == 1 ? " figure)\n" : " figures)\n");
  if (!summary->png_files.empty())
    std::cout << "  " << summary->png_files.size() << " PNG figures in " << options.png_dir << "\n";
  for (const auto& note : summary->notes) std::cout << "  note: " << note << "\n";
  for (const auto& warning : summary->warnings) std::cerr << "warning: " << warning << "\n";
}

void setup(CLI::App& root) {
  CLI::App* cmd = root.add_subcommand(
      "report",
      "HTML report of a calibration result (static, Allan, camera or camera chain, camera-IMU, thermal), "
      "figures drawn by gnuplot");
  auto o = std::make_shared<app::report::ReportOptions>();
  o->generator = std::string("imucal ") + kVersion + " report";
  cmd->add_option(
         "RESULT", o->result_path,
         "Result JSON (calibrate static --json, allan --json, calibrate camera --json), calibrate "
         "camera's YAML (-o; its tables, no figures), calibrate camimu's output folder, or calibrate "
         "thermal's YAML")
      ->required();
  cmd->add_option("--log", o->log_path,
                  "The session log (or ROS bag) the result came from (signals, per-pose figures)");
  auto topics = std::make_shared<std::vector<std::string>>();
  add_bag_topics_option(cmd, topics.get());
  cmd->add_option("-o,--output", o->html_path, "The HTML report to write")->required();
  cmd->add_option("--png-dir", o->png_dir, "Also write every figure as a PNG file into this folder");
  cmd->add_flag("--force", o->overwrite, "Replace a report and PNG files that exist");
  cmd->callback([o, topics] { run(*o, *topics); });
}

const CommandRegistrar registrar(80, setup);

}  // namespace
}  // namespace imucal::cli
