// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera module, libimucal_camera.so: target detection over a log's frames (OpenCV,
// libapriltag), the camera intrinsics solve and the camera-IMU calibration (Ceres), loaded by the
// programs only for these calibrations (app/module_loader.hpp, app::calibrate_camera and
// app::calibrate_camimu in app/solvers.hpp). Tests link imucal_app_camera directly.

#include "app/camera_calibration.hpp"
#include "app/camimu_calibration.hpp"
#include "calib/target_detection.hpp"
#include "core/module.hpp"

namespace imucal::app {

inline constexpr const char* kCameraModule = "imucal_camera";
inline constexpr const char* kCameraModuleEntry = "imucal_camera_module";

struct CameraModuleApi {
  ModuleHeader header;
  decltype(&calibrate_camera_log) calibrate_camera;
  decltype(&calibrate_camera_chain_log) calibrate_camera_chain;
  decltype(&calibrate_camimu_log) calibrate_camimu;
  decltype(&calib::TargetDetector::create) target_detector;
};

}  // namespace imucal::app
