// SPDX-License-Identifier: BSD-3-Clause
#include "calib/static_faces.hpp"

#include <Eigen/Dense>
#include <cmath>

namespace imucal::calib {
namespace {

Eigen::Vector3d face_axis(int face) {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  e[face / 2] = face % 2 == 0 ? 1.0 : -1.0;
  return e;
}

using Vec9 = Eigen::Matrix<double, 9, 1>;
using Vec12 = Eigen::Matrix<double, 12, 1>;

/// [A row by row, c] of a = A m + c  ->  the Tedaldi parameters of eq. 3.2 (angles, scales, bias
/// in Tedaldi's sign: a_O = T K (m + b)), and Q with A = Q T K. False when A is singular or
/// mirrors (a face taken for its opposite).
bool tedaldi_of(const Vec12& theta, Vec9* p, Eigen::Matrix3d* Q) {
  Eigen::Matrix3d A;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) A(r, c) = theta[3 * r + c];
  const Eigen::Vector3d offset = theta.tail<3>();
  if (!(A.determinant() > 0.0)) return false;
  const Eigen::HouseholderQR<Eigen::Matrix3d> qr(A);
  Eigen::Matrix3d q = qr.householderQ();
  Eigen::Matrix3d u = qr.matrixQR().triangularView<Eigen::Upper>();
  for (int i = 0; i < 3; ++i) {
    if (u(i, i) < 0.0) {
      u.row(i) *= -1.0;
      q.col(i) *= -1.0;
    }
  }
  const Eigen::Vector3d k = u.diagonal();
  const Eigen::Matrix3d T = u * k.cwiseInverse().asDiagonal();
  // a = A m + c = A (m + A^-1 c): Tedaldi's bias is A^-1 c.
  *p << accel_angles(T), k, A.partialPivLu().solve(offset);
  if (Q) *Q = q;
  return p->allFinite();
}

}  // namespace

std::string face_name(int face) { return std::string(face % 2 == 0 ? "+" : "-") + "xyz"[face / 2] + " up"; }

std::string face_in_words(int face) {
  const char axis = "XYZ"[face / 2];
  const bool plus = face % 2 == 0;
  return std::string(plus ? "+" : "-") + axis + " up (resting on its " + (plus ? "-" : "+") + axis + " face)";
}

std::vector<int> assign_faces(const std::vector<Eigen::Vector3d>& directions, double max_angle_rad) {
  std::vector<int> out;
  out.reserve(directions.size());
  const double cos_max = std::cos(max_angle_rad);
  for (const auto& d : directions) {
    int best = -1;
    double best_cos = cos_max;
    for (int f = 0; f < kFaceCount; ++f) {
      const double c = d.normalized().dot(face_axis(f));
      if (c >= best_cos) {
        best_cos = c;
        best = f;
      }
    }
    out.push_back(best);
  }
  return out;
}

std::array<int, kFaceCount> face_counts(const std::vector<int>& faces) {
  std::array<int, kFaceCount> n{};
  for (int f : faces)
    if (f >= 0) ++n[static_cast<std::size_t>(f)];
  return n;
}

std::string missing_faces_in_words(const std::array<int, kFaceCount>& counts) {
  std::string out;
  for (int f = 0; f < kFaceCount; ++f) {
    if (counts[static_cast<std::size_t>(f)] > 0) continue;
    if (!out.empty()) out += ", ";
    out += face_in_words(f);
  }
  return out;
}

