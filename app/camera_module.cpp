// SPDX-License-Identifier: BSD-3-Clause
// The entry point of libimucal_camera.so (app/camera_module.hpp). Everything else in the module
// is hidden: it carries its own copies of the imucal libraries it needs.

#include "app/camera_module.hpp"

#include "core/version.hpp"

extern "C" __attribute__((visibility("default"))) const void* imucal_camera_module() {
  static const imucal::app::CameraModuleApi api{{imucal::kVersion, imucal::kModuleAbi},
                                                &imucal::app::calibrate_camera_log,
                                                &imucal::app::calibrate_camera_chain_log,
                                                &imucal::app::calibrate_camimu_log,
                                                &imucal::calib::TargetDetector::create};
  return &api;
}
