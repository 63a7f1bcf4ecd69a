// SPDX-License-Identifier: BSD-3-Clause
#include "core/imu_model.hpp"

#include <Eigen/LU>
#include <Eigen/QR>
#include <cmath>

namespace imucal {
namespace {

constexpr double kSingular = 1e-12;

bool invertible(const Eigen::Matrix3d& M) {
  return std::abs(M.determinant()) > kSingular * std::pow(M.norm(), 3) && M.allFinite();
}

}  // namespace

RotationTriangular rotation_triangular_split(const Eigen::Matrix3d& X) {
  Eigen::HouseholderQR<Eigen::Matrix3d> qr(X);
  Eigen::Matrix3d Q = qr.householderQ();
  Eigen::Matrix3d U = qr.matrixQR().triangularView<Eigen::Upper>();
  for (int i = 0; i < 3; ++i) {
    if (U(i, i) < 0) {
      U.row(i) *= -1.0;
      Q.col(i) *= -1.0;
    }
  }
  // After the sign flips Q is a reflection exactly when det(X) < 0. A frame change must be a
  // rotation, so the reflection moves into U(2, 2).
  if (Q.determinant() < 0) {
    U.row(2) *= -1.0;
    Q.col(2) *= -1.0;
  }
  return {Q, U};
}

CanonicalInAof canonical_in_aof(const CanonicalImuModel& model) {
  const RotationTriangular split = rotation_triangular_split(model.A_a);
  const Eigen::Matrix3d R_aof_canonical = split.Q.transpose();
  CanonicalInAof out;
  out.R_canonical_aof = split.Q;
  out.model = model;
  // U itself rather than Q^T A_a, which equals it only up to rounding: the entries below the
  // diagonal are exact zeros, as the Tedaldi form requires.
  out.model.A_a = split.U;
  out.model.A_g = R_aof_canonical * model.A_g;
  out.model.G = R_aof_canonical * model.G * R_aof_canonical.transpose();
  return out;
}

TedaldiTriad tedaldi_triad(const Eigen::Matrix3d& A, const Eigen::Vector3d& b_canonical) {
  TedaldiTriad t;
  t.scale = A.diagonal();
  // K^-1 as the inverse of the full diagonal matrix rather than 1 / diag: the simulator's truth
  // files have always been computed this way, and the last bit of T would otherwise change in
  // every one of them.
  const Eigen::Matrix3d K = A.diagonal().asDiagonal();
  t.T = A * K.inverse();
  t.bias = -b_canonical;
  return t;
}

CanonicalImuModel CanonicalImuModel::expressed_in(const Eigen::Matrix3d& R_new_old) const {
  CanonicalImuModel out = *this;
  out.A_a = R_new_old * A_a;
  out.A_g = R_new_old * A_g;
  out.G = R_new_old * G * R_new_old.transpose();
  return out;
}

Eigen::Matrix3d accel_misalignment(const Eigen::Vector3d& a) {
  Eigen::Matrix3d T = Eigen::Matrix3d::Identity();
  T(0, 1) = -a[0];  // -alpha_yz
  T(0, 2) = a[1];   //  alpha_zy
  T(1, 2) = -a[2];  // -alpha_zx
  return T;
}

Eigen::Vector3d accel_angles(const Eigen::Matrix3d& T) { return {-T(0, 1), T(0, 2), -T(1, 2)}; }

Eigen::Matrix3d gyro_misalignment(const Eigen::Matrix<double, 6, 1>& g) {
  Eigen::Matrix3d T = Eigen::Matrix3d::Identity();
  T(0, 1) = -g[0];  // -gamma_yz
  T(0, 2) = g[1];   //  gamma_zy
  T(1, 0) = g[2];   //  gamma_xz
  T(1, 2) = -g[3];  // -gamma_zx
  T(2, 0) = -g[4];  // -gamma_xy
  T(2, 1) = g[5];   //  gamma_yx
  return T;
}

Eigen::Matrix<double, 6, 1> gyro_angles(const Eigen::Matrix3d& T) {
  Eigen::Matrix<double, 6, 1> g;
  g << -T(0, 1), T(0, 2), T(1, 0), -T(1, 2), -T(2, 0), T(2, 1);
  return g;
}

Eigen::Matrix3d krebs_misalignment(const Eigen::Vector3d& m) {
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  M(1, 0) = m[0];
  M(2, 0) = m[1];
  M(2, 1) = m[2];
  return M;
}

Eigen::Vector3d krebs_entries(const Eigen::Matrix3d& M) { return {M(1, 0), M(2, 0), M(2, 1)}; }

CanonicalImuModel canonical_from_tedaldi(const TedaldiImuModel& model) {
  CanonicalImuModel c;
  c.A_a = model.accel.TK();
  c.b_a = -model.accel.bias;
  c.A_g = model.gyro.TK();
  c.b_g = -model.gyro.bias;
  c.G.setZero();
  return c;
}

Result<TedaldiConversion> tedaldi_from_canonical(const CanonicalImuModel& model) {
  if (!model.G.isZero(0.0)) {
    return make_error(Errc::kInvalidArgument,
                      "the Tedaldi form has no g-sensitivity: the model's G is not zero");
  }
  if (!invertible(model.A_a) || !invertible(model.A_g)) {
    return make_error(Errc::kInvalidArgument, "A_a or A_g is singular: not a usable calibration");
  }
  const CanonicalInAof aof = canonical_in_aof(model);
  for (int i = 0; i < 3; ++i) {
    if (std::abs(aof.model.A_g(i, i)) < kSingular * aof.model.A_g.norm()) {
      return make_error(Errc::kInvalidArgument,
                        "A_g has a zero diagonal entry in the accelerometer frame: the gyro axes "
                        "cannot be mapped to the Tedaldi form");
    }
  }
  TedaldiConversion out;
  out.R_canonical_aof = aof.R_canonical_aof;
  out.model.accel = tedaldi_triad(aof.model.A_a, aof.model.b_a);
  out.model.gyro = tedaldi_triad(aof.model.A_g, aof.model.b_g);
  return out;
}

Result<CanonicalImuModel> canonical_from_krebs(const KrebsImuModel& k) {
  const Eigen::Matrix3d SMa = k.S_a.asDiagonal() * krebs_misalignment(k.M_a);
  const Eigen::Matrix3d SMg = k.S_g.asDiagonal() * krebs_misalignment(k.M_g);
  if (!invertible(SMa) || !invertible(SMg)) {
    return make_error(Errc::kInvalidArgument, "a Krebs scale factor is zero: the model is singular");
  }
  CanonicalImuModel c;
  c.A_a = SMa.inverse();
  c.b_a = k.b_a;
  c.A_g = k.C_bg * SMg.inverse();
  c.b_g = k.b_g;
  c.G = c.A_g * k.B_g * k.C_bg.transpose();
  return c;
}

Result<KrebsConversion> krebs_from_canonical(const CanonicalImuModel& model) {
  if (!invertible(model.A_a) || !invertible(model.A_g)) {
    return make_error(Errc::kInvalidArgument, "A_a or A_g is singular: not a usable calibration");
  }
  KrebsConversion out;
  // A_a^-1 = S_a M_a R^T (an LQ split), from the QR split of its transpose.
  const RotationTriangular sa = rotation_triangular_split(model.A_a.inverse().transpose());
  const Eigen::Matrix3d La = sa.U.transpose();
  out.R_canonical_body = sa.Q;
  out.model.S_a = La.diagonal();
  out.model.M_a = krebs_entries(La.diagonal().cwiseInverse().asDiagonal() * La);
  out.model.b_a = model.b_a;

  const Eigen::Matrix3d A_g_body = sa.Q.transpose() * model.A_g;
  const Eigen::Matrix3d G_body = sa.Q.transpose() * model.G * sa.Q;
  const RotationTriangular sg = rotation_triangular_split(A_g_body.inverse().transpose());
  const Eigen::Matrix3d Lg = sg.U.transpose();
  out.model.C_bg = sg.Q;
  out.model.S_g = Lg.diagonal();
  out.model.M_g = krebs_entries(Lg.diagonal().cwiseInverse().asDiagonal() * Lg);
  out.model.B_g = A_g_body.inverse() * G_body * out.model.C_bg;
  out.model.b_g = model.b_g;
  return out;
}

}  // namespace imucal
