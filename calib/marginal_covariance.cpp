// SPDX-License-Identifier: BSD-3-Clause
#include "calib/marginal_covariance.hpp"

#include <ceres/cost_function.h>
#include <ceres/crs_matrix.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <set>

namespace imucal::calib {

namespace {

/// H_ll^-1 H_lg by a sparse LDLT of H_ll scaled to unit diagonal (the knots mix metres, radians
/// and biases with weights over ten decades apart); when it is still singular (a nuisance
/// direction with no data), again with a ridge of 1e-9 of the scaled diagonal. False when even
/// that fails.
bool solve_nuisance(const Eigen::SparseMatrix<double>& H_ll, const Eigen::MatrixXd& H_lg, Eigen::MatrixXd* X,
                    bool* regularised) {
  const auto ok = [](const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>& f) {
    return f.info() == Eigen::Success && (f.vectorD().array() > 0.0).all();
  };
  const Eigen::Index n = H_ll.rows();
  Eigen::VectorXd d(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double h = H_ll.coeff(i, i);
    d(i) = h > 0.0 ? 1.0 / std::sqrt(h) : 1.0;
  }
  Eigen::SparseMatrix<double> S = d.asDiagonal() * H_ll * d.asDiagonal();
  // A parameter no residual touches (a knot past the last sample) has a zero row and column: it
  // is coupled to nothing, so it is taken out with a unit diagonal and no note.
  for (Eigen::Index i = 0; i < n; ++i)
    if (!(H_ll.coeff(i, i) > 0.0)) S.coeffRef(i, i) = 1.0;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(S);
  if (!ok(ldlt)) {
    for (Eigen::Index i = 0; i < n; ++i) S.coeffRef(i, i) += 1e-9;
    ldlt.compute(S);
    if (!ok(ldlt)) return false;
    *regularised = true;
  }
  // H^-1 = D (D H D)^-1 D.
  *X = d.asDiagonal() * ldlt.solve(d.asDiagonal() * H_lg);
  return true;
}

/// Every residual block in cluster order (the blocks in no cluster one cluster each), so that the
/// rows of a cluster are known: the blocks into `order`, each row's cluster into `row_cluster`.
/// Returns the number of clusters.
int order_clusters(ceres::Problem& problem, const std::vector<std::vector<ceres::ResidualBlockId>>& clusters,
                   std::vector<ceres::ResidualBlockId>* order, std::vector<int>* row_cluster) {
  int n = 0;
  std::set<ceres::ResidualBlockId> clustered;
  const auto add = [&](ceres::ResidualBlockId id, int cluster) {
    order->push_back(id);
    row_cluster->insert(row_cluster->end(), problem.GetCostFunctionForResidualBlock(id)->num_residuals(),
                        cluster);
  };
  for (const auto& c : clusters) {
    for (ceres::ResidualBlockId id : c)
      if (clustered.insert(id).second) add(id, n);
    ++n;
  }
  std::vector<ceres::ResidualBlockId> every;
  problem.GetResidualBlocks(&every);
  for (ceres::ResidualBlockId id : every)
    if (!clustered.count(id)) add(id, n++);
  return n;
}

/// The held inputs' scores (tangent vectors per block) in the columns of `order` (the rest
/// first, the wanted blocks last), projected: u_j = g_j,wanted - X^T g_j,rest.
Eigen::MatrixXd held_scores(ceres::Problem& problem, const std::vector<double*>& order,
                            const std::vector<MarginalCovariance::HeldScore>& held, const Eigen::MatrixXd& X,
                            int nl, int ng) {
  std::map<const double*, int> column;
  int n = 0;
  for (double* b : order) {
    column[b] = n;
    n += problem.ParameterBlockTangentSize(b);
  }
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, static_cast<Eigen::Index>(held.size()));
  for (std::size_t j = 0; j < held.size(); ++j)
    for (const auto& [block, g] : held[j]) {
      const auto it = column.find(block);
      if (it == column.end()) continue;  // held constant, or not in the problem
      G.col(static_cast<Eigen::Index>(j)).segment(it->second, g.size()) += g;
    }
  Eigen::MatrixXd U = G.bottomRows(ng);
  if (nl > 0) U -= X.transpose() * G.topRows(nl);
  return U;
}

/// Scores J^T D (any residual-space columns D) projected on the wanted parameters (the last ng
/// columns of J) through the Schur complement: U = [-X^T, I] J^T D, X = H_ll^-1 H_lg.
template <class Jacobian>
Eigen::MatrixXd projected_scores(const Jacobian& J, const Eigen::SparseMatrix<double>& D,
                                 const Eigen::MatrixXd& X, int nl, int ng) {
  const Eigen::SparseMatrix<double, Eigen::RowMajor> G = Eigen::SparseMatrix<double>(J.transpose()) * D;
  Eigen::MatrixXd U = Eigen::MatrixXd(G.bottomRows(ng));
  if (nl > 0) U -= (Eigen::SparseMatrix<double>(G.topRows(nl)).transpose() * X).transpose();
  return U;
}

/// The clusters' scores J_c^T r_c projected on the wanted parameters (the last ng columns of J)
/// through the Schur complement: u_c = g_c - X^T l_c, X = H_ll^-1 H_lg (ng x clusters).
template <class Jacobian>
Eigen::MatrixXd cluster_scores(const Jacobian& J, const std::vector<double>& residuals,
                               const std::vector<int>& row_cluster, int clusters, const Eigen::MatrixXd& X,
                               int nl, int ng) {
  std::vector<Eigen::Triplet<double>> t;
  for (std::size_t r = 0; r < residuals.size(); ++r)
    if (residuals[r] != 0.0) t.emplace_back(static_cast<int>(r), row_cluster[r], residuals[r]);
  Eigen::SparseMatrix<double> Rc(J.rows(), clusters);
  Rc.setFromTriplets(t.begin(), t.end());
  return projected_scores(J, Rc, X, nl, ng);
}

/// An undetermined direction (unit vector v over `coords`) as the coordinates it moves, largest
/// first (those of at least 0.1 of the largest).
MarginalCovariance::Direction direction_of(const Eigen::VectorXd& v,
                                           const std::vector<MarginalCovariance::Coordinate>& coords) {
  MarginalCovariance::Direction dir;
  const double top = v.cwiseAbs().maxCoeff();
  std::vector<int> idx;
  for (int i = 0; i < static_cast<int>(v.size()); ++i)
    if (std::abs(v(i)) >= 0.1 * top) idx.push_back(i);
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return std::abs(v(a)) > std::abs(v(b)); });
  for (int i : idx) dir.parts.push_back({coords[static_cast<std::size_t>(i)], v(i)});
  return dir;
}

}  // namespace

