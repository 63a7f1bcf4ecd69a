// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Overlapping Allan deviation (IEEE Std 952-1997, annex C; Tedaldi 2013 eq. 3.17) and the
// noise figures read from it.

#include <Eigen/Core>
#include <span>
#include <vector>

#include "core/result.hpp"

namespace imucal::calib {

/// Allan deviation per axis at octave-spaced cluster times tau = m / rate, m = 1, 2, 4, ...
struct AllanCurve {
  std::vector<double> tau_s;
  std::vector<Eigen::Vector3d> adev;  // same units as the input
  std::vector<long> clusters;         // number of overlapping differences averaged per tau
};

/// Overlapping Allan deviation of evenly sampled values, O(n) per tau through cumulative sums
/// of the centred signal. Needs at least 16 samples.
[[nodiscard]] Result<AllanCurve> allan_deviation(std::span<const Eigen::Vector3d> values, double rate_hz);

/// Noise figures of one axis with the lines they come from (log-log fits of fixed slope):
///   white noise   adev = N / sqrt(tau)           (slope -1/2, N read at tau = 1 s)
///   random walk   adev = K * sqrt(tau / 3)       (slope +1/2, K read at tau = 3 s)
///   instability   adev = 0.664 * B at the minimum (flat part)
/// When the recording is too short to show a +1/2 slope, K is the tightest upper bound the curve
/// gives (K <= adev * sqrt(3 / tau) at every tau) and random_walk_is_bound is set; likewise
/// when the curve still falls at its longest tau, B is an upper bound.
struct AllanNoise {
  double noise_density = 0.0;  // units / sqrt(Hz)
  double white_tau_min_s = 0.0, white_tau_max_s = 0.0;
  double random_walk = 0.0;  // units * sqrt(Hz)
  bool random_walk_is_bound = false;
  double rw_tau_min_s = 0.0, rw_tau_max_s = 0.0;
  double bias_instability = 0.0;  // units
  double bias_instability_tau_s = 0.0;
  bool bias_instability_is_bound = false;
};

AllanNoise fit_allan_noise(const AllanCurve& curve, int axis);

/// Tedaldi 2013, section 3.4.3: the averaging time after which the gyroscope Allan deviation
/// stops falling (by less than `flat_ratio` per octave on every axis), at most max_s. When it
/// falls all the way (white noise dominates), the whole span max_s is returned.
double choose_init_period_s(const AllanCurve& gyro_curve, double max_s, double flat_ratio = 0.9);

}  // namespace imucal::calib
