// SPDX-License-Identifier: BSD-3-Clause
#include "calib/static_detector.hpp"

#include <algorithm>

namespace imucal::calib {

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  const std::size_t k = std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

std::vector<double> variance_magnitude_sq(std::span<const Eigen::Vector3d> values, std::size_t window) {
  const std::size_t n = values.size();
  std::vector<double> out(n, 0.0);
  if (n == 0) return out;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& v : values) mean += v;
  mean /= static_cast<double>(n);
  // Prefix sums of the centred values and their squares.
  std::vector<Eigen::Vector3d> s1(n + 1), s2(n + 1);
  s1[0].setZero();
  s2[0].setZero();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d c = values[i] - mean;
    s1[i + 1] = s1[i] + c;
    s2[i + 1] = s2[i] + c.cwiseProduct(c);
  }
  const std::size_t half = std::max<std::size_t>(window, 1) / 2;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t a = i >= half ? i - half : 0;
    const std::size_t b = std::min(n, i + half + 1);
    const double m = static_cast<double>(b - a);
    const Eigen::Vector3d mu = (s1[b] - s1[a]) / m;
    const Eigen::Vector3d var = ((s2[b] - s2[a]) / m - mu.cwiseProduct(mu)).cwiseMax(0.0);
    out[i] = var.squaredNorm();
  }
  return out;
}

double variance_magnitude_sq_of(std::span<const Eigen::Vector3d> values) {
  if (values.empty()) return 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& v : values) mean += v;
  mean /= static_cast<double>(values.size());
  Eigen::Vector3d var = Eigen::Vector3d::Zero();
  for (const auto& v : values) var += (v - mean).cwiseProduct(v - mean);
  var /= static_cast<double>(values.size());
  return var.squaredNorm();
}

std::vector<StaticInterval> detect_static_intervals(std::span<const double> sigma_sq, double threshold,
                                                    const std::vector<bool>& usable,
                                                    const std::vector<bool>& break_before,
                                                    std::size_t min_samples) {
  std::vector<StaticInterval> out;
  const std::size_t n = sigma_sq.size();
  std::size_t i = 0;
  while (i < n) {
    if (!(sigma_sq[i] < threshold) || !usable[i]) {
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    while (j < n && sigma_sq[j] < threshold && usable[j] && !break_before[j]) ++j;
    if (j - i >= std::max<std::size_t>(min_samples, 1)) out.push_back({i, j});
    i = j;
  }
  return out;
}

}  // namespace imucal::calib
