// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the virtual rig's camera sees: the target fixed in the world, the rig moving along a
// checkerboard motion, the camera mounted at T_cam_imu, frames exposed around their stamps and
// shifted by timeshift_cam_imu. A SceneFrameSource renders the frames the virtual camera
// (drivers/camera/fake/virtual_camera.hpp) delivers; `imucal sim camimu` and `imucal record --sim`
// with cameras both use it.
//
// Conventions (docs/conventions.md): T_cam_imu maps IMU (body) points into the camera frame;
// t_imu = t_cam + timeshift_cam_imu.

#include <Eigen/Geometry>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <vector>

#include "core/camera_model.hpp"
#include "core/result.hpp"
#include "core/target.hpp"
#include "core/time.hpp"
#include "drivers/camera/fake/virtual_camera.hpp"
#include "sim/camera_render_options.hpp"
#include "sim/motion.hpp"
#include "sim/motion_random.hpp"

namespace imucal::sim {

class TargetRenderer;

struct SimCameraScene {
  CameraModel camera;
  TargetDescription target;
  Eigen::Isometry3d T_cam_imu = Eigen::Isometry3d::Identity();
  double timeshift_cam_imu_s = 0.0;
  TimeNs exposure_ns = 4'000'000;
  CameraRenderOptions render;
  bool motion_blur = true;
  /// Seeds the sensor noise (its own substream, independent of the IMU's).
  std::uint64_t seed = 1;
  /// Host time = trajectory (IMU) time + host_offset_ns.
  TimeNs host_offset_ns = 0;
};

/// Frame counts of a rendered session.
struct SceneFrameStats {
  std::int64_t frames = 0;
  std::int64_t frames_all_points_visible = 0;
  std::int64_t frames_no_point_visible = 0;
};

class SceneFrameSource {
 public:
  /// The motion is borrowed and must outlive the source; the board stands where the motion
  /// places it (CheckerboardMotion::T_world_board).
  [[nodiscard]] static Result<std::unique_ptr<SceneFrameSource>> create(const SimCameraScene& scene,
                                                                        const CheckerboardMotion& motion);
  /// Any trajectory (the guided session's operator), with the board at T_world_board.
  [[nodiscard]] static Result<std::unique_ptr<SceneFrameSource>> create(
      const SimCameraScene& scene, const Trajectory& trajectory, const Eigen::Isometry3d& T_world_board);
  ~SceneFrameSource();

  /// Renders the frame whose mid-exposure is at host time t_mid_host_ns into `pixels`
  /// (width * height bytes, rows of `width`). Frames must be rendered in order for the noise to
  /// be reproducible.
  [[nodiscard]] Status render(TimeNs t_mid_host_ns, std::span<std::uint8_t> pixels);

  /// The virtual camera's renderer: this source, shared.
  static drivers::camera::fake::FrameRenderer as_renderer(std::shared_ptr<SceneFrameSource> source);

  /// The target's points where the frame stamped (mid-exposure) at host time t_mid_host_ns shows
  /// them, by point id (NaN where a point is behind the camera or off the sensor): the truth of
  /// one of the last 64 frames rendered, for a check of what was drawn or detected; nothing for
  /// an older or unknown stamp. Safe beside render() on another thread.
  std::optional<std::vector<Eigen::Vector2d>> corners_at(TimeNs t_mid_host_ns) const;

  const SceneFrameStats& stats() const { return stats_; }
  const Eigen::Isometry3d& T_world_target() const { return T_world_board_; }

 private:
  SceneFrameSource(const SimCameraScene& scene, const Trajectory& trajectory);
  Eigen::Isometry3d T_cam_board_at(TimeNs t_imu_ns) const;

  SimCameraScene scene_;
  const Trajectory& trajectory_;
  std::unique_ptr<TargetRenderer> renderer_;
  Eigen::Isometry3d T_world_board_ = Eigen::Isometry3d::Identity();
  Rng noise_;
  std::vector<Eigen::Isometry3d> subs_;
  SceneFrameStats stats_;
  mutable std::mutex recent_mutex_;
  std::deque<std::pair<TimeNs, std::vector<Eigen::Vector2d>>> recent_;  // corners_at()
};

/// The virtual camera's renderer for `scene` along `trajectory` (kept alive by the renderer),
/// the board at T_world_board. The render module's entry for `imucal record --sim` with cameras
/// and for the service's virtual rig.
[[nodiscard]] Result<drivers::camera::fake::FrameRenderer> make_scene_renderer(
    const SimCameraScene& scene, std::shared_ptr<const Trajectory> trajectory,
    const Eigen::Isometry3d& T_world_board);

/// The simulated camera at another resolution: the default camera's lens (its field of view
/// across the width, its distortion) on a sensor of width x height, principal point centred.
CameraModel sim_camera_for(int width, int height);
/// A lens of `model` on that sensor (sim_camera_for's for pinhole-radtan): pinhole-equi, -fov and
/// -none of about 100 degrees across; omni-none and omni-radtan (xi 0.8) of about 120; eucm-none
/// (alpha 0.6, beta 1.1) and ds-none (xi -0.15, alpha 0.6) of about 195 degrees across the
/// width, the image circle filling the sensor's height.
CameraModel sim_camera_for(int width, int height, CameraModelKind model);

}  // namespace imucal::sim
