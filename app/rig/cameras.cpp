// SPDX-License-Identifier: BSD-3-Clause
#include "app/rig/cameras.hpp"

#include "app/module_loader.hpp"
#include "drivers/camera/aravis/aravis_module.hpp"
#include "drivers/camera/libcamera/libcamera_module.hpp"
#include "drivers/camera/v4l2/v4l2_camera.hpp"

namespace imucal::app {

namespace cam = drivers::camera;

namespace {

Result<std::unique_ptr<cam::Camera>> open_backend(const CameraConfig& c) {
  switch (c.backend) {
    case CameraBackend::kV4l2:
      return cam::open_v4l2_camera(c.device);
    case CameraBackend::kAravis: {
      auto api = load_module<cam::AravisModuleApi>(cam::kAravisModule, cam::kAravisModuleEntry);
      if (!api.ok()) return api.error();
      cam::AravisOptions o;
      o.fake_interface = c.device.rfind("Fake_", 0) == 0;  // Aravis's own fake camera, for demos
      return (*api)->open(c.device, o);
    }
    case CameraBackend::kLibcamera: {
      auto api = load_module<cam::LibcameraModuleApi>(cam::kLibcameraModule, cam::kLibcameraModuleEntry);
      if (!api.ok()) return api.error();
      return (*api)->open(c.device, cam::LibcameraOptions{});
    }
    case CameraBackend::kSim:
      break;
  }
  return make_error(Errc::kInvalidArgument,
                    "backend sim is the virtual rig's camera; record it with --sim (imu.bus: sim)");
}

}  // namespace

Result<std::unique_ptr<cam::Camera>> open_camera(const CameraConfig& c) {
  const std::string what = "camera " + c.name + " (" + camera_backend_name(c.backend) + " " + c.device + ")";
  auto camera = open_backend(c);
  if (!camera.ok()) return camera.error().context("opening " + what);
  auto st = (*camera)->set_format({c.width, c.height, c.pixel_format, c.rate_hz});
  if (!st.ok()) return st.error().context("configuring " + what);
  return camera;
}

Result<OpenedCameras> open_rig_cameras(const RigConfig& config) {
  OpenedCameras out;
  for (const CameraConfig& c : config.cameras) {
    auto camera = open_camera(c);
    if (!camera.ok()) return camera.error();
    acq::RecordCamera rc;
    rc.camera = camera->get();
    rc.info.name = c.name;
    rc.info.backend = camera_backend_name(c.backend);
    rc.info.device = c.device;
    out.record.push_back(rc);
    out.cameras.push_back(std::move(*camera));
  }
  return out;
}

}  // namespace imucal::app
