// SPDX-License-Identifier: BSD-3-Clause
#include "sim/virtual_cameras.hpp"

#include "sim/camimu.hpp"

namespace imucal::sim {

VirtualCameraTruth virtual_camera_truth(const CameraConfig& camera, std::size_t index) {
  VirtualCameraTruth t;
  t.camera = sim_camera_for(camera.width, camera.height);
  t.T_cam_imu = CamImuSimOptions::default_T_cam_imu();
  t.timeshift_cam_imu_s = kVirtualTimeshiftCamImuS;
  if (index > 0) {
    // The stereo partner of the first camera, on alternating sides for further ones.
    const CamImuSimCamera partner =
        CamImuSimOptions::default_stereo_camera(t.camera, t.T_cam_imu, t.timeshift_cam_imu_s, 0.0);
    t.camera = partner.camera;
    Eigen::Isometry3d T_cn_c0 = partner.T_cam_imu * t.T_cam_imu.inverse();
    const double reach = static_cast<double>((index + 1) / 2) * ((index % 2 == 1) ? 1.0 : -1.0);
    T_cn_c0.translation() *= reach;
    t.T_cam_imu = T_cn_c0 * t.T_cam_imu;
  }
  t.camera.shutter = camera.shutter;  // a rolling shutter renders each row at its own time
  return t;
}

SimCameraScene virtual_camera_scene(const CameraConfig& camera, const TargetDescription& target,
                                    std::uint64_t seed, std::size_t index, TimeNs host_offset_ns) {
  const VirtualCameraTruth truth = virtual_camera_truth(camera, index);
  SimCameraScene scene;
  scene.camera = truth.camera;
  scene.target = target;
  scene.T_cam_imu = truth.T_cam_imu;
  scene.timeshift_cam_imu_s = truth.timeshift_cam_imu_s;
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
