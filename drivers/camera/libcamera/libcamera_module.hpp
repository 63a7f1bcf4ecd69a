// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The libcamera camera module, libimucal_libcamera.so: the libcamera backend
// (libcamera_camera.hpp), loaded by a program only when a rig names a libcamera camera
// (app/module_loader.hpp). Tests link imucal_camera_libcamera directly.

#include <memory>
#include <string>
#include <vector>

#include "core/module.hpp"
#include "core/result.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/camera/libcamera/libcamera_camera.hpp"

namespace imucal::drivers::camera {

inline constexpr const char* kLibcameraModule = "imucal_libcamera";
inline constexpr const char* kLibcameraModuleEntry = "imucal_libcamera_module";

struct LibcameraModuleApi {
  ModuleHeader header;
  /// open_libcamera_camera behind the Camera interface.
  Result<std::unique_ptr<Camera>> (*open)(const std::string& id, const LibcameraOptions& options);
  /// list_libcamera_cameras.
  Result<std::vector<std::string>> (*list)();
};

}  // namespace imucal::drivers::camera
