// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The record of a continuous-time camera-IMU calibration (Krebs 2012, the lineage of Furgale and
// Rehder's Kalibr): every camera's extrinsics and time offset, the IMU's intrinsics in the Krebs
// form and in the canonical form, the gravity, each with its standard deviation, and the quality
// figures. It lives in core, with Eigen only, beside the static record (core/imu_calibration.hpp),
// so that storage, reports and the service can read and write it without linking the estimator;
// calib/camimu_calibration.hpp produces it.
//
// Conventions (docs/conventions.md): T_cam_imu maps points from the IMU body frame (the
// accelerometer frame of the Krebs model: x along the accelerometer x axis, y in its x-y plane)
// into the camera frame; t_imu = t_cam + timeshift_cam_imu (Kalibr's sign).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <string>
#include <vector>

#include "core/camera_model.hpp"
#include "core/imu_model.hpp"
#include "core/split_check.hpp"
#include "core/time.hpp"

namespace imucal {

/// A standard deviation that could not be determined (written as null in JSON, "not determined"
/// on screens): never 0, which would claim a perfectly known value.
inline constexpr double kNotDetermined = std::numeric_limits<double>::quiet_NaN();

/// Which IMU model the camera-IMU problem estimates.
enum class CamImuModelKind {
  kBasic,     // biases only: S = I, M = I, C_bg = I, B_g = 0 (Kalibr's "calibrated" IMU)
  kExtended,  // Krebs 2012, ch. 3: S_g, M_g, C_bg, B_g, S_a, M_a and the biases
  kAuto,      // a request only: basic or extended, whichever the data support (the result says)
};
inline const char* camimu_model_name(CamImuModelKind kind) {
  switch (kind) {
    case CamImuModelKind::kBasic:
      return "basic";
    case CamImuModelKind::kExtended:
      return "extended";
    default:
      return "auto";
  }
}

/// One camera of the rig as calibrated against the IMU.
struct CamImuCameraResult {
  std::string name = "cam0";
  std::string stream;  // the camera stream of the log
  CameraModel camera;  // intrinsics used (fixed in the problem) and the shutter solved
  Eigen::Isometry3d T_cam_imu = Eigen::Isometry3d::Identity();
  /// Standard deviations: rotation as a small-angle vector about the camera axes (rad), i.e.
  /// of delta in R_cam_imu = exp(delta) R_est, and translation (m), camera frame. NaN: not
  /// determined (held fixed, or the recording does not determine it; never 0).
  Eigen::Vector3d rotation_sigma_rad = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d translation_sigma_m = Eigen::Vector3d::Constant(kNotDetermined);
  double timeshift_cam_imu_s = 0.0;
  double timeshift_sigma_s = kNotDetermined;
  /// The shutter solved is camera.shutter (its line delay as estimated or held); the line
  /// delay's sigma (s per row; NaN: global, held, or not determined) and why this shutter.
  double line_delay_sigma_s = kNotDetermined;
  std::string shutter_choice;
  /// How the held intrinsics' own uncertainty entered the sigmas above ("propagated: ...", or
  /// "not known: ..." when the camera file gives none), and their share of the rotation and
  /// translation sigmas (NaN: not propagated).
  std::string intrinsics_uncertainty;
  Eigen::Vector3d rotation_sigma_from_intrinsics_rad = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d translation_sigma_from_intrinsics_m = Eigen::Vector3d::Constant(kNotDetermined);
  int frames = 0;           // frames with the target that entered the problem
  int corners = 0;          // corner observations that entered the problem
  int outlier_corners = 0;  // down-weighted by the robust loss (residual above its scale)
  /// Stamps of the frames left out because their target pose contradicts the gyro (a detection
  /// in the wrong order or a mirrored planar pose), ascending.
  std::vector<TimeNs> rejected_frames;
  double reprojection_rms_px = 0.0;
  double corner_sigma_px = 0.0;  // the corner noise the problem assumed
  /// The reprojection residual (projected - detected, px) of every corner, or of every k-th
  /// corner in time order when there are more than kMaxStoredResiduals, for the report's scatter
  /// and histogram; outlier_px is the robust loss's scale (a residual above it was down-weighted).
  static constexpr int kMaxStoredResiduals = 20000;
  std::vector<Eigen::Vector2f> residuals_px;
  double outlier_px = 0.0;
};

/// Standard deviations of the Krebs-form IMU parameters; NaN where not determined (a fixed block,
/// or a direction the recording does not determine), never 0.
struct KrebsImuSigma {
  Eigen::Vector3d S_a = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d M_a = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d b_a = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d S_g = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d M_g = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d C_bg = Eigen::Vector3d::Constant(kNotDetermined);  // small-angle vector of C_bg, rad
  Eigen::Matrix3d B_g = Eigen::Matrix3d::Constant(kNotDetermined);
  Eigen::Vector3d b_g = Eigen::Vector3d::Constant(kNotDetermined);
};

/// The biases along the recording (the bias splines sampled), for reports.
struct BiasSample {
  TimeNs t_ns = 0;
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
};

/// The IMU signals as measured and as one model predicts them from the solved trajectory,
/// biases and gravity (Krebs 2012, figures 5.6 and 5.7), for the report: every k-th sample in
/// time order when there are more than kMaxSamples. The RMS of measured - predicted is over every
/// sample of the problem.
struct ImuSignalFit {
  /// "basic": the first stage, IMU intrinsics (S, M, C_bg, B_g) held at their start;
  /// "extended": after the final stage, intrinsics as estimated (absent for the basic model).
  std::string model;
  static constexpr std::size_t kMaxSamples = 2000;
  std::vector<TimeNs> t_ns;
  std::vector<Eigen::Vector3f> accel_measured, accel_predicted;  // m/s^2
  std::vector<Eigen::Vector3f> gyro_measured, gyro_predicted;    // rad/s
  Eigen::Vector3d accel_residual_rms = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_residual_rms = Eigen::Vector3d::Zero();
};

struct CamImuQuality {
  /// RMS of the IMU residuals after the solve, per axis (m/s^2, rad/s), and the white-noise
  /// standard deviation per sample the problem assumed.
  Eigen::Vector3d accel_residual_rms = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_residual_rms = Eigen::Vector3d::Zero();
  double accel_sigma = 0.0;
  double gyro_sigma = 0.0;
  /// The per-sample sigmas the given noise figures imply (imu.yaml or the datasheet); they differ
  /// from accel_sigma / gyro_sigma when the residuals disagreed with them by more than a factor
  /// two and the problem was weighted with the residuals' own RMS instead (noise_from_residuals).
  double accel_sigma_given = 0.0;
  double gyro_sigma_given = 0.0;
  bool accel_noise_from_residuals = false;
  bool gyro_noise_from_residuals = false;
  /// Excitation: RMS of the angular rate and of the specific force without its mean (gravity),
  /// per body axis (rad/s, m/s^2).
  Eigen::Vector3d rotation_excitation_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_excitation_mps2 = Eigen::Vector3d::Zero();
  /// Time-offset initialisation: the cross-correlation of angular speeds (lag s, value) and the
  /// lag it peaked at, per camera.
  std::vector<std::vector<std::pair<double, double>>> xcorr;
  std::vector<double> xcorr_peak_s;
  int iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double solve_s = 0.0;       // wall time of the full solve (without the initialisation)
  double init_s = 0.0;        // wall time of the initialisation
  double covariance_s = 0.0;  // wall time of the covariance
  /// The cluster-robust covariance: its time blocks (s) and how many there were (0: the plain
  /// covariance only, docs/camimu-calibration.md "Uncertainty").
  double covariance_cluster_s = 0.0;
  int covariance_clusters = 0;
  double jacobian_s = 0.0;  // of the solve: residual and Jacobian evaluation
  double linear_solver_s = 0.0;
  /// IMU samples averaged into one residual (1: every sample its own), and the residuals: above
  /// CamImuOptions::imu_max_rate_hz the per-sample figures above are those of the averages.
  int imu_samples_per_residual = 1;
  /// The pose spline's knot spacing (s), whether it was chosen from the motion, and the gyro-fit
  /// residual sigma of each candidate spacing it was chosen by (rad/s; empty when given).
  double knot_spacing_s = 0.0;
  bool knot_spacing_chosen = false;
  std::vector<double> gyro_fit_sigma_radps;
  int imu_residuals = 0;
  int parameters = 0;  // estimated, in the tangent space
  int residuals = 0;
  int spline_knots = 0;
};

struct CamImuCalibrationResult {
  CamImuModelKind model = CamImuModelKind::kExtended;
  std::vector<CamImuCameraResult> cameras;
  /// The IMU in the Krebs form (biases at the start of the recording; S, M, C_bg, B_g constant)
  /// and in the canonical form (output frame = the Krebs body frame), both on the nominal SI
  /// values of the stream (raw counts already converted with the stream's nominal scale).
  KrebsImuModel imu;
  KrebsImuSigma imu_sigma;
  CanonicalImuModel canonical;
  /// Which blocks were held fixed ("S_a", "M_a", "S_g", "M_g", "C_bg", "B_g", "T_cam_imu",
  /// "timeshift"), as given or implied by the model.
  std::vector<std::string> fixed;
  /// Gravity in the world (target) frame, m/s^2; its direction's sigma (rad, two tangent axes).
  Eigen::Vector3d gravity_w = Eigen::Vector3d(0, 0, -kStandardGravityMps2);
  Eigen::Vector2d gravity_sigma_rad = Eigen::Vector2d::Constant(kNotDetermined);
  std::vector<BiasSample> biases;
  std::vector<ImuSignalFit> signal_fits;  // "basic" then "extended" (extended model), or "basic"
  CamImuQuality quality;
  /// Why the model is the one it is: forced by the request, or chosen by the evidence (the
  /// criterion's figures, docs/camimu-calibration.md "Model choice").
  std::string model_choice;
  /// The prior on the extended model's intrinsics (about the starting model), its source, and
  /// the parameters it mostly set (their sigma above half the prior's: the data hardly moved
  /// them). Sigmas NaN where a block had no prior (fixed, or the basic model).
  std::string prior_source;
  KrebsImuSigma prior_sigma;
  std::vector<std::string> prior_dominated;
  /// The directions the recording does not determine, in words (their sigmas are NaN).
  std::vector<std::string> undetermined;
  std::vector<std::string> warnings;  // observability, residuals, outliers
  /// The parts of the recording calibrated apart and compared (app/camimu_self_check.hpp);
  /// verdict kNotRun when not asked for.
  SplitCheck self_check;

  static constexpr double kStandardGravityMps2 = 9.80665;
};

}  // namespace imucal
