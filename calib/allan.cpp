// SPDX-License-Identifier: BSD-3-Clause
#include "calib/allan.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace imucal::calib {

Result<AllanCurve> allan_deviation(std::span<const Eigen::Vector3d> values, double rate_hz) {
  const long n = static_cast<long>(values.size());
  if (n < 16) {
    return make_error(Errc::kInsufficientData, "the Allan deviation needs at least 16 samples, got " +
                                                   std::to_string(n) + ": record a longer still period");
  }
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) {
    return make_error(Errc::kInvalidArgument, "the sample rate must be positive");
  }
  const double dt = 1.0 / rate_hz;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& v : values) mean += v;
  mean /= static_cast<double>(n);
  // theta[k] = dt * sum_{j<k} (y_j - mean): the integrated, centred signal.
  std::vector<Eigen::Vector3d> theta(static_cast<std::size_t>(n) + 1);
  theta[0].setZero();
  for (long k = 0; k < n; ++k) theta[k + 1] = theta[k] + dt * (values[k] - mean);

  AllanCurve curve;
  for (long m = 1; 2 * m <= n - 1; m *= 2) {
    const double tau = static_cast<double>(m) * dt;
    const long count = n + 1 - 2 * m;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (long k = 0; k < count; ++k) {
      const Eigen::Vector3d d = theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k];
      sum += d.cwiseProduct(d);
    }
    const Eigen::Vector3d avar = sum / (2.0 * tau * tau * static_cast<double>(count));
    curve.tau_s.push_back(tau);
    curve.adev.push_back(avar.cwiseSqrt());
    curve.clusters.push_back(count);
  }
  return curve;
}

AllanNoise fit_allan_noise(const AllanCurve& curve, int axis) {
  AllanNoise out;
  // Only points backed by at least 10 independent clusters: the longest tau are biased low.
  std::size_t n = 0;
  if (!curve.tau_s.empty()) {
    const double span_s = curve.tau_s[0] * static_cast<double>(curve.clusters[0] + 1);
    while (n < curve.tau_s.size() && (n < 3 || curve.tau_s[n] * 10.0 <= span_s)) ++n;
  }
  if (n == 0) return out;
  std::vector<double> lt(n), la(n);
  for (std::size_t i = 0; i < n; ++i) {
    lt[i] = std::log(curve.tau_s[i]);
    la[i] = std::log(std::max(curve.adev[i][axis], 1e-300));
  }
  // Local slope at point i (centred where possible).
  auto slope = [&](std::size_t i) {
    if (n == 1) return 0.0;
    const std::size_t a = i == 0 ? 0 : i - 1;
    const std::size_t b = i + 1 < n ? i + 1 : n - 1;
    return (la[b] - la[a]) / (lt[b] - lt[a]);
  };

  // White noise: the first run of points with slope near -1/2, fitted with slope -1/2.
  {
    std::size_t i0 = n, i1 = n;
    for (std::size_t i = 0; i < n; ++i) {
      const bool in = std::abs(slope(i) + 0.5) < 0.25;
      if (in && i0 == n) i0 = i;
      if (!in && i0 != n) {
        i1 = i;
        break;
      }
    }
    if (i0 == n) {  // no such run: the point whose slope is closest to -1/2
      double best = 1e300;
      for (std::size_t i = 0; i < n; ++i) {
        if (std::abs(slope(i) + 0.5) < best) {
          best = std::abs(slope(i) + 0.5);
          i0 = i;
        }
      }
      i1 = i0 + 1;
    }
    double s = 0.0;
    for (std::size_t i = i0; i < i1; ++i) s += la[i] + 0.5 * lt[i];
    out.noise_density = std::exp(s / static_cast<double>(i1 - i0));
    out.white_tau_min_s = curve.tau_s[i0];
    out.white_tau_max_s = curve.tau_s[i1 - 1];
  }

  // Bias instability: the minimum of the curve.
  std::size_t imin = 0;
  for (std::size_t i = 1; i < n; ++i) {
    if (la[i] < la[imin]) imin = i;
  }
  out.bias_instability = std::exp(la[imin]) / 0.664;
  out.bias_instability_tau_s = curve.tau_s[imin];
  out.bias_instability_is_bound = imin + 1 == n;

  // Random walk: the last run of points with slope near +1/2 after the minimum.
  {
    std::size_t i0 = n, i1 = n;
    for (std::size_t i = n; i-- > imin;) {
      const bool in = std::abs(slope(i) - 0.5) < 0.25 && i > imin;
      if (in && i1 == n) i1 = i + 1;
      if (in) i0 = i;
      if (!in && i1 != n) break;
    }
    // A genuine random-walk line spans at least two points and rises clearly above the minimum
    // (a noisy tail of a white-noise curve does neither).
    if (i1 != n && i0 != n && i1 - i0 >= 2 && la[i1 - 1] - la[imin] > std::log(1.4)) {
      double s = 0.0;
      for (std::size_t i = i0; i < i1; ++i) s += la[i] - 0.5 * (lt[i] - std::log(3.0));
      out.random_walk = std::exp(s / static_cast<double>(i1 - i0));
      out.rw_tau_min_s = curve.tau_s[i0];
      out.rw_tau_max_s = curve.tau_s[i1 - 1];
    } else {
      double bound = 1e300;
      std::size_t ib = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const double k = std::exp(la[i] - 0.5 * (lt[i] - std::log(3.0)));
        if (k < bound) {
          bound = k;
          ib = i;
        }
      }
      out.random_walk = bound;
      out.random_walk_is_bound = true;
      out.rw_tau_min_s = out.rw_tau_max_s = curve.tau_s[ib];
    }
  }
  return out;
}

double choose_init_period_s(const AllanCurve& gyro_curve, double max_s, double flat_ratio) {
  const std::size_t n = gyro_curve.tau_s.size();
  for (std::size_t i = 0; i + 1 < n; ++i) {
    // Only where at least 16 independent clusters back the estimate.
    if (gyro_curve.tau_s[i + 1] * 16.0 > max_s) break;
    if (gyro_curve.tau_s[i] < 1.0) continue;  // Tedaldi's t_0 = 1 s: below, sensor filtering shows
    bool flat = true;
    for (int a = 0; a < 3; ++a) {
      if (gyro_curve.adev[i + 1][a] < flat_ratio * gyro_curve.adev[i][a]) flat = false;
    }
    if (flat) return std::min(max_s, gyro_curve.tau_s[i]);
  }
  return max_s;
}

}  // namespace imucal::calib
