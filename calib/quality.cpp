// SPDX-License-Identifier: BSD-3-Clause
#include "calib/quality.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "calib/rk4.hpp"

namespace imucal::calib {
namespace {

void add(ErrorFigures& f, double mps2, double rad) {
  ++f.count;
  f.mean_mps2 += mps2;
  f.mean_rad += rad;
  f.max_mps2 = std::max(f.max_mps2, mps2);
  f.max_rad = std::max(f.max_rad, rad);
}

void finish(ErrorFigures& f) {
  if (f.count == 0) return;
  f.mean_mps2 /= f.count;
  f.mean_rad /= f.count;
}

}  // namespace

ErrorFigures gravity_magnitude_error(std::span<const Eigen::Vector3d> raw_means, const TedaldiTriad& accel,
                                     double gravity) {
  ErrorFigures f;
  for (const auto& m : raw_means) {
    const double err = std::abs(accel.apply(m).norm() - gravity);
    add(f, err, std::asin(std::min(1.0, err / gravity)));
  }
  finish(f);
  return f;
}

ErrorFigures gravity_direction_error(std::span<const GravityTransfer> transfers, const TedaldiTriad& gyro,
                                     double gravity) {
  ErrorFigures f;
  std::vector<Eigen::Vector3d> w;
  for (const auto& tr : transfers) {
    w.resize(tr.gyro_raw.size());
    for (std::size_t i = 0; i < w.size(); ++i) w[i] = gyro.apply(tr.gyro_raw[i]);
    const Eigen::Matrix3d R = quat_to_matrix(integrate_rk4n(w, tr.t_s));
    const Eigen::Vector3d u_pred = R.transpose() * tr.u0;
    const double angle = std::atan2(u_pred.cross(tr.u1).norm(), u_pred.dot(tr.u1));
    add(f, gravity * (tr.u1 - u_pred).norm(), angle);
  }
  finish(f);
  return f;
}

}  // namespace imucal::calib
