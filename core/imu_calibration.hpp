#pragma once
// The record of a static multi-position IMU calibration (Tedaldi, Pretto, Menegatti 2013/2014):
// the estimated model with its uncertainty, the static intervals it used, quality figures and
// warnings. It lives in core, with Eigen only, so that storage and the service can read and write
// calibrations without linking the estimator (calib/ and Ceres); calib/static_calibration.hpp
// produces it.

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
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

}  // namespace imucal
