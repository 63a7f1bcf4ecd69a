// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The steps of calibrate_static (calib/static_calibration.hpp) that stand on their own: the initial
// still period, the nominal conversion's check, the quality figures and the covariance helper (the scan of
// the input and the static detector, which the g-sensitivity experiment shares, are in
// calib/static_scan.hpp). They are declared here so that tests can check each step without running the whole
// method; callers outside calib use calibrate_static.

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "calib/static_calibration.hpp"
#include "calib/static_gyro.hpp"
#include "calib/static_scan.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::calib {

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

/// A stream's nominal conversion as a Tedaldi triad (scale and offset, no misalignment).
TedaldiTriad triad_from_conversion(const AxisConversion& c);

/// A nominal accelerometer conversion under which the still start does not read about gravity
/// hides every attitude: an offset it does not know (a sensor whose zero is mid-range: raw
/// 16-bit counts near 32768) turns all the poses' means one way. It is set aside, with a warning:
/// the attitudes are then told apart about the centre of the poses' means, and the solve starts
/// from an ellipsoid fit, so the biases take the offset.
void set_aside_an_implausible_accel_conversion(const StillStart& still, StaticCalibrationOptions* opt,
                                               std::vector<std::string>* warnings);

/// The quality figures of section 4.1.1 for the calibrated `model`: the gravity magnitude error
/// of the poses' `means` and the gravity direction error carried by the gyro over the
/// `transfers`; before calibration too (the nominal conversions) when the options give them.
StaticQuality quality_figures(const std::vector<Transfer>& transfers,
                              const std::vector<StaticInterval>& intervals,
                              const std::vector<Eigen::Vector3d>& means, const ScannedRecording& scan,
                              std::span<const ImuSample> samples, const StillStart& still,
                              const StaticCalibrationOptions& opt, const TedaldiImuModel& model);

}  // namespace imucal::calib
