// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The record of a static multi-position IMU calibration (Tedaldi, Pretto, Menegatti 2013/2014):
// the estimated model with its uncertainty, the static intervals it used, quality figures and
// warnings. It lives in core, with Eigen only, so that storage and the service can read and write
// calibrations without linking the estimator (calib/ and Ceres); calib/static_calibration.hpp
// produces it. The six-orientation g-sensitivity record (calib/gsens_calibration.hpp) is here too.

#include <Eigen/Core>
#include <cstddef>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/thermal_model.hpp"
#include "core/time.hpp"

namespace imucal {

/// Standard deviations of a TedaldiTriad's entries (0 for entries that are fixed).
struct TriadSigma {
  Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
  Eigen::Vector3d scale = Eigen::Vector3d::Zero();
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();
};

/// One static interval the calibration used.
struct StaticIntervalInfo {
  TimeNs t0_ns = 0;
  TimeNs t1_ns = 0;  // last sample
  std::size_t samples = 0;
  Eigen::Vector3d accel_mean_raw = Eigen::Vector3d::Zero();
};

/// Error figures as a magnitude (m/s^2) and an angle (rad), mean and max over the static
/// intervals (Tedaldi 2013, section 4.1.1; computed in calib/quality.hpp).
struct ErrorFigures {
  int count = 0;
  double mean_mps2 = 0.0;
  double max_mps2 = 0.0;
  double mean_rad = 0.0;
  double max_rad = 0.0;
};

struct StaticQuality {
  bool before_available = false;  // false when no nominal accelerometer conversion was given
  ErrorFigures accel_before, accel_after;
  ErrorFigures gyro_before, gyro_after;
};

/// CPU time of the calling thread spent in each step, s.
struct StaticTimings {
  double detector_s = 0.0;
  double threshold_search_s = 0.0;
  double accel_s = 0.0;
  double gyro_s = 0.0;
};

/// How the gyroscope g-sensitivity was treated (StaticCalibrationOptions::gsens).
enum class GSensitivityMode {
  kEstimate,  // estimated from the static poses with the gyro bias
  kFixed,     // given, not estimated
  kOff,       // neglected (Tedaldi's model: G = 0, bias from the still start)
};
inline const char* gsens_mode_name(GSensitivityMode mode) {
  switch (mode) {
    case GSensitivityMode::kEstimate:
      return "estimate";
    case GSensitivityMode::kFixed:
      return "fixed";
    case GSensitivityMode::kOff:
      return "off";
  }
  return "off";
}

/// Below this Wald statistic of its nine entries (the chi-square 95 % point with 9 degrees of
/// freedom) the static calibration takes G as not distinguishable from zero and neglects it.
inline constexpr double kGsensWaldLimit = 16.919;

/// Which accelerometer model the static calibration fitted (StaticCalibrationOptions::accel_model).
enum class StaticAccelModel {
  kFull,       // Tedaldi's magnitude form: 3 misalignment angles, 3 scales, 3 biases (9 attitudes)
  kFaces,      // known orientation: each pose on one of the six faces, full 3x3 matrix and offset
  kScaleBias,  // magnitude form with the misalignment held at zero: scales and biases (6 attitudes)
};
inline const char* static_accel_model_name(StaticAccelModel m) {
  switch (m) {
    case StaticAccelModel::kFull:
      return "full";
    case StaticAccelModel::kFaces:
      return "faces";
    case StaticAccelModel::kScaleBias:
      return "scale-bias";
  }
  return "full";
}

/// Degrees of freedom of a least-squares fit (residuals minus parameters). With none left the
/// residual variance is unknown and the parameters' sigmas are undetermined (NaN).
struct FitDof {
  int residuals = 0;
  int parameters = 0;
  int dof() const { return residuals - parameters; }
  bool determined() const { return dof() > 0; }
};

/// One threshold multiplier tried by the search (Algorithm 1), as scored.
struct ThresholdCandidate {
  int multiplier = 0;
  int intervals = 0;
  int distinct_attitudes = 0;
  int dropped_for_rotation = 0;
  double accel_rms = 0.0;  // of eq. 3.4, m^2/s^4
  double gyro_rms = 0.0;   // of the pose means about the gyro's static model, input units
  double score = 0.0;      // lower is better (docs/static-calibration.md, step 4)
};

struct StaticCalibrationResult {
  TedaldiImuModel model;
  /// Standard deviations; NaN where undetermined (no degrees of freedom left, see the dof fields).
  TriadSigma accel_sigma, gyro_sigma;
  /// Covariances of the parameter vectors of eqs. 3.2 and 3.6 (gyro: + 3 bias entries when the
  /// bias is estimated), already scaled by the residual variance.
  Eigen::MatrixXd accel_covariance, gyro_covariance;
  CanonicalImuModel canonical;
  /// Gyroscope g-sensitivity (canonical G, rad/s per m/s^2, output frame) and how it was found.
  /// The gyro bias of the model is the one fitted with it (the still start's mean when kOff).
  GSensitivityMode gsens_mode = GSensitivityMode::kOff;
  Eigen::Matrix3d gsens_sigma = Eigen::Matrix3d::Zero();  // of canonical.G; 0 when fixed or off
  /// Earth rate removed from G (its vertical part, Omega sin(latitude) / g on the diagonal); 0
  /// when the latitude is not known (then G holds it: at most 7.4e-6 rad/s per m/s^2).
  double earth_rate_removed = 0.0;
  /// Residual RMS of the per-pose gyro means about b_g + H a (rad/s, with the nominal gyro scale).
  double gsens_residual_rms = 0.0;
  /// Wald statistic of the estimated G's nine entries against zero (NaN when G was not
  /// estimated); below the chi-square 95 % point G is neglected.
  double gsens_wald = std::numeric_limits<double>::quiet_NaN();
  /// The gyro bias was fitted to the still poses (with its drift), also when G is neglected for
  /// being indistinguishable from zero; false: the still start's mean (gsens off).
  bool gyro_bias_from_poses = false;
  FitDof accel_dof, gyro_dof, gsens_dof;
  /// The accelerometer model fitted, why that one, and the parameters it held instead of fitting
  /// (their sigmas are NaN: not determined by the recording).
  StaticAccelModel accel_model = StaticAccelModel::kFull;
  std::string accel_model_reason;
  std::vector<std::string> accel_fixed;
  /// Gyro parameters the motions did not determine, held at nominal (sigma NaN).
  std::vector<std::string> gyro_fixed;
  /// Known-orientation form only: how far the poses' calibrated gravity lay from their faces'
  /// axes (RMS, rad), the rotation between the faces and the accelerometer's frame (rad), and the
  /// poses left out of the accelerometer fit because they lie on no face.
  double faces_direction_rms_rad = 0.0;
  double faces_rotation_rad = 0.0;
  int poses_off_faces = 0;

