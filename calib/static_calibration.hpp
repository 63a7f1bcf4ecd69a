#pragma once
// Static multi-position IMU calibration without equipment (Tedaldi, Pretto, Menegatti 2013/2014,
// the method of imu_tk): the variance static detector (eq. 3.9) with the threshold multiplier
// chosen by the lowest accelerometer residual (Algorithm 1), the accelerometer from the gravity
// magnitude (eqs. 3.1-3.4), the gyroscope from the gravity direction carried between static
// poses by RK4n integration (eqs. 3.5-3.16). Every parameter comes with its standard deviation
// from the solver covariance, scaled by the observed residual variance.
//
// Input: the samples of one IMU stream in time order, raw counts or SI. Output parameters are in
// Tedaldi's form (out = T K (raw + b)) and in the canonical form of calib/imu_model.hpp.

#include <Eigen/Core>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "calib/quality.hpp"
#include "calib/static_detector.hpp"
#include "core/imu.hpp"
#include "core/imu_model.hpp"
#include "core/result.hpp"

namespace imucal::calib {

struct StaticCalibrationOptions {
  /// Local gravity magnitude, m/s^2 (see calib/gravity.hpp for WGS-84 normal gravity).
  double gravity_mps2 = kStandardGravity;
  /// Length of the initial still period T_init, s; 0 = find the still start and choose T_init
  /// from the gyroscope Allan deviation (section 3.4.3).
  double init_still_s = 0.0;
  /// Shortest still start accepted when it is found automatically, s.
  double min_init_still_s = 10.0;
  /// Variance window t_w of eq. 3.9, s.
  double window_s = 1.0;
  /// Shortest static interval used, s.
  double min_interval_s = 0.5;
  /// Threshold multipliers tried (Algorithm 1): threshold = k * varsigma_init^2.
  int multiplier_min = 2;
  int multiplier_max = 10;
  /// Distinct attitudes: at least min_attitudes (observability, section 3.5), a warning below
  /// recommended_attitudes. Two static means closer than distinct_attitude_deg are one attitude.
  int min_attitudes = 9;
  int recommended_attitudes = 18;
  double distinct_attitude_deg = 8.0;
  /// Static intervals in which the gyro shows more rotation than this are dropped, deg.
  double max_rotation_in_static_deg = 1.0;
  /// Initial guesses as nominal raw->SI conversions (si = scale .* (raw - offset)). Without an
  /// accelerometer guess a closed-form ellipsoid fit provides one; without a gyro guess the scale
  /// is 1 (SI input). The gyro offset is not used: the bias comes from the still period.
  std::optional<AxisConversion> accel_init;
  std::optional<AxisConversion> gyro_init;
  /// Estimate the gyro bias in the gyroscope solve instead of keeping the still-period mean.
  bool estimate_gyro_bias = false;

  /// Checks ranges; the error says what is wrong.
  [[nodiscard]] Status validate() const;
};

/// Standard deviations of a TedaldiTriad's entries (0 for entries that are fixed).
struct TriadSigma {
  Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
  Eigen::Vector3d scale = Eigen::Vector3d::Zero();
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();
};

struct StaticIntervalInfo {
  TimeNs t0_ns = 0;
  TimeNs t1_ns = 0;  // last sample
  std::size_t samples = 0;
  Eigen::Vector3d accel_mean_raw = Eigen::Vector3d::Zero();
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

struct StaticCalibrationResult {
  TedaldiImuModel model;
  TriadSigma accel_sigma, gyro_sigma;
  /// Covariances of the parameter vectors of eqs. 3.2 and 3.6 (gyro: + 3 bias entries when the
  /// bias is estimated), already scaled by the residual variance.
  Eigen::MatrixXd accel_covariance, gyro_covariance;
  CanonicalImuModel canonical;

  double gravity_mps2 = 0.0;
  double init_still_s = 0.0;
  bool init_still_from_allan = false;
  int threshold_multiplier = 0;
  double threshold = 0.0;  // on varsigma^2, input units^4
  double sigma_init_sq = 0.0;
  std::vector<StaticIntervalInfo> intervals;
  int distinct_attitudes = 0;
  int gyro_transfers = 0;
  double accel_residual_rms = 0.0;  // of eq. 3.4 residuals, m^2/s^4
  double gyro_residual_rms = 0.0;   // of eq. 3.8 residuals (unit vectors)
  int accel_iterations = 0;
  int gyro_iterations = 0;
  StaticQuality quality;
  StaticTimings timings;
  std::vector<std::string> warnings;
};

/// Runs the whole method on one recording.
[[nodiscard]] Result<StaticCalibrationResult> calibrate_static(std::span<const ImuSample> samples,
                                                               const StaticCalibrationOptions& options);

}  // namespace imucal::calib
