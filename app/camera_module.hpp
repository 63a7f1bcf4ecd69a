#pragma once
// The camera module, libimucal_camera.so: target detection over a log's frames (OpenCV,
// libapriltag) and the camera intrinsics solve (Ceres), loaded by the programs only for the
// camera calibration (app/module_loader.hpp, app::calibrate_camera in app/solvers.hpp). Tests
// link imucal_app_camera directly.

#include "app/camera_calibration.hpp"
#include "core/module.hpp"

namespace imucal::app {

inline constexpr const char* kCameraModule = "imucal_camera";
inline constexpr const char* kCameraModuleEntry = "imucal_camera_module";

struct CameraModuleApi {
  ModuleHeader header;
  decltype(&calibrate_camera_log) calibrate_camera;
};

}  // namespace imucal::app
