// SPDX-License-Identifier: BSD-3-Clause
// The entry point of libimucal_render.so (sim/render_module.hpp). Everything else in the module
// is hidden: it carries its own copies of the imucal libraries it needs.

#include "sim/render_module.hpp"

#include "core/version.hpp"

extern "C" __attribute__((visibility("default"))) const void* imucal_render_module() {
  static const imucal::sim::RenderModuleApi api{{imucal::kVersion, imucal::kModuleAbi},
                                                &imucal::sim::simulate_camimu_session,
                                                &imucal::sim::make_scene_renderer};
  return &api;
}
