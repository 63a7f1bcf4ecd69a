// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The noise figures of the Allan deviation of a still recording: the analysis of the samples and
// its result files (Kalibr imu.yaml, JSON with the curves; docs/static-calibration.md, "Allan deviation").

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/allan.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// Noise figures of a still recording, per axis, and where they come from.
struct AllanReport {
  std::string log_path;  // named in the outputs
  std::string stream;
  std::string rostopic = "/imu0";
  double rate_hz = 0.0;
  double duration_s = 0.0;  // of the analysed run
  calib::AllanCurve accel_curve, gyro_curve;
  std::vector<calib::AllanNoise> accel_fits, gyro_fits;  // x, y, z

  /// Kalibr's figures: the worst axis of each.
  double accel_noise_density() const;
  double accel_random_walk() const;
  double gyro_noise_density() const;
  double gyro_random_walk() const;
  /// True when any random walk is only an upper bound (recording too short for its slope).
  bool random_walk_is_upper_bound() const;
};

/// Allan deviations and noise fits of `accel` (m/s^2) and `gyro` (rad/s) sampled at
/// `rate_hz`; `log_path`, `stream` and `rostopic` are left for the caller.
[[nodiscard]] Result<AllanReport> analyse_allan(const std::vector<Eigen::Vector3d>& accel,
                                                const std::vector<Eigen::Vector3d>& gyro, double rate_hz);

/// The Kalibr imu.yaml of a report.
std::string allan_kalibr_yaml(const AllanReport& report);
/// The report as JSON with the curves and fitted lines (indented, ending in a newline).
std::string allan_json(const AllanReport& report);

}  // namespace imucal::app
