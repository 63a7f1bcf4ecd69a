// SPDX-License-Identifier: BSD-3-Clause
#include "calib/rk4.hpp"

namespace imucal::calib {

Quat4 rk4n_step(const Quat4& q, const Eigen::Vector3d& w0, const Eigen::Vector3d& w1, double h) {
  using detail::omega_mul;
  const Eigen::Vector3d wm = 0.5 * (w0 + w1);
  const Quat4 k1 = 0.5 * omega_mul(q, w0);
  const Quat4 k2 = 0.5 * omega_mul(q + 0.5 * h * k1, wm);
  const Quat4 k3 = 0.5 * omega_mul(q + 0.5 * h * k2, wm);
  const Quat4 k4 = 0.5 * omega_mul(q + h * k3, w1);
  const Quat4 p = q + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
  return p / p.norm();
}

Quat4 integrate_rk4n(std::span<const Eigen::Vector3d> w, std::span<const double> t_s) {
  Quat4 q(1, 0, 0, 0);
  for (std::size_t i = 0; i + 1 < w.size(); ++i) q = rk4n_step(q, w[i], w[i + 1], t_s[i + 1] - t_s[i]);
  return q;
}

void rate_gradient_first_order(std::span<const Quat4> q, std::span<const double> t_s,
                               const Eigen::Vector3d& u0, std::vector<Eigen::Matrix3d>& df_dw) {
  const std::size_t n = q.size();
  df_dw.assign(n, Eigen::Matrix3d::Zero());
  if (n < 2) return;
  Eigen::Matrix3d skew_u0;
  skew_u0 << 0, -u0.z(), u0.y(), u0.z(), 0, -u0.x(), -u0.y(), u0.x(), 0;
  const Eigen::Matrix3d C = quat_to_matrix(q[n - 1]).transpose() * skew_u0;
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const Eigen::Matrix3d half =
        (0.5 * (t_s[k + 1] - t_s[k])) * (C * quat_to_matrix((q[k] + q[k + 1]).normalized()));
    df_dw[k] += half;
    df_dw[k + 1] += half;
  }
}

Eigen::Matrix3d quat_to_matrix(const Quat4& q) {
  const double a = q[0], b = q[1], c = q[2], d = q[3];
  Eigen::Matrix3d R;
  R << a * a + b * b - c * c - d * d, 2 * b * c - 2 * a * d, 2 * b * d + 2 * a * c,  //
      2 * b * c + 2 * a * d, a * a - b * b + c * c - d * d, 2 * c * d - 2 * a * b,   //
      2 * b * d - 2 * a * c, 2 * c * d + 2 * a * b, a * a - b * b - c * c + d * d;
  return R;
}

}  // namespace imucal::calib
