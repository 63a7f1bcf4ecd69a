// SPDX-License-Identifier: BSD-3-Clause
#include "calib/ellipsoid.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <cmath>
#include <string>

namespace imucal::calib {

Result<TedaldiTriad> fit_ellipsoid(std::span<const Eigen::Vector3d> points, double gravity) {
  const Eigen::Index n = static_cast<Eigen::Index>(points.size());
  if (n < 9) {
    return make_error(Errc::kInsufficientData,
                      "an ellipsoid fit needs at least 9 static attitudes, got " + std::to_string(n));
  }
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const auto& p : points) m += p;
  m /= static_cast<double>(n);
  double s = 0.0;
  for (const auto& p : points) s += (p - m).squaredNorm();
  s = std::sqrt(s / static_cast<double>(n));
  if (!(s > 0.0)) return make_error(Errc::kInsufficientData, "the static means are all equal");

  Eigen::MatrixXd D(n, 9);
  for (Eigen::Index k = 0; k < n; ++k) {
    const Eigen::Vector3d y = (points[static_cast<std::size_t>(k)] - m) / s;
    D.row(k) << y[0] * y[0], y[1] * y[1], y[2] * y[2], 2 * y[0] * y[1], 2 * y[0] * y[2], 2 * y[1] * y[2],
        2 * y[0], 2 * y[1], 2 * y[2];
  }
  const Eigen::VectorXd th = D.colPivHouseholderQr().solve(Eigen::VectorXd::Ones(n));
  Eigen::Matrix3d Q;
  Q << th[0], th[3], th[4], th[3], th[1], th[5], th[4], th[5], th[2];
  const Eigen::Vector3d l(th[6], th[7], th[8]);
  if (!Q.allFinite() || std::abs(Q.determinant()) < 1e-12) {
    return make_error(Errc::kSolverFailed,
                      "the static means do not determine an ellipsoid: the attitudes "
                      "do not cover enough directions");
  }
  const Eigen::Vector3d yc = -Q.inverse() * l;
  const double r = 1.0 + yc.dot(Q * yc);
  Eigen::LLT<Eigen::Matrix3d> llt(Q / r);
  if (!(r > 0.0) || llt.info() != Eigen::Success) {
    return make_error(Errc::kSolverFailed,
                      "the static means do not lie on an ellipsoid: check that the "
                      "recording holds static poses in many attitudes");
  }
  const Eigen::Matrix3d U = (gravity / s) * Eigen::Matrix3d(llt.matrixU());
  TedaldiTriad out;
  out.scale = U.diagonal();
  out.T = U * U.diagonal().cwiseInverse().asDiagonal();
  out.bias = -(m + s * yc);
  return out;
}

}  // namespace imucal::calib
