#pragma once
// The covariance of a few parameter blocks of a large least-squares problem, marginalised over
// all the others by a Schur complement: with H = J^T J split into the blocks of interest (g) and
// the rest (l), Cov_gg = (H_gg - H_gl H_ll^-1 H_lg)^-1. H_ll (the spline knots: banded) is
// factorised once by a sparse Cholesky (Eigen's SimplicialLDLT) and solved for the few columns
// of H_lg. ceres::Covariance computes the same blocks through a sparse QR of the whole Jacobian,
// which on a 90 s camera-IMU problem took as long as the solve (docs/camimu-calibration.md).

#include <ceres/problem.h>

#include <Eigen/Core>
#include <map>
#include <vector>

namespace imucal::calib {

class MarginalCovariance {
 public:
  /// Computes the covariance of `blocks` (tangent space, loss functions applied) at the
  /// problem's current values. Blocks held constant are left out (their covariance is zero).
  /// False when H is not positive definite (a parameter is not observable).
  bool compute(ceres::Problem& problem, const std::vector<const double*>& blocks, int threads);

  /// The covariance block of two blocks passed to compute(), tangent space.
  Eigen::MatrixXd block(const double* a, const double* b) const;
  bool has(const double* b) const { return offset_.count(b) != 0; }

 private:
  Eigen::MatrixXd cov_;
  std::map<const double*, std::pair<int, int>> offset_;  // offset, tangent size
};

}  // namespace imucal::calib
