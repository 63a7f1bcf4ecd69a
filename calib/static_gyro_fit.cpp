// SPDX-License-Identifier: BSD-3-Clause
#include "calib/static_gyro_fit.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace imucal::calib {

std::vector<Eigen::MatrixXd> newey_west_covariances(const Eigen::MatrixXd& X, const Eigen::MatrixXd& R,
                                                    const Eigen::MatrixXd& XtX_inv, int dof) {
  const auto n = static_cast<std::size_t>(X.rows());
  const Eigen::Index p = X.cols();
  const int lag = static_cast<int>(std::floor(4.0 * std::pow(static_cast<double>(n) / 100.0, 2.0 / 9.0)));
  Eigen::MatrixXd Ra = R;
  for (std::size_t k = 0; k < n; ++k) {
    const double h = X.row(k) * XtX_inv * X.row(k).transpose();
    Ra.row(k) /= std::max(1.0 - h, 0.05);
  }
  std::vector<Eigen::MatrixXd> out;
  for (Eigen::Index col = 0; col < R.cols(); ++col) {
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(p, p);
    for (std::size_t k = 0; k < n; ++k) S += Ra(k, col) * Ra(k, col) * X.row(k).transpose() * X.row(k);
    for (int l = 1; l <= lag; ++l) {
      const double w = 1.0 - static_cast<double>(l) / (lag + 1.0);
      for (std::size_t k = static_cast<std::size_t>(l); k < n; ++k) {
        const Eigen::MatrixXd xx = X.row(k).transpose() * X.row(k - l);
        S += w * Ra(k, col) * Ra(k - l, col) * (xx + xx.transpose());
      }
    }
    out.push_back(XtX_inv * S * XtX_inv * (static_cast<double>(n) / std::max(1, dof)));
  }
  return out;
}

GyroStaticFit fit_gyro_static(const PoseMeans& m, const StillStart& still, GSensitivityMode mode,
                              const Eigen::Matrix3d& H_fixed, bool fit_gsens) {
  GyroStaticFit f;
  const auto& gyro_means = m.gyro;
  const auto& accel_si = m.accel_si;
  const std::size_t n = gyro_means.size();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (mode == GSensitivityMode::kEstimate) {
    // Regressors [1, a, tau, tau^2]: the bias wanders over a session (random walk, warm-up) by as
    // much as the g-sensitivity moves the pose means, so a smooth drift is fitted with them.
    // Without G (fit_gsens false: G not distinguishable from zero) the bias and its drift are
    // still fitted to the poses: a short or disturbed still start says less about them.
    const int na = fit_gsens ? 3 : 0;
    const int nd = drift_terms(n);
    const int p = 1 + na + nd;
    const auto [t_lo, t_hi] = std::minmax_element(m.t_s.begin(), m.t_s.end());
    f.t_mid_s = 0.5 * (*t_lo + *t_hi);
    f.t_half_s = std::max(0.5 * (*t_hi - *t_lo), 1e-9);
    Eigen::MatrixXd X(n, p), Y(n, 3);
    for (std::size_t k = 0; k < n; ++k) {
      const double tau = (m.t_s[k] - f.t_mid_s) / f.t_half_s;
      X(k, 0) = 1.0;
      if (fit_gsens) X.row(k).segment<3>(1) = accel_si[k].transpose();
      for (int d = 0; d < nd; ++d) X(k, 1 + na + d) = std::pow(tau, d + 1);
      Y.row(k) = gyro_means[k].transpose();
    }
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(X);
    const Eigen::MatrixXd beta = qr.solve(Y);  // p x 3: [b; H^T; drift]
    f.bias = beta.row(0).transpose();
    if (fit_gsens) f.H = beta.middleRows(1, 3).transpose();
    for (int d = 0; d < nd; ++d) f.drift.col(d) = beta.row(1 + na + d).transpose();
    // Report the bias averaged over the span (see the sigma below) and keep the drift about it.
    if (nd == 2) {
      f.bias += f.drift.col(1) / 3.0;
      f.drift_offset = -f.drift.col(1) / 3.0;
    }
    f.dof = {static_cast<int>(n), p};
    const Eigen::MatrixXd R = Y - X * beta;
    const bool full_rank = qr.rank() == p;
    const Eigen::MatrixXd XtX_inv =
        full_rank ? Eigen::MatrixXd((X.transpose() * X).inverse()) : Eigen::MatrixXd::Constant(p, p, nan);
    // The pose errors are not independent: the bias wanders (a random walk) and consecutive poses
    // are close in attitude, so errors and regressors are both correlated from pose to pose, and
    // the textbook s^2 (X'X)^-1 is too small (by about 2 on the virtual rig). Newey-West's
    // covariance (Bartlett weights, lag 4 (n/100)^(2/9)) holds with such errors. Undetermined
    // (NaN) without degrees of freedom.
    const std::vector<Eigen::MatrixXd> cov = newey_west_covariances(X, R, XtX_inv, f.dof.dof());
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::MatrixXd& V = cov[static_cast<std::size_t>(axis)];
      const Eigen::VectorXd sd = V.diagonal().unaryExpr([](double v) { return std::sqrt(std::max(v, 0.0)); });
      // The reported bias is b(t) averaged over the span of the poses (tau uniform in [-1, 1]:
      // mean tau 0, mean tau^2 1/3), the bias a user of the whole recording saw.
      Eigen::VectorXd l = Eigen::VectorXd::Zero(p);
      l[0] = 1.0;
      if (nd == 2) l[2 + na] = 1.0 / 3.0;
      f.bias_sigma[axis] = std::sqrt(std::max(l.dot(V * l), 0.0));
      if (!f.dof.determined()) {
        f.bias_sigma[axis] = nan;
        f.H_sigma.row(axis).setConstant(nan);
        continue;
      }
      if (fit_gsens) f.H_sigma.row(axis) = sd.segment<3>(1).transpose();
    }
    if (!full_rank) f.H_sigma.setConstant(nan);
  } else {
    f.H = mode == GSensitivityMode::kFixed ? H_fixed : Eigen::Matrix3d::Zero();
    if (mode == GSensitivityMode::kFixed) {
      for (std::size_t k = 0; k < n; ++k) f.bias += gyro_means[k] - f.H * accel_si[k];
      f.bias /= static_cast<double>(n);
      f.dof = {static_cast<int>(n), 1};
    } else {
      f.bias = still.gyro_bias_raw;
      f.bias_sigma = still.gyro_bias_sigma;
      f.dof = {static_cast<int>(n), 0};
    }
  }
  f.residual.resize(n);
  double sum_sq = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    f.residual[k] = gyro_means[k] - f.bias - f.H * accel_si[k] - f.drift_at(m.t_s[k]);
    sum_sq += f.residual[k].squaredNorm();
  }
  f.rms = std::sqrt(sum_sq / (3.0 * static_cast<double>(std::max<std::size_t>(n, 1))));
  if (mode == GSensitivityMode::kFixed) {
    for (int axis = 0; axis < 3; ++axis) {
      double ss = 0.0;
      for (std::size_t k = 0; k < n; ++k) ss += f.residual[k][axis] * f.residual[k][axis];
      f.bias_sigma[axis] = n > 1 ? std::sqrt(ss / static_cast<double>(n - 1) / static_cast<double>(n)) : nan;
    }
  }
  return f;
}

}  // namespace imucal::calib
