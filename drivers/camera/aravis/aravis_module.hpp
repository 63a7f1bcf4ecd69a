// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The Aravis camera module, libimucal_aravis.so: the GenICam backend (aravis_camera.hpp) with
// Aravis and glib, loaded by a program only when a rig names an Aravis camera
// (app/module_loader.hpp). Tests link imucal_camera_aravis directly.

#include <memory>
#include <string>
#include <vector>

#include "core/module.hpp"
#include "core/result.hpp"
#include "drivers/camera/aravis/aravis_camera.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::drivers::camera {

inline constexpr const char* kAravisModule = "imucal_aravis";
inline constexpr const char* kAravisModuleEntry = "imucal_aravis_module";

struct AravisModuleApi {
  ModuleHeader header;
  /// open_aravis_camera behind the Camera interface.
  Result<std::unique_ptr<Camera>> (*open)(const std::string& id, const AravisOptions& options);
  /// list_aravis_cameras.
  std::vector<std::string> (*list)(bool fake_interface);
};

}  // namespace imucal::drivers::camera