bool MarginalCovariance::compute(ceres::Problem& problem, const std::vector<const double*>& blocks,
                                 int threads,
                                 const std::vector<std::vector<ceres::ResidualBlockId>>& clusters,
                                 const std::vector<HeldScore>& held) {
  offset_.clear();
  undetermined_.clear();
  nuisance_regularised_ = false;
  robust_.resize(0, 0);
  held_.resize(0, 0);
  clusters_ = 0;
  std::set<const double*> wanted;
  std::vector<double*> order;  // the rest first, the wanted blocks last
  for (const double* b : blocks)
    if (!problem.IsParameterBlockConstant(b)) wanted.insert(b);
  std::vector<double*> all;
  problem.GetParameterBlocks(&all);
  int nl = 0;
  for (double* b : all) {
    if (wanted.count(b) || problem.IsParameterBlockConstant(b)) continue;
    order.push_back(b);
    nl += problem.ParameterBlockTangentSize(b);
  }
  int ng = 0;
  std::vector<Coordinate> coords;
  for (const double* b : blocks) {
    if (!wanted.count(b) || offset_.count(b)) continue;
    const int size = problem.ParameterBlockTangentSize(b);
    offset_[b] = {ng, size};
    for (int i = 0; i < size; ++i) coords.push_back({b, i});
    ng += size;
    order.push_back(const_cast<double*>(b));
  }
  ceres::Problem::EvaluateOptions eo;
  eo.parameter_blocks = order;
  eo.num_threads = threads;
  std::vector<int> row_cluster;
  if (!clusters.empty()) clusters_ = order_clusters(problem, clusters, &eo.residual_blocks, &row_cluster);
  if (!held.empty() && eo.residual_blocks.empty()) problem.GetResidualBlocks(&eo.residual_blocks);
  ceres::CRSMatrix crs;
  std::vector<double> residuals;
  if (!problem.Evaluate(eo, nullptr, clusters.empty() ? nullptr : &residuals, nullptr, &crs)) return false;
  Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> J(
      crs.num_rows, crs.num_cols, static_cast<Eigen::Index>(crs.values.size()), crs.rows.data(),
      crs.cols.data(), crs.values.data());
  const Eigen::SparseMatrix<double> H = Eigen::SparseMatrix<double>(J.transpose()) * J;
  Eigen::MatrixXd S = Eigen::MatrixXd(H.bottomRightCorner(ng, ng));
  Eigen::MatrixXd X;  // H_ll^-1 H_lg
  if (nl > 0) {
    const Eigen::MatrixXd H_lg = Eigen::MatrixXd(H.topRightCorner(nl, ng));
    if (!solve_nuisance(H.topLeftCorner(nl, nl), H_lg, &X, &nuisance_regularised_)) {
      cov_ = Eigen::MatrixXd::Constant(ng, ng, std::nan(""));
      undetermined_.push_back({});  // nothing about the wanted blocks can be said
      return true;
    }
    S -= H_lg.transpose() * X;
  }
  // The scores of the clusters projected on the wanted blocks, u_c = [-X^T, I] J_c^T r_c.
  Eigen::MatrixXd U;
  if (!clusters.empty()) U = cluster_scores(J, residuals, row_cluster, clusters_, X, nl, ng);
  // The held inputs' scores projected the same way, u_j = [-X^T, I] J^T dr_j.
  Eigen::MatrixXd Uh;
  if (!held.empty()) Uh = held_scores(problem, order, held, X, nl, ng);
  S = 0.5 * (S + S.transpose());
  // Scale every coordinate to unit information, then split determined from undetermined.
  Eigen::VectorXd d(ng);
  for (int i = 0; i < ng; ++i) d(i) = S(i, i) > 0.0 ? 1.0 / std::sqrt(S(i, i)) : 1.0;
  const Eigen::MatrixXd Ss = d.asDiagonal() * S * d.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Ss);
  const Eigen::VectorXd& lambda = eig.eigenvalues();  // ascending
  const Eigen::MatrixXd& V = eig.eigenvectors();
  const double largest = ng > 0 ? std::max(lambda(ng - 1), 0.0) : 0.0;
  Eigen::MatrixXd inv = Eigen::MatrixXd::Zero(ng, ng);
  Eigen::VectorXd null_weight = Eigen::VectorXd::Zero(ng);
  for (int k = 0; k < ng; ++k) {
    if (lambda(k) > kRankTolerance * largest && largest > 0.0) {
      inv += V.col(k) * V.col(k).transpose() / lambda(k);
      continue;
    }
    null_weight += V.col(k).cwiseAbs2();
    undetermined_.push_back(direction_of(V.col(k), coords));
  }
  cov_ = d.asDiagonal() * inv * d.asDiagonal();
  if (clusters_ > 1) {
    const double c = static_cast<double>(clusters_);
    robust_ = cov_ * (c / (c - 1.0) * U * U.transpose()) * cov_;
  }
  if (Uh.size() > 0) held_ = cov_ * (Uh * Uh.transpose()) * cov_;
  for (int i = 0; i < ng; ++i) {
    if (null_weight(i) <= kNullComponent && std::isfinite(cov_(i, i))) continue;
    for (Eigen::MatrixXd* m : {&cov_, &robust_, &held_}) {
      if (m->size() == 0) continue;
      m->row(i).setConstant(std::nan(""));
      m->col(i).setConstant(std::nan(""));
    }
  }
  return true;
}