KnownOrientationFit fit_known_orientation(const std::vector<Eigen::Vector3d>& means,
                                          const std::vector<int>& faces, double gravity_mps2) {
  KnownOrientationFit fit;
  std::vector<std::size_t> used;
  for (std::size_t k = 0; k < means.size() && k < faces.size(); ++k)
    if (faces[k] >= 0) used.push_back(k);
  const std::string missing = missing_faces_in_words(face_counts(faces));
  if (!missing.empty()) {
    fit.error = "no pose with " + missing;
    return fit;
  }
  const auto n = static_cast<Eigen::Index>(used.size());
  // Centred and scaled columns: raw counts with offsets near 32768 would otherwise leave the
  // normal equations ill-conditioned.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (std::size_t k : used) centre += means[k];
  centre /= static_cast<double>(n);
  Eigen::Vector3d spread = Eigen::Vector3d::Zero();
  for (std::size_t k : used) spread += (means[k] - centre).cwiseAbs2();
  spread = (spread / static_cast<double>(n)).cwiseSqrt().cwiseMax(1e-300);
  Eigen::MatrixXd X(n, 4), Y(n, 3);
  for (Eigen::Index r = 0; r < n; ++r) {
    const std::size_t k = used[static_cast<std::size_t>(r)];
    X.row(r) << ((means[k] - centre).cwiseQuotient(spread)).transpose(), 1.0;
    Y.row(r) = gravity_mps2 * face_axis(faces[k]).transpose();
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(X);
  if (qr.rank() < 4) {
    fit.error = "the poses' means do not span three dimensions";
    return fit;
  }
  const Eigen::MatrixXd beta = qr.solve(Y);  // 4 x 3: column i gives output axis i
  const Eigen::MatrixXd R = Y - X * beta;
  fit.residuals = static_cast<int>(3 * n);
  const Eigen::Matrix4d XtX_inv = (X.transpose() * X).inverse();
  // beta -> [A_i0, A_i1, A_i2, c_i] of a_i = A_i m + c_i (the same linear map for every axis).
  Eigen::Matrix4d L = Eigen::Matrix4d::Zero();
  for (int j = 0; j < 3; ++j) {
    L(j, j) = 1.0 / spread[j];
    L(3, j) = -centre[j] / spread[j];
  }
  L(3, 3) = 1.0;
  Vec12 theta;
  Eigen::Matrix<double, 12, 12> cov_theta = Eigen::Matrix<double, 12, 12>::Zero();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector4d t = L * beta.col(i);
    theta.segment<3>(3 * i) = t.head<3>();
    theta[9 + i] = t[3];
    // Each axis's residual variance; undetermined (NaN) without degrees of freedom.
    const double s2 = n > 4 ? R.col(i).squaredNorm() / static_cast<double>(n - 4) : nan;
    const Eigen::Matrix4d V = L * XtX_inv * L.transpose() * s2;
    std::array<int, 4> idx = {3 * i, 3 * i + 1, 3 * i + 2, 9 + i};
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        cov_theta(idx[static_cast<std::size_t>(a)], idx[static_cast<std::size_t>(b)]) = V(a, b);
  }
  Vec9 p;
  if (!tedaldi_of(theta, &p, &fit.Q)) {
    fit.error = "the fitted matrix is singular or mirrors an axis (are the axes of the log right-handed?)";
    return fit;
  }
  // Central differences of the decomposition, each step small against its entry's row.
  Eigen::Matrix<double, 9, 12> J;
  for (int j = 0; j < 12; ++j) {
    const double typical = j < 9 ? theta.segment<3>(3 * (j / 3)).norm() : gravity_mps2;
    const double h = 1e-6 * std::max(typical, 1e-300);
    Vec12 up = theta, down = theta;
    up[j] += h;
    down[j] -= h;
    Vec9 pu, pd;
    if (!tedaldi_of(up, &pu, nullptr) || !tedaldi_of(down, &pd, nullptr)) {
      fit.error = "the fitted matrix is too close to singular";
      return fit;
    }
    J.col(j) = (pu - pd) / (2.0 * h);
  }
  fit.covariance = J * cov_theta * J.transpose();
  fit.triad.T = accel_misalignment(p.head<3>());
  fit.triad.scale = p.segment<3>(3);
  fit.triad.bias = p.tail<3>();
  fit.q_angle_rad = Eigen::AngleAxisd(fit.Q).angle();
  double sum_sq = 0.0;
  for (std::size_t k : used) {
    const Eigen::Vector3d a = fit.Q * fit.triad.apply(means[k]);
    const double e = std::acos(std::clamp(a.normalized().dot(face_axis(faces[k])), -1.0, 1.0));
    fit.direction_error_rad.push_back(e);
    sum_sq += e * e;
  }
  fit.direction_rms_rad = std::sqrt(sum_sq / static_cast<double>(n));
  fit.ok = true;
  return fit;
}

}  // namespace imucal::calib
