// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The documents of each kind of report (internal to app/report): what they show and the gnuplot
// scripts of their figures. report.cpp reads the inputs, picks one, draws and writes.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/report/gnuplot.hpp"
#include "app/report/html.hpp"
#include "core/result.hpp"

namespace YAML {
class Node;
}

namespace imucal::app::report {

/// Where the document's inputs are, and what was left out of it (shown on stdout).
struct BuildContext {
  std::string result_path;
  std::string log_path;  // empty: no log given
  std::vector<std::string> notes;
  bool log_in_progress = false;  // ReportOptions::log_in_progress
  std::string log_name;          // ReportOptions::log_name
  const std::string& shown_log() const { return log_name.empty() ? log_path : log_name; }
};

[[nodiscard]] Result<Document> static_document(const nlohmann::json& result, BuildContext& ctx);
[[nodiscard]] Result<Document> allan_document(const nlohmann::json& result, BuildContext& ctx);
[[nodiscard]] Result<Document> camera_document(const nlohmann::json& result, BuildContext& ctx);
/// A camera chain: calibrate camera --json of several cameras, or the camchain YAML of one or
/// several (calibrate camera -o) as camera_chain_from_yaml gives it.
[[nodiscard]] Result<Document> camera_chain_document(const nlohmann::json& result, BuildContext& ctx);
[[nodiscard]] Result<Document> camimu_document(const nlohmann::json& result, BuildContext& ctx);
[[nodiscard]] Result<Document> thermal_document(const nlohmann::json& result, BuildContext& ctx);

/// A camchain YAML (cam0 ... camN with imucal's figures under camN.imucal) in the shape of
/// calibrate camera --json of several cameras, without the views the YAML does not keep.
nlohmann::json camera_chain_from_yaml(const YAML::Node& camchain);

/// The session log's summary (rig, recording, streams, health) as a section; errors name the log.
/// `in_progress`: the log is still being written, so an open end is expected. `shown`: what the
/// page calls the log (a bag, when log_path is its import); empty: log_path.
[[nodiscard]] Result<Section> session_section(const std::string& log_path, bool in_progress = false,
                                              const std::string& shown = {});

// Reading result JSON: errors (kCorrupt) name the key, thrown as JsonError and caught by the
// document builders, which turn them into Result errors naming the file.
struct JsonError {
  std::string message;
};
const nlohmann::json& at(const nlohmann::json& j, const char* key);
double number(const nlohmann::json& j, const char* key);
Eigen::Vector3d vec3(const nlohmann::json& j);
Eigen::Matrix3d mat3(const nlohmann::json& j);

/// Reprojection residuals of one camera (or one class of corners), a flat dx, dy list in px.
struct ResidualSeries {
  std::string name;
  std::vector<double> px;
  double loss_px = 0.0;  // the robust loss's scale, drawn as a dashed circle; 0: none
  std::string colour;
};
/// A scatter of the residuals and a histogram of their lengths; `what` (how many corners the
/// series are of) starts the caption's counts. Empty when no series has a residual.
Figure reprojection_figure(const std::string& id, const std::vector<ResidualSeries>& series,
                           const std::string& what);

/// The result's self-check (core/split_check.hpp, the "self_check" object) as a section: the
/// verdict, the advice, any scaled sigmas and every compared parameter in every part; a section
/// without a title when the result has none or it was not run.
Section self_check_section(const nlohmann::json& result);

/// Gnuplot's line colours used across the report for x, y, z (colour-blind safe).
inline constexpr const char* kAxisColour[3] = {"#0072b2", "#d55e00", "#009e73"};

}  // namespace imucal::app::report
