#include "sim/virtual_cameras.hpp"

#include "sim/camimu.hpp"

namespace imucal::sim {

SimCameraScene virtual_camera_scene(const CameraConfig& camera, const TargetDescription& target,
                                    std::uint64_t seed, std::size_t index, TimeNs host_offset_ns) {
  SimCameraScene scene;
  scene.camera = sim_camera_for(camera.width, camera.height);
  scene.target = target;
  scene.T_cam_imu = CamImuSimOptions::default_T_cam_imu();
  scene.timeshift_cam_imu_s = kVirtualTimeshiftCamImuS;
  scene.exposure_ns = kVirtualExposureNs;
  scene.seed = seed + index;
  scene.host_offset_ns = host_offset_ns;
  return scene;
}

Result<std::unique_ptr<drivers::camera::fake::VirtualCamera>> make_virtual_camera(
    const CameraConfig& camera, drivers::camera::fake::FrameRenderer renderer,
    const VirtualCameraTiming& timing) {
  drivers::camera::fake::VirtualCameraOptions vo;
  vo.id = camera.name;
  vo.width = camera.width;
  vo.height = camera.height;
  vo.rate_hz = camera.rate_hz;
  vo.exposure_ns = kVirtualExposureNs;
  vo.first_frame_ns = timing.first_frame_ns;
  vo.clock = timing.clock;
  if (timing.disconnect_after > 0) vo.disconnect_after = timing.disconnect_after;
  auto made = drivers::camera::fake::VirtualCamera::create(vo, std::move(renderer));
  if (!made.ok()) return made.error().context("camera " + camera.name);
  return made;
}

}  // namespace imucal::sim
