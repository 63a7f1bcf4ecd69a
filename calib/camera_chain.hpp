// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Several cameras calibrated together (a camera chain, as Kalibr's kalibr_calibrate_cameras):
// every camera's intrinsics, each camera's pose relative to cam0 and its time offset against
// cam0, from the views in which they see the target, in one least-squares solve on a
// continuous-time trajectory of the target relative to cam0. Cameras that are not synchronized,
// or that run at different rates, are placed on that trajectory by their time offsets; cameras
// that overlap only in part are chained through the cameras they share views with.
// Method, outputs and figures: docs/camera-calibration.md, "Several cameras".

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "calib/camera_intrinsics.hpp"
#include "calib/shutter_options.hpp"
#include "calib/target_detection.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/target.hpp"

namespace imucal::calib {

/// One camera of the chain: its name (for messages), model and detections in time order.
struct CameraChainInput {
  std::string name;
  CameraModelKind model{ProjectionModel::kPinhole, DistortionModel::kRadtan};
  std::vector<TargetObservation> observations;
  /// The camera's shutter as known (a rolling one's readout direction, stamped row and line
  /// delay to start from); what the solve does with it is CameraChainOptions::shutter.
  Shutter shutter;
};

struct CameraChainOptions {
  /// The single-camera solve that starts each camera (its rejection rules apply to the chain).
  CameraIntrinsicsOptions intrinsics;
  /// Estimate each camera's time offset against cam0 on the continuous-time trajectory. False:
  /// cameras triggered together (Kalibr's model): the offsets are 0 and every group of views
  /// with the same stamp (within shared_view_fraction of a frame interval) has its own pose of
  /// cam0, so that still pairs, taken seconds apart, are calibrated as they are.
  bool estimate_time_offsets = true;
  /// The starting search for an offset covers +- this (s).
  double max_time_offset_s = 0.1;
  /// Knot spacing of the trajectory (s); 0 = the shortest median frame interval of the cameras.
  double knot_spacing_s = 0.0;
  /// Two cameras share a view when their frames are at most this fraction of the longer frame
  /// interval apart (after the offset).
  double shared_view_fraction = 0.5;
  /// Fewest shared views for two cameras to be linked in the chain.
  int min_shared_views = 5;
  /// Robust loss scale of the first pass in corner sigmas; corners beyond reject_sigmas robust
  /// sigmas are then dropped and the final pass is plain least squares.
  double loss_sigmas = 3.0;
  double reject_sigmas = 5.0;
  int max_iterations = 100;
  int threads = 0;
  /// Rolling shutters (docs/camera-calibration.md, "Rolling shutter"): each corner at its row's
  /// time on the trajectory, the line delay estimated, held, or chosen by the evidence. Needs the
  /// trajectory (estimate_time_offsets); with one pose per instant every camera is global.
  ShutterSolveOptions shutter;

  [[nodiscard]] Status validate() const;
};

/// One camera's result in the chain.
struct CameraChainCameraResult {
  std::string name;
  /// The camera and its sigmas from the joint solve; the views, coverage and residual figures
  /// of this camera (views as its single-camera start used or rejected them).
  CameraIntrinsicsResult intrinsics;
  /// Pose relative to cam0 (p_cam = T_cam_cam0 p_cam0) and its 6 x 6 covariance (rotation as a
  /// right perturbation R <- R Exp(d), then translation; NaN where not determined). cam0:
  /// identity, covariance zero (it is the reference, not an estimate).
  Eigen::Isometry3d T_cam_cam0 = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> T_cam_cam0_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  /// Relative to the camera before it (Kalibr's T_cn_cnm1; n >= 1): the transform, the standard
  /// deviations of its rotation (rad, about its axes) and translation (m), and of the baseline
  /// |t| (m). NaN where not determined.
  Eigen::Isometry3d T_cn_cnm1 = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> T_cn_cnm1_covariance = Eigen::Matrix<double, 6, 6>::Zero();  // as T_cam_cam0's
  Eigen::Vector3d T_cn_cnm1_rotation_sigma_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d T_cn_cnm1_translation_sigma_m = Eigen::Vector3d::Zero();
  double baseline_m = 0.0;
  double baseline_sigma_m = 0.0;
  /// cam0's time of this camera's frame stamped t: t_cam0 = t + timeshift_cam0_s (cam0: 0).
  double timeshift_cam0_s = 0.0;
  double timeshift_sigma_s = 0.0;  // NaN: not determined; 0 for cam0 and when held
  bool timeshift_estimated = false;
  /// The camera it is chained through at the start (-1 for cam0), and the views it shares with
  /// each camera (index = camera).
  int linked_to = -1;
  std::vector<int> shared_views;
  /// Of this camera's views with the target, how many carry the same stamp as a view of cam0.
  int views_stamped_with_cam0 = 0;
  int views_used = 0;
  double rms_px = 0.0;  // of this camera's corners in the joint solve
  /// The shutter solved is intrinsics.camera.shutter; the line delay's sigma (s per row; NaN:
  /// global, held or not determined) and why this shutter.
  double line_delay_sigma_s = std::numeric_limits<double>::quiet_NaN();
  std::string shutter_choice;
};

struct CameraChainResult {
  std::vector<CameraChainCameraResult> cameras;
  double knot_spacing_s = 0.0;  // of the trajectory; 0 with one pose per stamp (offsets held)
  double rms_px = 0.0;          // all corners
  int iterations = 0;
  double solve_cpu_s = 0.0;
  std::vector<std::string> warnings;
};

/// Calibrates the chain (cam0 is the first; a single camera is calibrated on the trajectory, as a
/// rolling shutter needs). Errors: kInsufficientData
/// (a camera with too few views, or one that shares no views with the others: the message names
/// it and says what to record), kSolverFailed. `progress` receives the fraction done.
[[nodiscard]] Result<CameraChainResult> calibrate_camera_chain(const TargetDescription& target,
                                                               std::span<const CameraChainInput> cameras,
                                                               const CameraChainOptions& options,
                                                               const ProgressFn& progress);

}  // namespace imucal::calib
