// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera calibration's self-check (core/split_check.hpp), as the camera-IMU one
// (app/camimu_self_check.hpp): the views cut by time into consecutive parts, each part solved
// apart with the whole solve's choices (model, shutter), the parts side by side, and every
// camera's intrinsics, its pose relative to the camera before it, its time offset and line delay
// compared against their sigmas. Compiled into the camera module. Docs:
// docs/camera-calibration.md, "Self-check".

#include <string>
#include <vector>

#include "calib/camera_chain.hpp"
#include "calib/camera_intrinsics.hpp"
#include "core/split_check.hpp"
#include "core/target.hpp"

namespace imucal::app {

/// One camera: its views solved per part as the whole was (per-view poses, or on the trajectory
/// with the line delay when the whole found a rolling shutter). `name` prefixes the parameters.
SplitCheck camera_self_check(const TargetDescription& target,
                             const std::vector<calib::TargetObservation>& views,
                             const calib::CameraIntrinsicsOptions& options,
                             const calib::CameraIntrinsicsResult& full, const std::string& name, int parts,
                             int threads);

/// A chain: every camera's views of a part (by its own stamps, cut at cam0's times).
SplitCheck chain_self_check(const TargetDescription& target,
                            const std::vector<calib::CameraChainInput>& cameras,
                            const calib::CameraChainOptions& options, const calib::CameraChainResult& full,
                            int parts, int threads);

/// The factor a group's sigmas are scaled by: sqrt(chi-square / dof) of the parameters whose
/// names start with `prefix` when their probability is below 5 %, recorded in check->scaled
/// under `who` with a note in `notes`; else 1 (and nothing recorded). The camera-IMU self-check
/// uses it too.
double split_scale(SplitCheck* check, const std::string& prefix, const std::string& who,
                   std::vector<std::string>* notes);

/// Scales, per camera whose parameters spread with a chi-square probability below 5 %, its
/// intrinsics' and relative pose's sigmas (and covariance) by sqrt(chi-square / dof); returns the
/// notes that say so.
std::vector<std::string> scale_chain_by_self_check(calib::CameraChainResult* chain, SplitCheck* check);
std::vector<std::string> scale_camera_by_self_check(calib::CameraIntrinsicsResult* camera,
                                                    double* line_delay_sigma_s, const std::string& name,
                                                    SplitCheck* check);

}  // namespace imucal::app
