// SPDX-License-Identifier: BSD-3-Clause
#include "sim/camera_scene.hpp"

#include <cmath>
#include <cstring>

#include "sim/camera_render.hpp"
#include "sim/camimu.hpp"

namespace imucal::sim {
namespace {

constexpr std::uint64_t kNoiseSubstream = 0xCA3E7A;  // camera noise stream, independent of the IMU's

Eigen::Isometry3d pose_of(const RigState& s) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = s.q_world_body.toRotationMatrix();
  T.translation() = s.p_world_body;
  return T;
}

}  // namespace

SceneFrameSource::SceneFrameSource(const SimCameraScene& scene, const Trajectory& trajectory)
    : scene_(scene), trajectory_(trajectory), noise_(Rng::substream(scene.seed, kNoiseSubstream)) {}

Result<std::unique_ptr<SceneFrameSource>> SceneFrameSource::create(const SimCameraScene& scene,
                                                                   const CheckerboardMotion& motion) {
  return create(scene, motion, motion.T_world_board(scene.target));
}

Result<std::unique_ptr<SceneFrameSource>> SceneFrameSource::create(const SimCameraScene& scene,
                                                                   const Trajectory& trajectory,
                                                                   const Eigen::Isometry3d& T_world_board) {
  auto renderer = TargetRenderer::create(scene.camera, scene.target, scene.render);
  if (!renderer.ok()) return renderer.error();
  std::unique_ptr<SceneFrameSource> source(new SceneFrameSource(scene, trajectory));
  source->renderer_ = std::move(*renderer);
  source->T_world_board_ = T_world_board;
  return source;
}

SceneFrameSource::~SceneFrameSource() = default;

Result<drivers::camera::fake::FrameRenderer> make_scene_renderer(const SimCameraScene& scene,
                                                                 std::shared_ptr<const Trajectory> trajectory,
                                                                 const Eigen::Isometry3d& T_world_board) {
  if (!trajectory) return make_error(Errc::kInvalidArgument, "simulated camera: no motion");
  auto source = SceneFrameSource::create(scene, *trajectory, T_world_board);
  if (!source.ok()) return source.error();
  std::shared_ptr<SceneFrameSource> shared(std::move(*source));
  return drivers::camera::fake::FrameRenderer(
      [shared, trajectory](TimeNs t_mid, std::uint32_t, std::span<std::uint8_t> px) {
        return shared->render(t_mid, px);
      });
}

Eigen::Isometry3d SceneFrameSource::T_cam_board_at(TimeNs t_imu_ns) const {
  return scene_.T_cam_imu * pose_of(trajectory_.at(t_imu_ns)).inverse() * T_world_board_;
}

Status SceneFrameSource::render(TimeNs t_mid_host_ns, std::span<std::uint8_t> pixels) {
  const TimeNs t_mid_imu = t_mid_host_ns - scene_.host_offset_ns + s_to_ns(scene_.timeshift_cam_imu_s);
  const TimeNs t_open = t_mid_imu - scene_.exposure_ns / 2;
  int n_sub = 1;
  if (scene_.motion_blur) {
    n_sub =
        renderer_->sub_exposures_needed(T_cam_board_at(t_open), T_cam_board_at(t_open + scene_.exposure_ns));
  }
  subs_.clear();
  // A rolling shutter exposes row r from t_open + row_time(r) (the stamp's row at t_open).
  const Shutter& shutter = scene_.camera.shutter;
  const int rows = shutter.rolling() ? scene_.camera.height : 1;
  for (int i = 0; i < n_sub; ++i) {
    const double f = scene_.motion_blur ? (i + 0.5) / n_sub : 0.5;
    const TimeNs t = t_open + static_cast<TimeNs>(std::llround(f * scene_.exposure_ns));
    for (int r = 0; r < rows; ++r) {
      const double dt = shutter.row_time(r, scene_.camera.height);
      subs_.push_back(T_cam_board_at(t + static_cast<TimeNs>(std::llround(dt * 1e9))));
    }
  }
  const cv::Mat image =
      shutter.rolling() ? renderer_->render_rows(subs_, n_sub, &noise_) : renderer_->render(subs_, &noise_);
  const CornerTruth truth = renderer_->project_corners(T_cam_board_at(t_mid_imu));
  if (truth.visible_count == static_cast<int>(truth.px.size())) ++stats_.frames_all_points_visible;
  if (truth.visible_count == 0) ++stats_.frames_no_point_visible;
  {
    std::vector<Eigen::Vector2d> corners = truth.px;
    for (std::size_t i = 0; i < corners.size(); ++i)
      if (i >= truth.visible.size() || !truth.visible[i]) corners[i].setConstant(std::nan(""));
    std::lock_guard lock(recent_mutex_);
    recent_.emplace_back(t_mid_host_ns, std::move(corners));
    if (recent_.size() > 64) recent_.pop_front();
  }
  const std::size_t w = static_cast<std::size_t>(image.cols);
  if (pixels.size() != w * static_cast<std::size_t>(image.rows)) {
    return make_error(Errc::kInvalidArgument, "simulated camera: the buffer does not match the render size");
  }
  for (int r = 0; r < image.rows; ++r) {
    std::memcpy(pixels.data() + w * static_cast<std::size_t>(r), image.ptr<std::uint8_t>(r), w);
  }
  ++stats_.frames;
  return {};
}

std::optional<std::vector<Eigen::Vector2d>> SceneFrameSource::corners_at(TimeNs t_mid_host_ns) const {
  std::lock_guard lock(recent_mutex_);
  for (const auto& [t, corners] : recent_)
    if (t == t_mid_host_ns) return corners;
  return std::nullopt;
}

drivers::camera::fake::FrameRenderer SceneFrameSource::as_renderer(std::shared_ptr<SceneFrameSource> source) {
  return [source = std::move(source)](TimeNs t_mid, std::uint32_t, std::span<std::uint8_t> px) {
    return source->render(t_mid, px);
  };
}

}  // namespace imucal::sim
