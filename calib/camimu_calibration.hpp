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

struct CamImuOptions {
  CamImuModelKind model = CamImuModelKind::kExtended;
  /// Pose spline: order (degree + 1) and knot spacing; bias splines: their own spacing.
  int spline_order = 4;
  double knot_spacing_s = 0.05;
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
  /// Largest |time offset| the cross-correlation searches, s.
  double max_timeshift_s = 0.2;
  int max_iterations = 60;
  int threads = 0;  // 0 = all cores
  /// Compute the standard deviations (ceres::Covariance); off saves time in tests.
  bool covariance = true;

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

/// Runs the initialisation and the full problem. Errors: kInvalidArgument (options),
/// kInsufficientData (too few frames with the target, IMU not covering the frames, too little
/// rotation to align camera and IMU), kSolverFailed.
[[nodiscard]] Result<CamImuCalibrationResult> calibrate_camimu(const std::vector<CamImuSample>& imu,
                                                               const std::vector<CamImuCameraInput>& cameras,
                                                               const TargetDescription& target,
                                                               const CamImuOptions& options,
                                                               const CamImuProgressFn& progress = {});

}  // namespace imucal::calib
