// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// `imucal report`: one self-contained HTML page (figures embedded as SVG data URIs, no network)
// of a calibration result (static, Allan, camera or camera chain, camera-IMU, thermal), with its figures
// drawn by gnuplot; optionally the same figures as PNG files. The kind of result is read from the file's
// content. docs/report.md describes each kind.

#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "core/result.hpp"

namespace imucal::app::report {

/// The results a report is made of.
enum class ReportKind {
  kStatic,       // imucal calibrate static --json
  kAllan,        // imucal allan --json
  kCamImu,       // imucal calibrate camimu: OUT_DIR/result.json
  kCamera,       // imucal calibrate camera --json
  kCameraChain,  // imucal calibrate camera --json of several cameras, or its YAML (-o) of one or several
  kThermal,      // imucal calibrate thermal -o (YAML)
};
const char* report_kind_name(ReportKind kind);

/// The kind of a parsed result, from the keys it has. Errc::kCorrupt naming `origin` when the
/// content is no result imucal writes.
[[nodiscard]] Result<ReportKind> detect_report_kind(const nlohmann::json& result, const std::string& origin);

struct ReportOptions {
  std::string result_path;  // a result JSON, or a folder holding result.json (camimu)
  std::string log_path;     // the session log the result came from; empty: figures from it are left out
  std::string
      log_name;  // what the page calls the log (a ROS bag, when log_path is its import); empty: log_path
  std::string html_path;   // the report
  std::string png_dir;     // empty: no PNG files
  bool overwrite = false;  // replace an existing report and PNG files
  std::string generator;   // shown at the foot of the page ("imucal 0.3.0")
  /// The log is still being written (a session report drawn before the session ends): its
  /// missing end is not reported as an interrupted recording.
  bool log_in_progress = false;
};

struct ReportSummary {
  ReportKind kind = ReportKind::kStatic;
  int figures = 0;
  std::vector<std::string> png_files;
  std::vector<std::string> notes;  // what was left out and why (no --log, ...)
  /// Figures gnuplot could not draw from the result's data (empty or out-of-range values): the
  /// page holds a note in their place, and the rest of the report is complete.
  std::vector<std::string> warnings;
};

/// Reads the result (and the log), draws the figures and writes the page (and the PNGs).
/// Errors: kNotFound / kCorrupt for the inputs, kInvalidArgument / kAlreadyExists for outputs
/// that may not be written, kUnsupported when gnuplot is missing, kIo when an output cannot be
/// written. A figure gnuplot fails to draw is a warning (ReportSummary::warnings), not an error.
[[nodiscard]] Result<ReportSummary> write_report(const ReportOptions& options);

}  // namespace imucal::app::report