  double gravity_mps2 = 0.0;
  double init_still_s = 0.0;
  bool init_still_from_allan = false;
  /// Static samples have varsigma < multiplier * varsigma_init (imu_tk's rule), that is
  /// varsigma^2 < threshold = multiplier^2 * varsigma_init^2.
  int threshold_multiplier = 0;
  double threshold = 0.0;  // on varsigma^2, input units^4
  double sigma_init_sq = 0.0;
  std::vector<ThresholdCandidate> threshold_candidates;  // those with enough attitudes
  std::vector<StaticIntervalInfo> intervals;
  int distinct_attitudes = 0;
  int gyro_transfers = 0;
  double accel_residual_rms = 0.0;  // of eq. 3.4 residuals, m^2/s^4
  double gyro_residual_rms = 0.0;   // of eq. 3.8 residuals (unit vectors)
  int accel_iterations = 0;
  int gyro_iterations = 0;
  StaticQuality quality;
  StaticTimings timings;
  /// The thermal model the samples were corrected with before the fit (`--thermal`), on the
  /// input units: the biases above are those at its reference temperature. Empty: none.
  std::optional<ThermalModel> thermal;
  std::vector<std::string> warnings;
};

/// One still hold of the six-orientation g-sensitivity experiment (Krebs 2012, section 5.2.3).
struct GSensitivityHold {
  TimeNs t0_ns = 0;
  TimeNs t1_ns = 0;  // last sample
  std::size_t samples = 0;
  /// The body axis pointing up ("+x" ... "-z": the accelerometer reads +g along it), empty when
  /// the hold is tilted from every face by more than the method's limit; and that tilt, deg.
  std::string face;
  double face_angle_deg = 0.0;
  Eigen::Vector3d accel_mps2 = Eigen::Vector3d::Zero();     // calibrated accelerometer mean a_k
  Eigen::Vector3d gyro_mean_raw = Eigen::Vector3d::Zero();  // input units
  /// A_g (gyro mean - b_g(t) - H a_k): what the fitted model leaves of this hold, rad/s.
  Eigen::Vector3d residual_radps = Eigen::Vector3d::Zero();
  /// Rotation inside the hold: the turn of the gravity direction between its first and last
  /// second (accelerometer), and the residual rate times the hold's length (gyro), deg.
  double tilt_deg = 0.0;
  double rotation_deg = 0.0;
};

/// The static six-orientation g-sensitivity experiment: the canonical G of core/imu_model.hpp
/// (w = A_g (w_raw - b_g) - G a) and the gyro bias, fitted to the gyro means of still holds.
struct GSensitivityResult {
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();        // rad/s per m/s^2, output frame of A_g
  Eigen::Matrix3d G_sigma = Eigen::Matrix3d::Zero();  // standard deviations of G's entries
  /// The gyro bias (input units, canonical sign) at the middle of the holds' span, with sigma.
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_g_sigma = Eigen::Vector3d::Zero();
  TimeNs b_g_t_ns = 0;  // the time b_g refers to
  /// Covariance of [G row by row (9), b_g (3)], including the models' share (model_sigma).
  Eigen::Matrix<double, 12, 12> covariance = Eigen::Matrix<double, 12, 12>::Zero();
  /// The models the holds were read through: a = A_a (a_raw - b_a), w = A_g (w_raw - b_g) - G a,
  /// and the uncertainty assumed for them (0: calibrated): relative, of A_a's and A_g's entries
  /// (carried into G), and of b_a (carried into b_g).
  Eigen::Matrix3d A_a = Eigen::Matrix3d::Identity();
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  Eigen::Matrix3d A_g = Eigen::Matrix3d::Identity();
  double accel_model_rel_sigma = 0.0;
  double gyro_model_rel_sigma = 0.0;
  double accel_offset_sigma_mps2 = 0.0;  // of b_a, each axis
  /// Earth rate removed from G (Omega sin(latitude) / g on the diagonal); 0 when the latitude is
  /// not known (then G holds it).
  double earth_rate_removed = 0.0;
  /// The noise of one hold's gyro mean, per axis in input units: white noise density (/sqrt(Hz))
  /// and bias random walk (*sqrt(Hz)) from the pooled Allan deviation of the holds, or given.
  Eigen::Vector3d gyro_noise_density = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_random_walk = Eigen::Vector3d::Zero();
  /// Chi-square of the residuals per degree of freedom against that noise (pooled over axes);
  /// the covariance is scaled by it when it exceeds 1.
  double chi2_per_dof = 0.0;
  double residual_rms_radps = 0.0;  // of the holds' residuals, all axes
  FitDof dof;                       // all three axes: 3 residuals per hold, 12 parameters
  double gravity_mps2 = 0.0;
  std::vector<GSensitivityHold> holds;
  std::vector<std::string> warnings;
};

}  // namespace imucal
