#pragma once
// The steps of calibrate_static (calib/static_calibration.hpp) that stand on their own: the scan
// of the input, the static detector and the initial still period. They are declared here so that
// tests can check each step without running the whole method; callers outside calib use
// calibrate_static.

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "calib/static_calibration.hpp"
#include "calib/static_scan.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// The variance static detector (eq. 3.9) over the whole recording, for the accelerometer (which
/// selects the static poses) and the gyroscope (which, with it, tells a still start from motion).
struct StaticDetection {
  std::size_t window = 0;             // samples
  std::size_t half = 0;               // window / 2
  std::vector<double> sigma_sq;       // accelerometer
  std::vector<double> gyro_sigma_sq;  // the same statistic of the gyroscope
  /// 10th percentile of sigma_sq (gyro_sigma_sq) over the valid samples: the noise floor of a
  /// still rig.
  double floor_sq = 0.0;
  double gyro_floor_sq = 0.0;

  /// Ratios to the floors (on varsigma^2, the squared variance) for the still start: a sample is
  /// moving when both sensors exceed kStillRatio (variance 3.2 times the floor), or either
  /// exceeds kStrongRatio (variance 1000 times). One sensor alone being noisier than in the later
  /// poses (an accelerometer that settles after power-up; a gyro on a rig held by hand, 40 times
  /// the floor's variance in a real recording) is not motion: turning the rig raises both, by
  /// far more.
  static constexpr double kStillRatio = 10.0;
  static constexpr double kStrongRatio = 1e6;
  bool moving(std::size_t i) const;
};
StaticDetection detect_variance(const ScannedRecording& scan, double window_s);

/// The initial still period (section 3.4.3) and what is estimated from it.
struct StillStart {
  std::size_t samples = 0;
  double length_s = 0.0;
  bool from_allan = false;     // length chosen from the gyroscope Allan deviation
  double sigma_init_sq = 0.0;  // varsigma_init^2 of Algorithm 1
  Eigen::Vector3d gyro_bias_raw = Eigen::Vector3d::Zero();  // the gyro's mean over the still start
  /// Its uncertainty as the bias of the whole session: white noise over sqrt(n), at least the
  /// Allan deviation at the longest averaging time the still start supports.
  Eigen::Vector3d gyro_bias_sigma = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_mean_raw = Eigen::Vector3d::Zero();
};
/// The given initial still period (options.init_still_s > 0), checked to be still, or the still
/// start found from the detector with its length chosen from the gyroscope Allan deviation.
[[nodiscard]] Result<StillStart> find_still_start(std::span<const ImuSample> samples,
                                                  const ScannedRecording& scan,
                                                  const StaticDetection& detection,
                                                  const StaticCalibrationOptions& options,
                                                  std::vector<std::string>* warnings);

/// (J^T J)^+ from the SVD of J, singular values below sqrt(1e-14) of the largest being dropped
/// (what ceres::Covariance does with DENSE_SVD and automatic null-space truncation).
Eigen::MatrixXd normal_pseudo_inverse(const Eigen::MatrixXd& J);

}  // namespace imucal::calib
