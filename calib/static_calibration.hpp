// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Static multi-position IMU calibration without equipment (Tedaldi, Pretto, Menegatti 2013/2014,
// the method of imu_tk): the variance static detector (eq. 3.9) with the threshold multiplier
// chosen by the lowest accelerometer residual (Algorithm 1), the accelerometer from the gravity
// magnitude (eqs. 3.1-3.4), the gyroscope from the gravity direction carried between static
// poses by RK4n integration (eqs. 3.5-3.16). Every parameter comes with its standard deviation
// from the solver covariance, scaled by the observed residual variance.
//
// Input: the samples of one IMU stream in time order, raw counts or SI. Output parameters are in
// Tedaldi's form (out = T K (raw + b)) and in the canonical form of core/imu_model.hpp;
// the record is core/imu_calibration.hpp.

#include <Eigen/Core>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "calib/quality.hpp"
#include "core/imu.hpp"
#include "core/imu_calibration.hpp"
#include "core/imu_model.hpp"
#include "core/result.hpp"

namespace imucal::calib {

struct StaticCalibrationOptions {
  /// Local gravity magnitude, m/s^2 (see calib/gravity.hpp for WGS-84 normal gravity).
  double gravity_mps2 = kStandardGravity;
  /// Length of the initial still period T_init, s; 0 = find the still start and choose T_init
  /// from the gyroscope Allan deviation (section 3.4.3).
  double init_still_s = 0.0;
  /// Shortest still start accepted, found or given, s (a warning below 10 s: the protocol asks
  /// for about 50).
  double min_init_still_s = 3.0;
  /// Variance window t_w of eq. 3.9, s.
  double window_s = 1.0;
  /// Shortest static interval used, s.
  double min_interval_s = 0.5;
  /// Threshold multipliers tried (Algorithm 1): a sample is static when varsigma < k *
  /// varsigma_init (imu_tk's rule; the thesis text states k * varsigma_init^2 on varsigma^2,
  /// which for the same k is far stricter).
  int multiplier_min = 2;
  int multiplier_max = 10;
  /// Distinct attitudes: at least min_attitudes for the full model (observability, section
  /// 3.5), a warning below recommended_attitudes. Two static means closer than
  /// distinct_attitude_deg are one attitude.
  int min_attitudes = 9;
  /// The accelerometer model. Auto: the full model when some threshold finds min_attitudes;
  /// otherwise the known-orientation form when the poses cover the six faces, else scales and
  /// biases alone (misalignment held at zero) from min_attitudes_scale_bias attitudes.
  enum class AccelModel { kAuto, kFull, kFaces, kScaleBias };
  AccelModel accel_model = AccelModel::kAuto;
  int min_attitudes_scale_bias = 6;
  /// A pose lies on a face when its gravity reaction is within this angle of the face's axis.
  double face_max_angle_deg = 15.0;
  /// Scale-bias form: the misalignment held at zero is really up to about this (1 sigma, rad;
  /// the MPU-6000's cross-axis sensitivity is +-2 %); the scales and biases it shifts are
  /// widened by that shift.
  double misalignment_prior_rad = 0.02;
  int recommended_attitudes = 18;
  double distinct_attitude_deg = 8.0;
  /// Static intervals in which the gyro shows more rotation than this are dropped, deg.
  double max_rotation_in_static_deg = 1.0;
  /// Initial guesses as nominal raw->SI conversions (si = scale .* (raw - offset)). Without an
  /// accelerometer guess a closed-form ellipsoid fit provides one; without a gyro guess the scale
  /// is 1 (SI input). The gyro offset is not used: the bias comes from the still period.
  std::optional<AxisConversion> accel_init;
  std::optional<AxisConversion> gyro_init;
  /// Estimate the gyro bias in the gyroscope solve (eq. 3.8) instead of fixing it beforehand.
  bool estimate_gyro_bias = false;
  /// Gyroscope g-sensitivity: estimated with the gyro bias from the per-pose gyro means (the
  /// mean of a still pose is b_g + H a, H = A_g^-1 G; default), fixed to `gsens_fixed` (canonical
  /// G, rad/s per m/s^2, frame of the result), or neglected as in Tedaldi's model (the bias is
  /// then the still start's mean).
  GSensitivityMode gsens = GSensitivityMode::kEstimate;
  /// Fewest static poses (besides the still start) with which G is estimated; with fewer it is
  /// neglected, with a warning (4 unknowns per gyro axis would be fitted to a handful of poses).
  int min_poses_for_gsens = 15;
  Eigen::Matrix3d gsens_fixed = Eigen::Matrix3d::Zero();
  /// Latitude, deg, when known: the vertical part of the Earth's rotation (which a still gyro
  /// sees as Omega sin(latitude) along gravity, indistinguishable from g-sensitivity) is removed
  /// from the estimated G.
  std::optional<double> latitude_deg;
  /// Gyro parameters the motions determine worse than this (1 sigma: misalignment angle, rad;
  /// scale, relative) are held at nominal and named instead of fitted.
  double gyro_max_misalignment_sigma_rad = 0.01;
  double gyro_max_scale_rel_sigma = 0.01;
  /// A held gyro scale is really within this of nominal (1 sigma, relative: the MPU-6000's
  /// sensitivity tolerance is +-3 %); a held angle within misalignment_prior_rad. What they move
  /// the fitted parameters by is added to those's covariance.
  double scale_prior_rel = 0.03;
  /// Threads for the gyroscope solve (0: one per core). The result does not depend on it.
  int threads = 0;

  /// Checks ranges; the error says what is wrong.
  [[nodiscard]] Status validate() const;
};

// The result record lives in core (core/imu_calibration.hpp) so that code reading or writing
// calibrations needs no solver; these names keep calib::X working for the estimator's callers.
using imucal::StaticCalibrationResult;
using imucal::StaticIntervalInfo;
using imucal::StaticQuality;
using imucal::StaticTimings;
using imucal::TriadSigma;

/// Runs the whole method on one recording.
[[nodiscard]] Result<StaticCalibrationResult> calibrate_static(std::span<const ImuSample> samples,
                                                               const StaticCalibrationOptions& options);

}  // namespace imucal::calib
