// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Stillness over the last half second of samples (SI units): the accelerometer's largest axis
// standard deviation and the gyro's mean and largest axis standard deviation, kept as running
// sums over a ring of samples.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <deque>

#include "app/session/session_engine.hpp"

namespace imucal::app::session {

struct SessionEngine::Window {
  explicit Window(double rate_hz) : size(std::max<std::size_t>(8, static_cast<std::size_t>(0.5 * rate_hz))) {}

  void add(const Eigen::Vector3d& accel, const Eigen::Vector3d& gyro) {
    ring.push_back({accel, gyro});
    a_sum += accel;
    a_sq += accel.cwiseProduct(accel);
    g_sum += gyro;
    g_sq += gyro.cwiseProduct(gyro);
    if (ring.size() > size) {
      const auto& old = ring.front();
      a_sum -= old.first;
      a_sq -= old.first.cwiseProduct(old.first);
      g_sum -= old.second;
      g_sq -= old.second.cwiseProduct(old.second);
      ring.pop_front();
    }
  }
  bool full() const { return ring.size() >= size; }
  void clear() {
    ring.clear();
    a_sum = a_sq = g_sum = g_sq = Eigen::Vector3d::Zero();
  }
  Eigen::Vector3d accel_mean() const { return a_sum / static_cast<double>(ring.size()); }
  Eigen::Vector3d gyro_mean() const { return g_sum / static_cast<double>(ring.size()); }
  static double max_std(const Eigen::Vector3d& sum, const Eigen::Vector3d& sq, double n) {
    const Eigen::Vector3d var = (sq / n - (sum / n).cwiseProduct(sum / n)).cwiseMax(0.0);
    return std::sqrt(var.maxCoeff());
  }
  double accel_std() const { return max_std(a_sum, a_sq, static_cast<double>(ring.size())); }
  double gyro_std() const { return max_std(g_sum, g_sq, static_cast<double>(ring.size())); }

  std::size_t size;
  std::deque<std::pair<Eigen::Vector3d, Eigen::Vector3d>> ring;
  Eigen::Vector3d a_sum = Eigen::Vector3d::Zero(), a_sq = Eigen::Vector3d::Zero();
  Eigen::Vector3d g_sum = Eigen::Vector3d::Zero(), g_sq = Eigen::Vector3d::Zero();
};

}  // namespace imucal::app::session
