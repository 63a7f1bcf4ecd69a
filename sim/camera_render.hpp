// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig's camera: renders a printed calibration target (core/target.hpp) as an 8-bit
// grey image through a distorting camera model (core/camera_model.hpp). Two targets:
//   checkerboard: cols x rows inner corners, the (cols+1) x (rows+1) squares around them and a
//     white margin, printed on the board's z < 0 side;
//   aprilgrid: Kalibr's AprilGrid as kalibr_create_target_pdf prints it (tag36h11 tags with a
//     2-bit black border, small black squares in the gaps at the tag corners, a white margin),
//     printed on the board's z > 0 side (Kalibr's frame: x right and y up on the printed page).
//
// Image formation, per pixel: n x n sub-pixel samples; each sample's ray (the distorted camera's
// ray, precomputed once per camera from unproject() with its derivatives across the pixel) is
// intersected with the board plane, and the board's reflectance is integrated exactly over the
// sample's footprint on the board, approximated by an axis-aligned box of the same extent (no
// aliasing, and the filter is point-symmetric so edges and corners stay where the geometry puts
// them). The checkerboard integrates in closed form (separable integrals of the square wave);
// the AprilGrid's reflectance is piecewise constant on an axis-aligned grid of cells and
// integrates as the sum over the cells the box overlaps of value x overlap area. Motion blur
// averages sub-exposure renders over the exposure; Gaussian sensor noise (sigma in grey levels)
// is added before rounding to 8 bits. See docs/simulator-camera.md.

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

/// Projected target points of one frame: the ground truth a detector should find.
struct CornerTruth {
  /// Index = point id of TargetDescription::points(): r * cols + c for a checkerboard's inner
  /// corners; for an AprilGrid the four corners of every tag (TargetDescription::tag_point_ids).
  std::vector<Eigen::Vector2d> px;
  std::vector<std::uint8_t> visible;  // 1 when in front and on the sensor
  int visible_count = 0;
};

class TargetRenderer {
 public:
  /// Validates the inputs and precomputes the per-pixel rays (the costly part, done once per
  /// camera) and, for an AprilGrid, its cells.
  [[nodiscard]] static Result<std::unique_ptr<TargetRenderer>> create(const CameraModel& camera,
                                                                      const TargetDescription& target,
                                                                      const CameraRenderOptions& options);

  /// Noise-free irradiance (CV_32F, grey levels, lens blur included) of the board at pose
  /// T_cam_target (board points -> camera frame).
  void render_irradiance(const Eigen::Isometry3d& T_cam_target, cv::Mat* irradiance) const;

  /// An 8-bit frame: the average of the irradiance at the given sub-exposure poses (one pose:
  /// no motion blur), plus noise from `rng` (unused when noise_sigma_dn is 0), rounded and
  /// clamped to [0, 255].
  [[nodiscard]] cv::Mat render(std::span<const Eigen::Isometry3d> T_cam_target_sub_exposures, Rng* rng) const;

  /// A rolling-shutter frame: `sub_exposures` sub-exposures of every row, the pose of row r in
  /// sub-exposure i at T_cam_target_rows[i * height + r]; otherwise as render().
  [[nodiscard]] cv::Mat render_rows(std::span<const Eigen::Isometry3d> T_cam_target_rows, int sub_exposures,
                                    Rng* rng) const;

  /// Projection of every target point (TargetDescription::points()) at one pose.
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
  TargetRenderer() = default;
  /// Adds weight x the board's irradiance at one pose to the pixels [first, last) (row-major).
  void accumulate(const Eigen::Isometry3d& T_cam_target, float weight, float* out, std::size_t first,
                  std::size_t last) const;
  void accumulate(const Eigen::Isometry3d& T_cam_target, float weight, float* out) const {
    accumulate(T_cam_target, weight, out, 0, ray_valid_.size());
  }
  template <class Pattern>
  void accumulate_pattern(const Pattern& pattern, const Eigen::Matrix3d& R, const Eigen::Vector3d& o,
                          float weight, float* out, std::size_t first, std::size_t last) const;
  /// Optics, noise and rounding of an accumulated irradiance.
  cv::Mat finish(cv::Mat* irradiance, Rng* rng) const;
  void apply_optics(cv::Mat* irradiance) const;
  [[nodiscard]] Status build_aprilgrid_cells();

  CameraModel camera_;
  TargetDescription target_;
  CameraRenderOptions options_;
  std::vector<Eigen::Vector3d> points_;  // TargetDescription::points()
  // AprilGrid: reflectance (grey levels) on the cells between sorted edges along board x and y;
  // cell i along x spans (edges_x_[i - 1], edges_x_[i]), the first and last cells reach to
  // infinity (background). Row-major, (edges_y_.size() + 1) rows of (edges_x_.size() + 1).
  std::vector<double> edges_x_;
  std::vector<double> edges_y_;
  std::vector<double> cell_dn_;
  // Per pixel, row-major: the ray through the pixel centre and its derivatives with respect to
  // the pixel coordinates u and v (rays scaled to unit length at the centre).
  std::vector<double> rays_;  // 9 doubles per pixel: r, dr/du, dr/dv
  std::vector<std::uint8_t> ray_valid_;
  int invalid_pixels_ = 0;
};

/// The renderer's name from when it drew checkerboards only.
using CheckerboardRenderer = TargetRenderer;

}  // namespace imucal::sim
