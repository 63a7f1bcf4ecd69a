// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Quality figures of a static multi-position calibration (Tedaldi 2013, sections 4.1.1 and
// 4.2.1), computed over the static intervals only, so they need no ground truth.

#include <Eigen/Core>
#include <span>

#include "core/imu_calibration.hpp"
#include "core/imu_model.hpp"

namespace imucal::calib {

using imucal::ErrorFigures;  // part of the result record, core/imu_calibration.hpp

/// Accelerometer divergence (4.1.1, metric 3): | |a_k| - g | for every static mean a_k after the
/// triad's correction, and the worst-case tilt angle asin(err / g) it causes.
ErrorFigures gravity_magnitude_error(std::span<const Eigen::Vector3d> raw_means, const TedaldiTriad& accel,
                                     double gravity);

/// One gyroscope check: the gravity direction at a static pose (calibrated accelerometer) carried
/// through the motion to the next pose by RK4n integration of the corrected gyro.
struct GravityTransfer {
  Eigen::Vector3d u0 = Eigen::Vector3d::UnitZ();  // unit gravity direction before the motion
  Eigen::Vector3d u1 = Eigen::Vector3d::UnitZ();  // unit gravity direction after it
  std::span<const Eigen::Vector3d> gyro_raw;      // raw gyro from the end of one pose to the next
  std::span<const double> t_s;
};

/// Gyroscope divergence (4.1.1, metric 4): the angle between u1 and the gyro-predicted
/// direction, and g times the length of their difference (m/s^2).
ErrorFigures gravity_direction_error(std::span<const GravityTransfer> transfers, const TedaldiTriad& gyro,
                                     double gravity);

}  // namespace imucal::calib
