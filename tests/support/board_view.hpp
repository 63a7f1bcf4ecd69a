// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// One synthetic view of a planar target through a camera, for the tests of the camera solves:
// the board's points about its centre, turned by R and put at `at` in the camera frame,
// projected with pixel noise; points the model cannot project are left out.

#include <Eigen/Core>
#include <random>
#include <vector>

#include "calib/target_detection.hpp"
#include "core/camera_model.hpp"

namespace imucal::test {

inline calib::TargetObservation board_view(const CameraModel& camera,
                                           const std::vector<Eigen::Vector3d>& points,
                                           const Eigen::Vector3d& centre, const Eigen::Matrix3d& R,
                                           const Eigen::Vector3d& at, TimeNs t_ns,
                                           std::normal_distribution<double>& noise, std::mt19937& rng) {
  calib::TargetObservation obs;
  obs.t_ns = t_ns;
  obs.width = camera.width;
  obs.height = camera.height;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto p = camera.project(R * (points[i] - centre) + at);
    if (!p.valid()) continue;
    obs.ids.push_back(static_cast<int>(i));
    obs.px.push_back(p.px + Eigen::Vector2d(noise(rng), noise(rng)));
  }
  return obs;
}

}  // namespace imucal::test
