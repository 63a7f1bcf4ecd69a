#pragma once
// The virtual rig's camera: renders a printed checkerboard (core/target.hpp, cols x rows inner
// corners, the (cols+1) x (rows+1) squares around them and a white margin) as an 8-bit grey
// image through a distorting camera model (core/camera_model.hpp).
//
// Image formation, per pixel: n x n sub-pixel samples; each sample's ray (the distorted camera's
// ray, precomputed once per camera from unproject() with its derivatives across the pixel) is
// intersected with the board plane, and the board's reflectance is integrated exactly over the
// sample's footprint on the board, approximated by an axis-aligned box of the same extent
// (separable integrals of the square wave; no aliasing, and the filter is point-symmetric so
// edges and corners stay where the geometry puts them). Motion blur averages sub-exposure
// renders over the exposure; Gaussian sensor noise (sigma in grey levels) is added before
// rounding to 8 bits. See docs/simulator-camera.md.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <span>
#include <vector>

#include "core/camera_model.hpp"
#include "core/result.hpp"
#include "core/target.hpp"
#include "sim/camera_render_options.hpp"
#include "sim/motion_random.hpp"

namespace imucal::sim {

/// Projected inner corners of one frame: the ground truth a corner detector should find.
struct CornerTruth {
  std::vector<Eigen::Vector2d> px;    // index r * cols + c, as TargetDescription::corner_points()
  std::vector<std::uint8_t> visible;  // 1 when in front and on the sensor
  int visible_count = 0;
};

class CheckerboardRenderer {
 public:
  /// Validates the inputs and precomputes the per-pixel rays (the costly part, done once per
  /// camera). The target must be a checkerboard.
  [[nodiscard]] static Result<std::unique_ptr<CheckerboardRenderer>> create(
      const CameraModel& camera, const TargetDescription& target, const CameraRenderOptions& options);

  /// Noise-free irradiance (CV_32F, grey levels, lens blur included) of the board at pose
  /// T_cam_target (board points -> camera frame).
  void render_irradiance(const Eigen::Isometry3d& T_cam_target, cv::Mat* irradiance) const;

  /// An 8-bit frame: the average of the irradiance at the given sub-exposure poses (one pose:
  /// no motion blur), plus noise from `rng` (unused when noise_sigma_dn is 0), rounded and
  /// clamped to [0, 255].
  [[nodiscard]] cv::Mat render(std::span<const Eigen::Isometry3d> T_cam_target_sub_exposures, Rng* rng) const;

  /// Projection of the inner corners at one pose.
  CornerTruth project_corners(const Eigen::Isometry3d& T_cam_target) const;

  /// Number of sub-exposures that keeps the image motion between successive ones below
  /// `max_step_px` for the board moving from T_begin to T_end during the exposure (1..64).
  int sub_exposures_needed(const Eigen::Isometry3d& T_cam_target_begin,
                           const Eigen::Isometry3d& T_cam_target_end, double max_step_px = 0.25) const;

  const CameraModel& camera() const { return camera_; }
  const TargetDescription& target() const { return target_; }
  const CameraRenderOptions& options() const { return options_; }
  /// Pixels whose ray the model cannot produce (outside its invertible region); they show the
  /// background.
  int invalid_pixels() const { return invalid_pixels_; }

 private:
  CheckerboardRenderer() = default;
  void accumulate(const Eigen::Isometry3d& T_cam_target, float weight, float* out) const;
  void apply_optics(cv::Mat* irradiance) const;

  CameraModel camera_;
  TargetDescription target_;
  CameraRenderOptions options_;
  std::vector<Eigen::Vector3d> corner_points_;
  // Per pixel, row-major: the ray through the pixel centre and its derivatives with respect to
  // the pixel coordinates u and v (rays scaled to unit length at the centre).
  std::vector<double> rays_;  // 9 doubles per pixel: r, dr/du, dr/dv
  std::vector<std::uint8_t> ray_valid_;
  int invalid_pixels_ = 0;
};

}  // namespace imucal::sim
