// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The variance static detector of Tedaldi 2013, eq. 3.9, in O(n) with running sums.

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <vector>

namespace imucal::calib {

/// A run of samples [begin, end) classified as static.
struct StaticInterval {
  std::size_t begin = 0;
  std::size_t end = 0;
  std::size_t size() const { return end - begin; }
};

/// The p-quantile (0..1) of `v` by selection; 0 for an empty vector.
double percentile(std::vector<double> v, double p);

/// varsigma(t)^2 of eq. 3.9 for every sample: the sum over the three axes of the squared
/// variance of the signal in a window of `window` samples centred on the sample (truncated at
/// the ends of the recording). The data are centred on their mean before the running sums are
/// formed, so raw counts with large offsets lose no precision.
std::vector<double> variance_magnitude_sq(std::span<const Eigen::Vector3d> values, std::size_t window);

/// varsigma^2 of eq. 3.9 over one whole span (Algorithm 1's varsigma_init^2, with t_w = T_init).
double variance_magnitude_sq_of(std::span<const Eigen::Vector3d> values);

/// Static intervals: maximal runs of samples with sigma_sq < threshold and usable[i] set, never
/// crossing a sample with break_before[i] set, at least min_samples long.
std::vector<StaticInterval> detect_static_intervals(std::span<const double> sigma_sq, double threshold,
                                                    const std::vector<bool>& usable,
                                                    const std::vector<bool>& break_before,
                                                    std::size_t min_samples);

}  // namespace imucal::calib
