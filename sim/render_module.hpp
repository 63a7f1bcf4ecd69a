// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The renderer module, libimucal_render.so: the simulated camera-IMU session, whose camera
// renderer needs OpenCV, loaded by the CLI only for `sim camimu` (app/module_loader.hpp).

#include "core/module.hpp"
#include "sim/camera_scene.hpp"
#include "sim/camimu.hpp"

namespace imucal::sim {

inline constexpr const char* kRenderModule = "imucal_render";
inline constexpr const char* kRenderModuleEntry = "imucal_render_module";

struct RenderModuleApi {
  ModuleHeader header;
  decltype(&simulate_camimu_session) camimu_session;
  decltype(&make_scene_renderer) scene_renderer;
};

}  // namespace imucal::sim
