// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The estimators that need Ceres, called through the solver module libimucal_solve.so
// (app/module_loader.hpp), so that programs load Ceres and its BLAS/LAPACK/SuiteSparse chain only
// when they solve.

#include <future>
#include <memory>
#include <span>

#include "app/camera_calibration.hpp"
#include "app/camimu_calibration.hpp"
#include "calib/static_calibration.hpp"
#include "calib/target_detection.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// Starts loading the solver module on another thread (about 10 ms of the dynamic loader's work),
/// for a caller with other work to do first, such as reading the log. The result is only waited
/// for: a load that failed is tried again, and reported, by calibrate_static.
[[nodiscard]] std::future<void> load_static_solver_meanwhile();

/// Loads the modules a session solves with (the solver module; the camera module too with
/// `cameras`) when it starts: a loaded module stays mapped, so a package upgrade during the
/// session replaces the files on disk but not what the session solves with, and a module that
/// cannot be loaded refuses the start instead of the solve after the recording.
[[nodiscard]] Status load_session_modules(bool cameras);

/// calib::calibrate_static; fails with the loader's error when the module cannot be loaded.
[[nodiscard]] Result<StaticCalibrationResult> calibrate_static(
    std::span<const ImuSample> samples, const calib::StaticCalibrationOptions& options);

/// app::calibrate_camera_log through the camera module libimucal_camera.so (detection and the
/// intrinsics solve); fails with the loader's error when the module cannot be loaded.
[[nodiscard]] Result<CameraCalibrationReport> calibrate_camera(const CameraCalibrationRequest& request);

/// app::calibrate_camera_chain_log through the camera module (several cameras in one solve).
[[nodiscard]] Result<CameraChainReport> calibrate_camera_chain(const CameraChainRequest& request);

/// app::calibrate_camimu_log through the camera module libimucal_camera.so (detection and the
/// camera-IMU estimator); fails with the loader's error when the module cannot be loaded.
[[nodiscard]] Result<CamImuReport> calibrate_camimu(const CamImuRequest& request);
/// A target detector (calib::TargetDetector::create) from the camera module, for live detection
/// (the service's motion step); fails with the loader's error when the module cannot be loaded.
[[nodiscard]] Result<std::unique_ptr<calib::TargetDetector>> make_target_detector(
    const TargetDescription& target, const calib::DetectionOptions& options = {});

}  // namespace imucal::app
