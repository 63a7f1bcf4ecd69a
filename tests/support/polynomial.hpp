// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A cubic written about another reference point, for comparing the virtual IMU's temperature
// truth (about its start temperature) with a fit about its own reference.

#include <Eigen/Core>
#include <cmath>

namespace imucal::test {

/// The polynomial sum c_j (T - from)^j written about `to`: sum d_k (T - to)^k.
inline Eigen::Vector4d shift_poly(const Eigen::Vector4d& c, double from, double to) {
  Eigen::Vector4d d = Eigen::Vector4d::Zero();
  const double s = to - from;
  const double binom[4][4] = {{1, 0, 0, 0}, {1, 1, 0, 0}, {1, 2, 1, 0}, {1, 3, 3, 1}};
  for (int j = 0; j < 4; ++j) {
    for (int k = 0; k <= j; ++k) d[k] += c[j] * binom[j][k] * std::pow(s, j - k);
  }
  return d;
}

}  // namespace imucal::test
