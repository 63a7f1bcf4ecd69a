// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Continuous-time camera-IMU calibration with the extended IMU model (Krebs 2012, chapters 3-5;
// Furgale, Rehder and Siegwart's batch formulation). The body pose is a uniform cumulative
// B-spline on SO(3) x R^3 (calib/spline.hpp) and the biases are R^3 B-splines; the problem joins
// the reprojection of the target corners at t_cam + timeshift, the gyroscope and accelerometer
// residuals of the IMU model, the bias random walk and the gravity direction, solved by
// Levenberg-Marquardt in Ceres. Method, defaults and measurements: docs/camimu-calibration.md.
//
// Inputs are the IMU samples in nominal SI (raw counts converted with the stream's nominal
// scale), the target detections of each camera with their camera stamps, and each camera's
// intrinsics (held fixed). The result record is core/camimu_calibration.hpp.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "calib/shutter_options.hpp"
#include "calib/target_detection.hpp"
#include "core/camera_model.hpp"
#include "core/camimu_calibration.hpp"
#include "core/imu_model.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/target.hpp"

namespace imucal::calib {

/// One IMU sample, nominal SI (m/s^2, rad/s).
struct CamImuSample {
  TimeNs t_ns = 0;
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
};

/// One camera: its intrinsics and its target detections (t_ns = the frame's camera stamp).
struct CamImuCameraInput {
  std::string name = "cam0";
  std::string stream;
  CameraModel camera;
  std::vector<TargetObservation> observations;
  /// The covariance of the held intrinsics in the solves' layout [fu fv pu pv, projection (2),
  /// distortion (4)] (10 x 10, from the camera's own calibration, 0 in the rows the model does not
  /// use; NaN rows where it did not determine one), propagated into the
  /// result's sigmas (CamImuOptions::propagate_intrinsics); empty: not known, left out. The
  /// source names it in the result (CamImuCameraResult::intrinsics_uncertainty), or says why
  /// there is none.
  Eigen::MatrixXd intrinsics_covariance;
  std::string intrinsics_covariance_source;
};

/// IMU noise in Kalibr's continuous-time units (imu.yaml; `imucal allan` measures them).
struct CamImuNoise {
  double accel_noise_density = 0.0039;  // m/s^2/sqrt(Hz), MPU-6000 datasheet (400 ug/sqrt(Hz))
  double accel_random_walk = 1e-4;      // m/s^3/sqrt(Hz)
  double gyro_noise_density = 8.73e-5;  // rad/s/sqrt(Hz), MPU-6000 datasheet (0.005 dps/sqrt(Hz))
  double gyro_random_walk = 2e-5;       // rad/s^2/sqrt(Hz)
};

/// Blocks that may be held fixed at their initial value.
struct CamImuFixed {
  bool S_a = false, M_a = false, S_g = false, M_g = false, C_bg = false, B_g = false;
  bool T_cam_imu = false;
  bool timeshift = false;
};

/// A Gaussian prior on the extended model's IMU intrinsics, about the starting model (imu_init,
/// else S = 1, M = 0, C_bg = I, B_g = 0), as standard deviations per entry. It bounds what a weakly
/// excited recording cannot determine, and is negligible where the data are strong. The default
/// is an MPU-6000's datasheet tolerances taken as one standard deviation (docs/camimu-calibration.md,
/// "Priors"). A block held fixed has no prior.
struct CamImuIntrinsicsPrior {
  bool enabled = true;
  double scale = 0.03;         // S_a, S_g: relative (datasheet: sensitivity tolerance +-3 %)
  double misalignment = 0.02;  // M_a, M_g entries, rad (datasheet: cross-axis sensitivity +-2 %)
  double gyro_axes = 0.02;     // C_bg, rad about each axis (the two triads of one die)
  double gsens = 1.75e-4;      // B_g entries, rad/s per m/s^2 (datasheet: 0.1 deg/s per g)
  std::string source = "MPU-6000 datasheet tolerances";
};

/// Camera n's pose relative to camera n - 1 from a camera chain (imucal calibrate camera with
/// several cameras), with its 6 x 6 covariance (rotation as a right perturbation about camera
/// n's axes, then translation, m): a Gaussian prior on T_cam_imu[n] T_cam_imu[n - 1]^-1, so that
/// the pair's baseline comes from the chain's views where those know it better than the IMU.
struct CamImuChainPrior {
  int camera = 1;  // n >= 1
  Eigen::Isometry3d T_cn_cnm1 = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  std::string source;  // for messages
};

/// The cameras' shutters in the solve (docs/camimu-calibration.md, "Rolling shutter").
using CamImuShutterOptions = ShutterSolveOptions;

/// The ranges CamImuOptions::validate() accepts, one per option; `calibrate camimu`'s checks
/// and its --help use the same, and it validates before the camera module loads.
struct CamImuLimits {
  static constexpr int kMinSplineOrder = 4;          // cubic
  static constexpr int kMaxSplineOrder = 6;          // quintic
  static constexpr double kMinKnotSpacingS = 0.005;  // or 0: chosen from the motion
  static constexpr double kMaxKnotSpacingS = 0.5;
  static constexpr double kMinBiasKnotSpacingS = 0.05;  // and at least the knot spacing
  static constexpr double kMaxBiasKnotSpacingS = 60.0;
  static constexpr double kMaxCornerSigmaPx = 50.0;  // 0: estimated
  static constexpr double kMinImuMaxRateHz = 20.0;   // or 0: one residual per sample
  static constexpr double kMaxImuMaxRateHz = 100000.0;
  static constexpr double kMaxCovarianceClusterS = 3600.0;
  static constexpr int kMaxIterations = 10000;
};

struct CamImuOptions {
  /// kAuto: basic or extended by the evidence of the IMU residuals (docs/camimu-calibration.md,
  /// "Model choice"); the result says which and why.
  CamImuModelKind model = CamImuModelKind::kAuto;
  CamImuIntrinsicsPrior prior;
  /// IMU samples above this rate are averaged in groups of k = floor(rate / imu_max_rate_hz)
  /// consecutive samples, one residual per group at its mean time: the spline (knots every
  /// 0.05 s) cannot follow what the average removes, the group's white noise is that of a
  /// sensor with the same noise density at rate / k, and a 1 kHz IMU costs no more than a
  /// 200 Hz one (docs/camimu-calibration.md, "Speed"). 0 = one residual per sample.
  double imu_max_rate_hz = 200.0;
  /// Weight the IMU residuals with their own RMS when it differs from the sigma the noise figures
  /// imply by more than a factor two (false: keep the given figures and only warn).
  bool imu_noise_from_residuals = true;
  /// Pose spline: order (degree + 1) and knot spacing; bias splines: their own spacing.
  int spline_order = 4;
  /// 0: chosen from the motion (calib/camimu_imu_prep.hpp choose_knot_spacing), else the spacing in s.
  double knot_spacing_s = 0.0;
  double bias_knot_spacing_s = 1.0;
  CamImuNoise noise;
  /// Corner noise (pixels, standard deviation per coordinate); 0 = estimated per camera from
  /// the reprojection residuals (from the PnP poses to start, then after the first stage), so
  /// the weights and the sigmas follow what the detector really delivers. The Cauchy loss
  /// scale is given in these sigmas.
  double corner_sigma_px = 0.0;
  double reprojection_loss_sigmas = 3.0;
  double gravity_mps2 = 9.80665;
  /// Initial values and priors. An IMU model given here is the starting point (and the fixed
  /// value of fixed blocks); without one S = I, M = 0, C_bg = I, B_g = 0 and the biases are
  /// estimated from the data.
  std::optional<KrebsImuModel> imu_init;
  CamImuFixed fixed;
  /// Initial extrinsics and time offset per camera (by index); absent: found by the
  /// initialisation (rotation from angular velocities, offset from the cross-correlation).
  std::vector<std::optional<Eigen::Isometry3d>> T_cam_imu_init;
  std::vector<std::optional<double>> timeshift_init_s;
  CamImuShutterOptions shutter;
  /// Camera-camera extrinsics from a camera chain (empty: each camera through the IMU alone).
  std::vector<CamImuChainPrior> chain_priors;
  /// Largest |time offset| the cross-correlation searches, s.
  double max_timeshift_s = 0.2;
  int max_iterations = 60;
  int threads = 0;  // 0 = all cores
  /// Compute the standard deviations (ceres::Covariance); off saves time in tests.
  bool covariance = true;
  /// Length of the time blocks whose residuals (frames and IMU samples) form one cluster of the
  /// cluster-robust covariance, s; 0: the plain covariance only. Every sigma is the larger of
  /// the plain and the cluster-robust one (docs/camimu-calibration.md, "Uncertainty").
  double covariance_cluster_s = 1.0;
  /// Add the held intrinsics' covariance (CamImuCameraInput::intrinsics_covariance) to the
  /// sigmas, linearised at the solution: the spread their own error causes in the result
  /// (docs/camimu-calibration.md, "Uncertainty").
  bool propagate_intrinsics = true;

  [[nodiscard]] Status validate() const;
};

/// A solver iteration as reported to the caller (for progress displays).
struct CamImuIteration {
  std::string stage;  // "init", "solve", "covariance"
  int iteration = 0;
  double cost = 0.0;
  double gradient_max_norm = 0.0;
};
using CamImuProgressFn = std::function<void(const CamImuIteration&)>;

/// Runs the initialisation and the full problem. Errors: kInvalidArgument (options, or an
/// observation whose ids the target does not have: check_observation),
/// kInsufficientData (too few frames with the target, IMU not covering the frames, too little
/// rotation to align camera and IMU), kSolverFailed.
[[nodiscard]] Result<CamImuCalibrationResult> calibrate_camimu(const std::vector<CamImuSample>& imu,
                                                               const std::vector<CamImuCameraInput>& cameras,
                                                               const TargetDescription& target,
                                                               const CamImuOptions& options,
                                                               const CamImuProgressFn& progress = {});

}  // namespace imucal::calib
