// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Camera intrinsic calibration from target observations: a camera of one of Kalibr's models
// (core/camera_model.hpp) and one target pose per view, by
// Levenberg-Marquardt on the reprojection errors (Ceres), with outlier views and corners
// rejected and the parameters' standard deviations from the solver covariance.
// Method, figures and their meaning: docs/camera-calibration.md.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "calib/target_detection.hpp"
#include "core/camera_model.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/target.hpp"
#include "core/time.hpp"

namespace imucal::calib {

/// Whether item k of n consecutive ones opens one of `slots` equal runs of them: the items for
/// which it holds are `slots` of them spread evenly, the first among them (every item when
/// n <= slots). The solve's start subset and a long recording's views are chosen by it.
inline bool opens_slot(long k, long n, long slots) {
  return n <= slots || k == 0 || k * slots / n != (k - 1) * slots / n;
}

struct CameraIntrinsicsOptions {
  CameraModelKind model{ProjectionModel::kPinhole, DistortionModel::kRadtan};
  /// Fewest usable views; fewer is refused (the pose of every view is unknown, and a handful of
  /// views at different tilts is what separates the focal length from the distance).
  int min_views = 5;
  /// Fewest target points for a view to be used (a pose has 6 unknowns).
  int min_points_per_view = 8;
  /// Robust loss of the first pass (Cauchy), scale in pixels.
  double robust_loss_px = 1.0;
  /// A view is dropped when its RMS is above view_rms_factor x the median view RMS and above
  /// view_rms_floor_px (a clean set has views within a small factor of each other).
  double view_rms_factor = 3.0;
  double view_rms_floor_px = 1.0;
  /// A corner is dropped when its residual is above corner_sigmas robust standard deviations
  /// (1.4826 x the median absolute residual per coordinate) and above corner_floor_px.
  double corner_sigmas = 5.0;
  double corner_floor_px = 0.5;
  /// Solver iterations per pass.
  int max_iterations = 100;
  /// The starts are solved on at most this many views, spread evenly over the recording; every
  /// view then joins from that solution, so that the passes over all of them begin at the
  /// solution and take a few iterations (0: every view from the start). Consecutive views of a
  /// recording repeat each other: the subset finds the same minimum.
  int start_views = 150;
  /// Coverage grid: the image is cut into coverage_cols columns and as many rows as make the
  /// cells about square.
  int coverage_cols = 10;
  /// Warn when the relative standard deviation of a focal length exceeds this.
  double max_focal_relative_sigma = 0.01;
  /// Threads for the solver (0 = all cores).
  int threads = 0;
  /// Compute the parameters' covariance (false: the sigmas are left not determined, for a
  /// solve that only starts another, such as the camera chain's).
  bool covariance = true;

  [[nodiscard]] Status validate() const;
};

/// What became of one view.
struct CameraViewReport {
  TimeNs t_ns = 0;
  int points = 0;       // target points observed
  int points_used = 0;  // after corner rejection
  double rms_px = 0.0;  // of the used points at the solution (or at rejection, for a dropped view)
  bool used = false;
  std::string rejected_because;  // empty when used
  /// The target's pose in the camera frame (p_cam = R_cam_target p_target + t_cam_target); set
  /// for used views.
  Eigen::Quaterniond q_cam_target = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t_cam_target = Eigen::Vector3d::Zero();
};

struct CameraIntrinsicsResult {
  CameraModel camera;
  /// Standard deviations of fu, fv, pu, pv, of the projection's parameters and of the distortion
  /// coefficients, from the covariance of the final solve scaled by the residual variance
  /// (sigma^2 = RSS / (n - p)); infinite where not determined, NaN for the entries the model does
  /// not have (kalibr_intrinsics and kalibr_distortion give the model's own, in Kalibr's order).
  Eigen::Vector4d intrinsics_sigma = Eigen::Vector4d::Zero();
  Eigen::Vector2d projection_sigma = Eigen::Vector2d::Zero();
  Eigen::Vector4d distortion_sigma = Eigen::Vector4d::Zero();
  /// The 10 x 10 covariance of [intrinsics, projection_params, distortion_coeffs] (0 in the rows
  /// and columns of the entries the model does not have).
  Eigen::Matrix<double, 10, 10> covariance = Eigen::Matrix<double, 10, 10>::Zero();
  bool covariance_ok = false;  // false: the problem is rank deficient (sigmas are infinite)

