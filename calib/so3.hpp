// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// SO(3) helpers for the splines and the camera-IMU problem: the exponential and logarithm maps
// and the right Jacobian with its inverse (Sola, Deray, Atchuthan, "A micro Lie theory", 2018,
// eqs. 143-146). Rotations are Eigen matrices; tangent vectors are rotation vectors, rad.
//
// Conventions: Exp(phi + d) ~= Exp(phi) Exp(Jr(phi) d) and Log(R Exp(d)) ~= Log(R) + Jr^-1(Log R) d;
// the left Jacobian is Jl(phi) = Jr(-phi).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace imucal::calib::so3 {

inline Eigen::Matrix3d hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

/// Below this angle the series expansions are used (their truncation error is below 1e-16).
inline constexpr double kSmallAngle = 1e-5;

inline Eigen::Matrix3d exp(const Eigen::Vector3d& phi) {
  const double theta2 = phi.squaredNorm();
  const Eigen::Matrix3d K = hat(phi);
  if (theta2 < kSmallAngle * kSmallAngle) return Eigen::Matrix3d::Identity() + K + 0.5 * K * K;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() + (std::sin(theta) / theta) * K +
         ((1.0 - std::cos(theta)) / theta2) * K * K;
}

inline Eigen::Vector3d log(const Eigen::Matrix3d& R) {
  // Through the quaternion: accurate near 0 and near pi, where the trace formula is not.
  Eigen::Quaterniond q(R);
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  const Eigen::Vector3d v = q.vec();
  const double s = v.norm();
  if (s < kSmallAngle) return (2.0 / q.w()) * (1.0 - s * s / (3.0 * q.w() * q.w())) * v;
  return (2.0 * std::atan2(s, q.w()) / s) * v;
}

/// Right Jacobian of Exp.
inline Eigen::Matrix3d right_jacobian(const Eigen::Vector3d& phi) {
  const double theta2 = phi.squaredNorm();
  const Eigen::Matrix3d K = hat(phi);
  if (theta2 < kSmallAngle * kSmallAngle) return Eigen::Matrix3d::Identity() - 0.5 * K + (1.0 / 6.0) * K * K;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() - ((1.0 - std::cos(theta)) / theta2) * K +
         ((theta - std::sin(theta)) / (theta2 * theta)) * K * K;
}

/// Inverse of the right Jacobian.
inline Eigen::Matrix3d right_jacobian_inverse(const Eigen::Vector3d& phi) {
  const double theta2 = phi.squaredNorm();
  const Eigen::Matrix3d K = hat(phi);
  if (theta2 < kSmallAngle * kSmallAngle) return Eigen::Matrix3d::Identity() + 0.5 * K + (1.0 / 12.0) * K * K;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() + 0.5 * K +
         (1.0 / theta2 - (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta))) * K * K;
}

inline Eigen::Matrix3d left_jacobian_inverse(const Eigen::Vector3d& phi) {
  return right_jacobian_inverse(-phi);
}

}  // namespace imucal::calib::so3
