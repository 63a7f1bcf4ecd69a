// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The six-orientation g-sensitivity experiment's result files (YAML and JSON, docs/gsens.md).

#include <string>

#include "calib/gsens_calibration.hpp"
#include "core/imu.hpp"

namespace imucal::app {

/// Where a g-sensitivity result's inputs come from, written with it.
struct GSensProvenance {
  std::string models;          // "nominal conversion" or the --imu-intrinsics file
  std::string gravity_source;  // app::GravityChoice::source
};

/// The six-orientation g-sensitivity result as YAML: a top-level `G:` (3 rows of 3, rad/s per
/// m/s^2, what read_gsens_matrix and `calibrate static --gsens fix` read), G_sigma, b_g and its
/// sigma, the models used, the noise, residual figures and the holds.
std::string gsens_result_yaml(const GSensitivityResult& result, const ImuStreamInfo& info,
                              const GSensProvenance& provenance);
/// The same as JSON (indented, ending in a newline), with the full covariance and the warnings.
std::string gsens_result_json(const GSensitivityResult& result, const ImuStreamInfo& info,
                              const GSensProvenance& provenance);

}  // namespace imucal::app
