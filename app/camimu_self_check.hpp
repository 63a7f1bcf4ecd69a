// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera-IMU self-check (core/split_check.hpp): the recording's frames cut into consecutive
// parts of equal duration, each part calibrated apart with the full solve's choices (IMU model,
// knot spacing, shutters, noise), the parts solved in parallel on the detections already found,
// and their extrinsics, time offsets, line delays and IMU intrinsics compared against their
// sigmas. Compiled into the camera module with the estimator. Docs: docs/camimu-calibration.md.

#include <vector>

#include "calib/camimu_calibration.hpp"
#include "core/camimu_calibration.hpp"
#include "core/split_check.hpp"
#include "core/target.hpp"

namespace imucal::app {

/// Calibrates `parts` consecutive parts of the recording (2..8) and judges them (SplitCheck).
/// `full` is the whole recording's result: its choices are the parts' options, and its
/// rotations the reference the parts' rotations are compared about. `threads` are shared out
/// among the parts. Never fails: a part that cannot be calibrated is named in part_errors.
SplitCheck camimu_self_check(const std::vector<calib::CamImuSample>& imu,
                             const std::vector<calib::CamImuCameraInput>& cameras,
                             const TargetDescription& target, const calib::CamImuOptions& options,
                             const CamImuCalibrationResult& full, int parts, int threads);

}  // namespace imucal::app
