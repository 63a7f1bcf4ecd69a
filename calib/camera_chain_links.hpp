// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// How the cameras of a chain sit against each other before the joint solve
// (calib/camera_chain.cpp, step 2): each camera's track of target poses, and the link of one
// camera against another from the views they share, with the time offset that fits best.
// Internal to the chain estimator.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <vector>

namespace imucal::calib::chain {

/// A camera's pose in one view: target (world) from camera, at the view's stamp (s from t0).
struct PoseSample {
  double t = 0.0;
  Eigen::Matrix3d R_wc = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p_wc = Eigen::Vector3d::Zero();
};

/// How camera b sits against camera a, from the views they share.
struct Link {
  int shared = 0;                                      // b's views with a's pose interpolated at the offset
  double shift = 0.0;                                  // t_a = t_b + shift
  Eigen::Matrix3d R_ba = Eigen::Matrix3d::Identity();  // p_b = R_ba p_a + t_ba
  Eigen::Vector3d t_ba = Eigen::Vector3d::Zero();
  double score = std::numeric_limits<double>::infinity();
};

/// The link of b against a: the offset on a 1 ms grid within +-max_shift_s (0 alone when
/// offsets are not estimated) with the smallest spread among those with at least min_shared
/// views, refined by a parabola through its neighbours.
Link find_link(const std::vector<PoseSample>& a, const std::vector<PoseSample>& b, double max_shift_s,
               double max_gap_s, int min_shared);

/// d(T_cn_cnm1) / d(T_n_0, T_m_0) by central differences in the tangent spaces (right
/// perturbations of the rotations, then translations), 6 x 12: how a camera's pose relative to the
/// one before moves with both cameras' poses relative to cam0.
Eigen::Matrix<double, 6, 12> relative_jacobian(const Eigen::Isometry3d& T_n0, const Eigen::Isometry3d& T_m0);

}  // namespace imucal::calib::chain
