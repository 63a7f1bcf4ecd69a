#include "calib/marginal_covariance.hpp"

#include <ceres/crs_matrix.h>

#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <set>

namespace imucal::calib {

bool MarginalCovariance::compute(ceres::Problem& problem, const std::vector<const double*>& blocks,
                                 int threads) {
  offset_.clear();
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
  for (const double* b : blocks) {
    if (!wanted.count(b) || offset_.count(b)) continue;
    const int size = problem.ParameterBlockTangentSize(b);
    offset_[b] = {ng, size};
    ng += size;
    order.push_back(const_cast<double*>(b));
  }
  ceres::Problem::EvaluateOptions eo;
  eo.parameter_blocks = order;
  eo.num_threads = threads;
  ceres::CRSMatrix crs;
  if (!problem.Evaluate(eo, nullptr, nullptr, nullptr, &crs)) return false;
  Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> J(
      crs.num_rows, crs.num_cols, static_cast<Eigen::Index>(crs.values.size()), crs.rows.data(),
      crs.cols.data(), crs.values.data());
  const Eigen::SparseMatrix<double> H = Eigen::SparseMatrix<double>(J.transpose()) * J;
  const Eigen::SparseMatrix<double> H_ll = H.topLeftCorner(nl, nl);
  const Eigen::MatrixXd H_lg = Eigen::MatrixXd(H.topRightCorner(nl, ng));
  Eigen::MatrixXd S = Eigen::MatrixXd(H.bottomRightCorner(ng, ng));
  if (nl > 0) {
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(H_ll);
    if (ldlt.info() != Eigen::Success || (ldlt.vectorD().array() <= 0.0).any()) return false;
    S -= H_lg.transpose() * ldlt.solve(H_lg);
  }
  const Eigen::LDLT<Eigen::MatrixXd> s_ldlt(S);
  if (s_ldlt.info() != Eigen::Success || !s_ldlt.isPositive() || (s_ldlt.vectorD().array() <= 0.0).any())
    return false;
  cov_ = s_ldlt.solve(Eigen::MatrixXd::Identity(ng, ng));
  return cov_.allFinite();
}

Eigen::MatrixXd MarginalCovariance::block(const double* a, const double* b) const {
  const auto& [oa, na] = offset_.at(a);
  const auto& [ob, nb] = offset_.at(b);
  return cov_.block(oa, ob, na, nb);
}

}  // namespace imucal::calib
