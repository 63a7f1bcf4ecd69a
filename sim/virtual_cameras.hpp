// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig's cameras, assembled in one place for `imucal record --sim` and the service's
// virtual rig (sim/service_rig.hpp): each configured camera becomes a virtual camera
// (drivers/camera/fake) of the configured size and rate whose renderer draws the configured target
// through the simulated lens at that size. The first camera is mounted at
// CamImuSimOptions::default_T_cam_imu; every further one is its stereo partner
// (CamImuSimOptions::default_stereo_camera: 11 cm along cam0's x axis, its own intrinsics), the
// second beside it on the other side, and so on. All stamp on the rig's clock
// kVirtualTimeshiftCamImuS late.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>

#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "core/target.hpp"
#include "core/time.hpp"
#include "drivers/camera/fake/virtual_camera.hpp"
#include "sim/camera_scene.hpp"

namespace imucal::sim {

/// How long each virtual frame is exposed.
inline constexpr TimeNs kVirtualExposureNs = 4'000'000;

/// The virtual cameras' time offset, t_imu = t_cam + timeshift_cam_imu (docs/conventions.md): a
/// frame stamped t_cam on the rig's clock shows the scene of 4 ms earlier, as with a camera whose
/// driver stamps a frame after its exposure. The camera-IMU calibration finds it.
inline constexpr double kVirtualTimeshiftCamImuS = -0.004;

/// The truth of the rig's camera number `index` (virtual_cameras.hpp's header): its camera model
/// (with the configured shutter), T_cam_imu and time offset.
struct VirtualCameraTruth {
  CameraModel camera;
  Eigen::Isometry3d T_cam_imu = Eigen::Isometry3d::Identity();
  double timeshift_cam_imu_s = 0.0;
};
VirtualCameraTruth virtual_camera_truth(const CameraConfig& camera, std::size_t index);

/// What the rig's camera number `index` sees: its truth (virtual_camera_truth), the target, its
/// own noise (seed + index). Host time is trajectory time + host_offset_ns.
SimCameraScene virtual_camera_scene(const CameraConfig& camera, const TargetDescription& target,
                                    std::uint64_t seed, std::size_t index, TimeNs host_offset_ns = 0);

struct VirtualCameraTiming {
  /// Host time of frame 0's mid-exposure.
  TimeNs first_frame_ns = 0;
  /// The rig's simulated clock; empty: real time.
  std::function<TimeNs()> clock;
  /// After this many frames the camera is gone (a yanked cable); 0: never.
  std::uint32_t disconnect_after = 0;
};

/// The virtual camera of `camera` delivering what `renderer` draws. Its format is its own size in
/// GREY at the configured rate; the caller sets the configured format where it must be checked.
[[nodiscard]] Result<std::unique_ptr<drivers::camera::fake::VirtualCamera>> make_virtual_camera(
    const CameraConfig& camera, drivers::camera::fake::FrameRenderer renderer,
    const VirtualCameraTiming& timing);

}  // namespace imucal::sim
