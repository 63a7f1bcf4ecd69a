// SPDX-License-Identifier: BSD-3-Clause
// The entry point of libimucal_aravis.so (drivers/camera/aravis/aravis_module.hpp). Everything
// else in the module is hidden: it carries its own copies of the imucal libraries it needs.

#include "drivers/camera/aravis/aravis_module.hpp"

#include "core/version.hpp"

namespace {

imucal::Result<std::unique_ptr<imucal::drivers::camera::Camera>> open_camera(
    const std::string& id, const imucal::drivers::camera::AravisOptions& options) {
  auto camera = imucal::drivers::camera::open_aravis_camera(id, options);
  if (!camera.ok()) return camera.error();
  return std::unique_ptr<imucal::drivers::camera::Camera>(std::move(*camera));
}

}  // namespace

extern "C" __attribute__((visibility("default"))) const void* imucal_aravis_module() {
  static const imucal::drivers::camera::AravisModuleApi api{
      {imucal::kVersion, imucal::kModuleAbi}, &open_camera, &imucal::drivers::camera::list_aravis_cameras};
  return &api;
}
