// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The static calibration's result files (docs/static-calibration.md): YAML and JSON, for the CLI
// and the rig service, and the g-sensitivity matrix read back from one.

#include <Eigen/Core>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/static_calibration.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// The g-sensitivity matrix G (rad/s per m/s^2) of a YAML file: `canonical: G:` of a static
/// result written by static_result_yaml, or a top-level `G:` (3 rows of 3). Errors name the file.
[[nodiscard]] Result<Eigen::Matrix3d> read_gsens_matrix(const std::string& path);

/// What a stored record takes of a static result (static_result_yaml, or static_result_json),
/// typed: the stream (name, units) in `info`, and in `result` the canonical model, the triads'
/// sigmas, the g-sensitivity's mode and sigma, gravity and the thermal model the samples were
/// corrected with. The result's other fields keep their defaults.
struct StaticResultFile {
  ImuStreamInfo info;
  calib::StaticCalibrationResult result;
};
/// `root`: the file as JSON (yaml_to_json). Errors: kCorrupt naming `origin` and the key.
[[nodiscard]] Result<StaticResultFile> parse_static_result(const nlohmann::json& root,
                                                           const std::string& origin);

/// Static calibration as YAML: the canonical form, the triads with their sigmas, quality.
std::string static_result_yaml(const calib::StaticCalibrationResult& result, const ImuStreamInfo& info);

/// Static calibration as JSON (indented, ending in a newline): the YAML's content plus the
/// Tedaldi angles, the static intervals, quality before and after, warnings, CPU timings and
/// the log's "software_version" from `log_metadata` when present.
std::string static_result_json(const calib::StaticCalibrationResult& result, const ImuStreamInfo& info,
                               const std::string& gravity_source,
                               const std::map<std::string, std::string>& log_metadata);

}  // namespace imucal::app
