// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// YAML files for the readers of result files: a file read and parsed with one error form, and a
// YAML document as JSON for the readers that take either (a result YAML into the calibration
// record, a thermal YAML into the report).

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

#include "core/result.hpp"

namespace imucal {

/// Scalars become integers, then floating point (NaN as null: a figure not determined), then
/// booleans, else strings; a quoted scalar (tag "!") stays a string; YAML null is null.
nlohmann::json yaml_to_json(const YAML::Node& node);

/// The YAML document of a result file (at most kMaxResultFileBytes): the read's errors, or
/// kCorrupt "PATH: not valid YAML (...)".
[[nodiscard]] Result<YAML::Node> read_yaml_file(const std::string& path);

/// A matrix as a sequence of its rows, each in flow style (Kalibr's layout of T_cam_imu,
/// T_cn_cnm1 and the IMU matrices).
YAML::Node yaml_matrix_rows(const Eigen::MatrixXd& m);

}  // namespace imucal
