// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The covariance of a few parameter blocks of a large least-squares problem, marginalised over
// all the others by a Schur complement: with H = J^T J split into the blocks of interest (g) and
// the rest (l), Cov_gg = (H_gg - H_gl H_ll^-1 H_lg)^-1. H_ll (the spline knots: banded) is
// factorised once by a sparse Cholesky (Eigen's SimplicialLDLT) and solved for the few columns
// of H_lg. ceres::Covariance computes the same blocks through a sparse QR of the whole Jacobian,
// which on a 90 s camera-IMU problem took as long as the solve (docs/camimu-calibration.md).
//
// A problem whose data do not determine every wanted parameter still gets a covariance: the
// Schur complement S is scaled by its diagonal (S' = D S D, D = diag(S)^-1/2, so every parameter
// weighs alike whatever its unit) and decomposed into eigenvectors. Directions whose eigenvalue
// is below kRankTolerance of the largest are the undetermined ones; the covariance is the
// pseudo-inverse on the rest, and every coordinate with a component along an undetermined
// direction gets a NaN row and column ("not determined"), never a number that looks like one.

#include <ceres/problem.h>

#include <Eigen/Core>
#include <map>
#include <vector>

namespace imucal::calib {

class MarginalCovariance {
 public:
  /// Relative eigenvalue (of the diagonally scaled Schur complement) below which a direction is
  /// taken as undetermined: its standard deviation would be over 1e5 times what the parameters'
  /// own information gives them.
  static constexpr double kRankTolerance = 1e-10;
  /// A coordinate whose squared component along an undetermined direction exceeds this has no
  /// finite variance.
  static constexpr double kNullComponent = 1e-6;

  /// One coordinate of a wanted block (tangent space).
  struct Coordinate {
    const double* block = nullptr;
    int index = 0;
  };
  /// An undetermined direction: the coordinates it moves, largest first, with their weights in
  /// the scaled coordinates (unit vector; only those of at least 0.1 of the largest).
  struct Direction {
    std::vector<std::pair<Coordinate, double>> parts;
  };

  /// Computes the covariance of `blocks` (tangent space, loss functions applied) at the
  /// problem's current values. Blocks held constant are left out (has() is false for them).
  /// False only when the problem cannot be evaluated there.
  ///
  /// With `clusters` (groups of residual blocks whose errors may be shared, such as the views of
  /// one frame), it also computes the cluster-robust (sandwich) covariance of the same blocks:
  ///   Cov_r = S^-1 (C / (C - 1) sum_c u_c u_c^T) S^-1,  u_c = [-H_gl H_ll^-1, I] J_c^T r_c,
  /// S the Schur complement above, C the number of clusters (every residual block in no cluster
  /// is a cluster of its own). It equals the plain covariance in expectation when the residuals
  /// are independent and correctly weighted, and grows when residuals of a cluster share an
  /// error or the weights are too high (docs/camera-calibration.md, "Several cameras").
  ///
  /// With `held` (inputs held fixed in the problem whose own uncertainty should reach the result,
  /// such as a camera's intrinsics), each entry is the change of the gradient's Gauss-Newton part,
  /// J^T dr, when the held input moves by one column of a square root of its covariance (L with
  /// L L^T = its covariance): tangent-space vectors per parameter block (a block may appear more
  /// than once: its parts are summed; constant blocks are ignored). Its effect on the wanted
  /// blocks, linearised at the solution, is
  ///   Cov_h = S^-1 (sum_j u_j u_j^T) S^-1,  u_j = [-H_gl H_ll^-1, I] J^T dr_j,
  /// the spread that the input's own error (independent of these data) causes in the wanted
  /// blocks: solving again with the input moved by L's column j moves them by -S^-1 u_j.
  /// held_block() returns it; block() and robust_block() leave it out, so callers add it where
  /// the result's sigmas are formed.
  using HeldScore = std::vector<std::pair<const double*, Eigen::VectorXd>>;
  bool compute(ceres::Problem& problem, const std::vector<const double*>& blocks, int threads,
               const std::vector<std::vector<ceres::ResidualBlockId>>& clusters = {},
               const std::vector<HeldScore>& held = {});

  /// The covariance block of two blocks passed to compute(), tangent space; NaN where a
  /// coordinate is not determined.
  Eigen::MatrixXd block(const double* a, const double* b) const;
  bool has(const double* b) const { return offset_.count(b) != 0; }
  /// The cluster-robust covariance block (compute() with clusters); NaN where not determined.
  Eigen::MatrixXd robust_block(const double* a, const double* b) const;
  bool has_robust() const { return robust_.size() > 0; }
  /// The held inputs' share of the covariance (compute() with held; zero without); NaN where a
  /// coordinate is not determined.
  Eigen::MatrixXd held_block(const double* a, const double* b) const;
  bool has_held() const { return held_.size() > 0; }
  int clusters() const { return clusters_; }

  /// The directions the data do not determine (empty when the wanted blocks are all determined).
  const std::vector<Direction>& undetermined() const { return undetermined_; }
  /// True when the other parameters (H_ll) were singular and had to be regularised: the
  /// covariance is then conditioned on a weak prior on them.
  bool nuisance_regularised() const { return nuisance_regularised_; }

 private:
  Eigen::MatrixXd cov_;
  Eigen::MatrixXd robust_;
  Eigen::MatrixXd held_;
  int clusters_ = 0;
  std::map<const double*, std::pair<int, int>> offset_;  // offset, tangent size
  std::vector<Direction> undetermined_;
  bool nuisance_regularised_ = false;
};

/// The square roots of a covariance's diagonal, NaN kept (a negative variance from rounding is 0).
Eigen::VectorXd sigma_of(const Eigen::MatrixXd& cov);

}  // namespace imucal::calib