Eigen::MatrixXd MarginalCovariance::robust_block(const double* a, const double* b) const {
  const auto& [oa, na] = offset_.at(a);
  const auto& [ob, nb] = offset_.at(b);
  if (robust_.size() == 0) return Eigen::MatrixXd::Constant(na, nb, std::nan(""));
  return robust_.block(oa, ob, na, nb);
}

Eigen::MatrixXd MarginalCovariance::held_block(const double* a, const double* b) const {
  const auto& [oa, na] = offset_.at(a);
  const auto& [ob, nb] = offset_.at(b);
  if (held_.size() == 0) return Eigen::MatrixXd::Zero(na, nb);
  return held_.block(oa, ob, na, nb);
}

Eigen::MatrixXd MarginalCovariance::block(const double* a, const double* b) const {
  const auto& [oa, na] = offset_.at(a);
  const auto& [ob, nb] = offset_.at(b);
  return cov_.block(oa, ob, na, nb);
}

Eigen::VectorXd sigma_of(const Eigen::MatrixXd& cov) {
  Eigen::VectorXd s(cov.rows());
  for (Eigen::Index i = 0; i < cov.rows(); ++i) {
    const double v = cov(i, i);
    s(i) = std::isnan(v) ? v : std::sqrt(std::max(v, 0.0));
  }
  return s;
}

}  // namespace imucal::calib
