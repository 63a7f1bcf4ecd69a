// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The gyroscope at rest in the static calibration: one linear fit of its bias, g-sensitivity and
// bias drift over the still start and every pose's mean, with Newey-West covariances. Internal to
// calib/static_calibration.cpp, which runs it for each threshold candidate and for the result.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "calib/static_calibration.hpp"
#include "calib/static_steps.hpp"
#include "core/imu_calibration.hpp"

namespace imucal::calib {

/// The gyroscope at rest: the mean of still pose k is b_g + H a_k + noise (the bias, the
/// g-sensitivity H = A_g^-1 G in input units per m/s^2 acting on the calibrated specific force
/// a_k, and whatever rotation or bias drift the pose holds). One linear fit per axis over the
/// still start and every pose, unweighted, its covariance scaled by the residual variance.
struct GyroStaticFit {
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();  // b_g over the session, input units (canonical sign)
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  /// Bias drift over the session: b(t) = bias + drift_at(t), a quadratic in
  /// tau = (t - t_mid_s) / t_half_s that averages to zero over the poses' span (zero when not fitted).
  Eigen::Matrix<double, 3, 2> drift = Eigen::Matrix<double, 3, 2>::Zero();
  double t_mid_s = 0.0, t_half_s = 1.0;
  Eigen::Vector3d drift_offset = Eigen::Vector3d::Zero();  // makes the drift average to 0
  Eigen::Vector3d drift_at(double t_s) const {
    const double tau = (t_s - t_mid_s) / t_half_s;
    return drift.col(0) * tau + drift.col(1) * tau * tau + drift_offset;
  }
  Eigen::Vector3d bias_sigma = Eigen::Vector3d::Zero();
  Eigen::Matrix3d H_sigma = Eigen::Matrix3d::Zero();
  FitDof dof;
  double rms = 0.0;                       // of the residual rates, input units
  std::vector<Eigen::Vector3d> residual;  // per pose: mean - b_g - H a
};

/// The still start's and the poses' means (the still start first) and their mid times.
struct PoseMeans {
  std::vector<Eigen::Vector3d> gyro, accel_si;
  std::vector<double> t_s;
};

/// Bias drift terms fitted with `poses` means: a quadratic in time once there are enough poses
/// to spare the degrees of freedom, then a line, then none.
inline int drift_terms(std::size_t poses) { return poses >= 20 ? 2 : poses >= 12 ? 1 : 0; }

/// Newey-West covariances of a least-squares fit Y = X beta + R, one per column of R (Bartlett
/// weights, lag 4 (n/100)^(2/9)), with leverage-inflated residuals (HC3: the sandwich is otherwise
/// too small for the few tens of poses a session has) and Stata's degrees-of-freedom factor
/// n / (n - p).
std::vector<Eigen::MatrixXd> newey_west_covariances(const Eigen::MatrixXd& X, const Eigen::MatrixXd& R,
                                                    const Eigen::MatrixXd& XtX_inv, int dof);

/// Fits the gyroscope's means `m` (the still start first): bias and, by `mode`, the
/// g-sensitivity (estimated, or `H_fixed`), and the drift terms the poses can spare.
GyroStaticFit fit_gyro_static(const PoseMeans& m, const StillStart& still, GSensitivityMode mode,
                              const Eigen::Matrix3d& H_fixed, bool fit_gsens = true);

}  // namespace imucal::calib