  double rms_px = 0.0;             // RMS of the used corners' reprojection errors (Euclidean, px)
  double residual_sigma_px = 0.0;  // sqrt(RSS / (n - p)), per coordinate
  int views_total = 0;
  int views_used = 0;
  int points_used = 0;
  int corners_rejected = 0;  // by the per-corner test, in the views kept
  std::vector<CameraViewReport> views;

  /// Fraction of the coverage grid's cells holding at least one used corner, and the grid
  /// itself (row-major, corners per cell).
  double coverage = 0.0;
  int coverage_cols = 0;
  int coverage_rows = 0;
  std::vector<int> coverage_counts;
  /// The reprojection residual (projected - detected, px) of each corner of the used views, or
  /// of every k-th in view order above kMaxStoredResiduals, and whether the corner test rejected
  /// it (1) or it was used (0), for the report's scatter and histogram.
  static constexpr int kMaxStoredResiduals = 20000;
  std::vector<Eigen::Vector2f> residuals_px;
  std::vector<std::uint8_t> residual_rejected;

  /// The focal lengths are determined (relative sigma below the option's limit, covariance of
  /// full rank). False for degenerate sets such as fronto-parallel views at one distance.
  bool focal_well_determined = false;
  /// Not empty when another start ended in a camera that fits the views as well (its cost
  /// within a chi-square of 4 of this one's) but lies beyond 3 sigmas of it: which of them the
  /// solve kept, the other, and that the covariance was widened by their difference (d d^T) to
  /// cover both (docs/camera-calibration.md, "Robust pass").
  std::string ambiguity;
  /// The profile check of the projection's first parameter (omni and ds xi, eucm alpha; docs/
  /// camera-calibration.md, "Uncertainty"): the least chi-square rise of the cost with it held 3
  /// sigmas away (9 for a quadratic valley; NaN: not checked) and the factor its sigma was
  /// stretched by (1: not stretched).
  double profile_chi2 = std::numeric_limits<double>::quiet_NaN();
  double profile_stretch = 1.0;
  std::vector<std::string> warnings;
  int iterations = 0;  // solver iterations over all passes
  double solve_cpu_s = 0.0;
};

/// Estimates the camera and the view poses from the observations of `target` (validated).
/// All observations must have the same image size; empty ones are ignored. Fails with
/// kInsufficientData (fewer usable views than options.min_views: the message says how many
/// were usable and why the others were not) or kSolverFailed. `progress` receives the fraction
/// of the passes done.
[[nodiscard]] Result<CameraIntrinsicsResult> calibrate_camera_intrinsics(
    const TargetDescription& target, std::span<const TargetObservation> observations,
    const CameraIntrinsicsOptions& options, const ProgressFn& progress);

/// The coverage grid of `result` (coverage_cols, _rows, _counts, coverage) from the used
/// corners `px` of a width x height image, `cols` columns and rows to make the cells about square.
void set_coverage(int width, int height, int cols, std::span<const Eigen::Vector2d> px,
                  CameraIntrinsicsResult* result);

/// The warnings a camera result deserves: focal length not determined (covariance of full
/// rank and relative sigma within options.max_focal_relative_sigma, else the views cannot tell
/// focal length from distance), coverage below half the grid, corners in fewer than half the
/// cells along the image's edges, more than a fifth of the views
/// rejected; each with what to record instead.
std::vector<std::string> camera_quality_warnings(const CameraIntrinsicsResult& result,
                                                 const CameraIntrinsicsOptions& options);

/// Sets the result's covariance (scaled; nullopt: not determined) and the sigmas from it: infinite
/// when not determined, NaN for the entries result->camera's model does not have.
void set_camera_covariance(const std::optional<Eigen::Matrix<double, 10, 10>>& covariance,
                           CameraIntrinsicsResult* result);

/// Kalibr's model name for the option: "pinhole-radtan", "pinhole-equi", "ds-none", ...
std::string camera_model_option_name(CameraModelKind model);
/// Parses Kalibr's model names (camera_model_name; also "radtan", "equidistant",
/// "pinhole-equidistant" for pinhole-radtan and pinhole-equi).
[[nodiscard]] Result<CameraModelKind> parse_camera_model_option(const std::string& text);
/// The candidates of `--model auto` (calib/camera_model_choice.hpp): Kalibr's models
/// pinhole-radtan, pinhole-equi, pinhole-fov, omni-none, omni-radtan, eucm-none, ds-none.
std::vector<CameraModelKind> default_model_candidates();

}  // namespace imucal::calib
