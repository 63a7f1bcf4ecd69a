// SPDX-License-Identifier: BSD-3-Clause
#include "app/solvers.hpp"

#include "app/camera_module.hpp"
#include "app/module_loader.hpp"
#include "calib/solve_module.hpp"

namespace imucal::app {

std::future<void> load_static_solver_meanwhile() {
  return std::async(std::launch::async, [] {
    (void)load_module<calib::SolveModuleApi>(calib::kSolveModule, calib::kSolveModuleEntry);
  });
}

Status load_session_modules(bool cameras) {
  if (auto api = load_module<calib::SolveModuleApi>(calib::kSolveModule, calib::kSolveModuleEntry); !api.ok())
    return api.error();
  if (!cameras) return {};
  if (auto api = load_module<CameraModuleApi>(kCameraModule, kCameraModuleEntry); !api.ok())
    return api.error();
  return {};
}

Result<StaticCalibrationResult> calibrate_static(std::span<const ImuSample> samples,
                                                 const calib::StaticCalibrationOptions& options) {
  auto api = load_module<calib::SolveModuleApi>(calib::kSolveModule, calib::kSolveModuleEntry);
  if (!api.ok()) return api.error();
  return (*api)->static_calibration(samples, options);
}

Result<CameraCalibrationReport> calibrate_camera(const CameraCalibrationRequest& request) {
  auto api = load_module<CameraModuleApi>(kCameraModule, kCameraModuleEntry);
  if (!api.ok()) return api.error();
  return (*api)->calibrate_camera(request);
}

Result<CameraChainReport> calibrate_camera_chain(const CameraChainRequest& request) {
  auto api = load_module<CameraModuleApi>(kCameraModule, kCameraModuleEntry);
  if (!api.ok()) return api.error();
  return (*api)->calibrate_camera_chain(request);
}

Result<CamImuReport> calibrate_camimu(const CamImuRequest& request) {
  auto api = load_module<CameraModuleApi>(kCameraModule, kCameraModuleEntry);
  if (!api.ok()) return api.error();
  return (*api)->calibrate_camimu(request);
}

Result<std::unique_ptr<calib::TargetDetector>> make_target_detector(const TargetDescription& target,
                                                                    const calib::DetectionOptions& options) {
  auto api = load_module<CameraModuleApi>(kCameraModule, kCameraModuleEntry);
  if (!api.ok()) return api.error();
  return (*api)->target_detector(target, options);
}

}  // namespace imucal::app
