// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Initialisation of the camera-IMU problem without a prior (Furgale et al. 2013; Kalibr does the
// same steps): camera poses from the target by PnP, the camera's angular rate by differencing
// them, the time offset from the cross-correlation of the angular speeds of camera and
// gyroscope (both rotation-invariant), and the camera-IMU rotation (with a gyro bias) by least
// squares on the angular velocities at that offset.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <utility>
#include <vector>

#include "calib/target_detection.hpp"
#include "core/camera_model.hpp"
#include "core/target.hpp"

namespace imucal::calib::camimu {

/// A camera pose from one frame: world (= target) from camera.
struct FramePose {
  TimeNs t_ns = 0;   // camera stamp
  double t_s = 0.0;  // camera stamp, s from the problem's origin
  Eigen::Matrix3d R_wc = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p_wc = Eigen::Vector3d::Zero();
  double rms_px = 0.0;  // reprojection RMS of the PnP pose
};

/// PnP on each observation with at least `min_corners` corners (on undistorted rays, so any
/// camera model works). Observations whose pose is not found or reprojects worse than
/// `max_rms_px` are left out. `t0_ns` is the problem's time origin.
std::vector<FramePose> pnp_poses(const CameraModel& camera,
                                 const std::vector<TargetObservation>& observations,
                                 const std::vector<Eigen::Vector3d>& target_points, TimeNs t0_ns,
                                 int min_corners, double max_rms_px);

/// Angular velocity of the camera in its own frame between consecutive poses no further apart
/// than `max_gap_s`, stamped at the midpoint.
struct RateSample {
  double t_s = 0.0;
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
};
std::vector<RateSample> camera_rates(const std::vector<FramePose>& poses, double max_gap_s);

/// The gyro rate (mean over the samples within half a camera interval of t_s), for the
/// correlation and the alignment. `gyro_t_s` ascending.
class GyroLookup {
 public:
  GyroLookup(std::vector<double> t_s, std::vector<Eigen::Vector3d> w);
  /// False when t_s is outside the samples.
  bool at(double t_s, double half_window_s, Eigen::Vector3d* w) const;
  /// The angle (rad) the gyro turned through from t0_s to t1_s (the raw rates integrated,
  /// times rounded to the nearest sample); false when either is outside the samples.
  bool turn_angle(double t0_s, double t1_s, double* angle) const;
  /// The largest angular speed (rad/s) of the samples within [t0_s, t1_s] (0 when none).
  double max_speed(double t0_s, double t1_s) const;

 private:
  std::size_t nearest(double t_s) const;

  std::vector<double> t_;
  std::vector<Eigen::Vector3d> w_;
  std::vector<Eigen::Quaterniond> q_;  // the rates integrated from the first sample
};

/// Frames whose target pose contradicts the gyro: the angle between the orientations of two
/// frames does not depend on the unknown camera-IMU rotation, so it must match the angle the
/// gyro turned through between their stamps (at `shift_s`, t_imu = t_cam + shift). Every frame
/// is compared with the others within `window_s`; a pair disagrees when the angles differ by
/// more than 0.35 rad + 2 shift_uncertainty_s x (the fastest gyro rate around it). A frame that
/// disagrees with most of at least two others is a wrong detection (corners found in the wrong
/// order, or the mirror solution of a planar pose). Returns their indices into `poses`,
/// ascending.
std::vector<std::size_t> poses_against_gyro(const std::vector<FramePose>& poses, const GyroLookup& gyro,
                                            double shift_s, double shift_uncertainty_s, double window_s);

struct TimeshiftEstimate {
  double shift_s = 0.0;                          // t_imu = t_cam + shift
  double peak = 0.0;                             // normalised correlation at the peak
  std::vector<std::pair<double, double>> curve;  // (lag s, normalised correlation)
};
/// Lags from -max_shift_s to +max_shift_s in 1 ms steps, refined by a parabola through the peak.
TimeshiftEstimate correlate_timeshift(const std::vector<RateSample>& camera, const GyroLookup& gyro,
                                      double half_window_s, double max_shift_s);

struct RotationEstimate {
  Eigen::Matrix3d R_cam_imu = Eigen::Matrix3d::Identity();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
  double rms_radps = 0.0;
  int pairs = 0;
};
/// w_cam = R_cam_imu (w_gyro - b): Kabsch on the rates, then Gauss-Newton with the bias.
RotationEstimate align_rotation(const std::vector<RateSample>& camera, const GyroLookup& gyro, double shift_s,
                                double half_window_s);

}  // namespace imucal::calib::camimu
