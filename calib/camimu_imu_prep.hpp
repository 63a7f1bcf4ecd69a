// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The IMU samples of the camera-IMU problem prepared before the solve (calib/camimu_calibration.cpp):
// a fast IMU averaged down to the rate the pose spline can use, and the spline's knot spacing
// chosen from the motion the gyroscope saw. docs/camimu-calibration.md, "Trajectory" and "Speed".

#include <vector>

#include "calib/camimu_calibration.hpp"
#include "core/time.hpp"

namespace imucal::calib {

/// The median interval between the samples (core/time.hpp median_interval_ns); 0 with fewer than 2.
TimeNs imu_median_interval_ns(const std::vector<CamImuSample>& imu);

/// Groups of k consecutive samples averaged, one sample per group at its mean time (k =
/// floor(rate / max_rate_hz), the rate from the median interval); a group that a gap interrupts is
/// left out. k = 1 (a copy) at or below max_rate_hz, or with max_rate_hz 0. `*k_out` receives k.
std::vector<CamImuSample> average_imu(const std::vector<CamImuSample>& imu, double max_rate_hz, int* k_out);

/// The pose spline's knot spacing the motion needs: the largest of kKnotSpacingCandidates at
/// which a B-spline of one order lower (the angular velocity's function space) fitted to the
/// gyroscope samples alone leaves a residual sigma (unbiased: sum of squares over samples less
/// knots) within 3 times that of the finest candidate, or within 1.5 times the gyro's white
/// noise per sample. A smooth motion gets 0.05 s; a hand-held, jerky one a denser spline, whose
/// IMU residuals are then near the noise rather than at the spline's lag. The factor 3 trades
/// the last of the lag for time. `fit_sigma`, when given, receives the residual sigma of each
/// candidate.
inline constexpr double kKnotSpacingCandidates[] = {0.05, 0.04, 0.03, 0.025, 0.02, 0.015, 0.01};
double choose_knot_spacing(const std::vector<CamImuSample>& imu, int spline_order, double gyro_sigma,
                           std::vector<double>* fit_sigma = nullptr);

}  // namespace imucal::calib
