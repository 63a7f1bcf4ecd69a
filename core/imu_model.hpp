// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// IMU error models and the conversions between them.
//
// Canonical correction (stored and applied at run time; docs/conventions.md section 4):
//   a = A_a (a_raw - b_a)
//   w = A_g (w_raw - b_g) - G a
// with A full 3x3 and G the g-sensitivity (rad/s per m/s^2). a and w are in an orthogonal body
// frame; raw values are in input units (counts or uncalibrated SI).
//
// Tedaldi form (Tedaldi 2013, eqs. 2.6, 2.7, 3.1, 3.5):
//   a_O = T_a K_a (a_S + b_a),  T_a unit upper triangular (3 angles, eq. 2.2)
//   w_O = T_g K_g (w_S + b_g),  T_g unit diagonal, 6 angles (eq. 2.3)
// Note the sign: Tedaldi adds the bias, the canonical form subtracts it (b_canonical = -b_tedaldi).
// The frame of a_O (AOF) is the accelerometer orthogonal frame implied by the upper triangular T_a.
//
// Krebs form (Krebs 2012, ch. 3), a forward (sensor) model:
//   a_raw = S_a M_a a + b_a
//   w_raw = S_g M_g C_bg^T w + B_g C_bg^T a + b_g
// M unit lower triangular (3 entries), S diagonal, C_bg the rotation of the gyro frame into the
// body frame, B_g the g-sensitivity (raw units per m/s^2, acting on the acceleration in the gyro
// frame). Its body frame is defined by the lower triangular M_a.
//
// The three forms describe the same linear model up to a rotation of the body frame; the
// conversions return that rotation where the target form fixes its own frame.

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/result.hpp"

namespace imucal {

struct CanonicalImuModel {
  Eigen::Matrix3d A_a = Eigen::Matrix3d::Identity();
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  Eigen::Matrix3d A_g = Eigen::Matrix3d::Identity();
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();

  Eigen::Vector3d correct_accel(const Eigen::Vector3d& a_raw) const { return A_a * (a_raw - b_a); }
  Eigen::Vector3d correct_gyro(const Eigen::Vector3d& w_raw, const Eigen::Vector3d& a) const {
    return A_g * (w_raw - b_g) - G * a;
  }
  /// The same model with its output expressed in another frame: outputs are rotated by R_new_old.
  CanonicalImuModel expressed_in(const Eigen::Matrix3d& R_new_old) const;
};

/// One triad in Tedaldi's form: out = T * diag(scale) * (raw + bias).
struct TedaldiTriad {
  Eigen::Matrix3d T = Eigen::Matrix3d::Identity();  // misalignment, unit diagonal
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();  // diagonal of K
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();   // Tedaldi's sign: added to the raw value

  Eigen::Matrix3d TK() const { return T * scale.asDiagonal(); }
  Eigen::Vector3d apply(const Eigen::Vector3d& raw) const { return TK() * (raw + bias); }
};

/// Accelerometer angles of eq. 3.2: [alpha_yz, alpha_zy, alpha_zx] <-> upper triangular T_a.
Eigen::Matrix3d accel_misalignment(const Eigen::Vector3d& alpha_yz_zy_zx);
Eigen::Vector3d accel_angles(const Eigen::Matrix3d& T_a);
/// Gyroscope angles of eq. 3.6: [g_yz, g_zy, g_xz, g_zx, g_xy, g_yx] <-> T_g (eq. 2.3).
Eigen::Matrix3d gyro_misalignment(const Eigen::Matrix<double, 6, 1>& gamma);
Eigen::Matrix<double, 6, 1> gyro_angles(const Eigen::Matrix3d& T_g);

struct TedaldiImuModel {
  TedaldiTriad accel;  // T upper triangular
  TedaldiTriad gyro;
};

struct KrebsImuModel {
  Eigen::Vector3d S_a = Eigen::Vector3d::Ones();
  Eigen::Vector3d M_a = Eigen::Vector3d::Zero();  // [M_yz, M_zy, M_zx] = M(1,0), M(2,0), M(2,1)
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d S_g = Eigen::Vector3d::Ones();
  Eigen::Vector3d M_g = Eigen::Vector3d::Zero();
  Eigen::Matrix3d C_bg = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d B_g = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
};

/// Unit lower triangular M from [M_yz, M_zy, M_zx] and back.
Eigen::Matrix3d krebs_misalignment(const Eigen::Vector3d& m);
Eigen::Vector3d krebs_entries(const Eigen::Matrix3d& M);

/// X = Q U with Q a proper rotation and U upper triangular. diag(U) is positive, except U(2,2),
/// which is negative when det(X) < 0: a rotation cannot absorb a reflection, so the reflection
/// stays in U (for the Tedaldi form: a negative z scale). This is the one decomposition every
/// conversion to an upper (Tedaldi) or lower (Krebs, through the transpose) triangular form uses.
struct RotationTriangular {
  Eigen::Matrix3d Q = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d U = Eigen::Matrix3d::Identity();
};
RotationTriangular rotation_triangular_split(const Eigen::Matrix3d& X);

/// A canonical model re-expressed in Tedaldi's accelerometer frame (AOF): with A_a = Q U,
/// model.A_a = U exactly (zeros below the diagonal), A_g and G rotated by Q^T. G is kept, so a
/// model with g-sensitivity (a simulator's truth) can be compared with a Tedaldi estimate.
/// No checks: A_a must be invertible.
struct CanonicalInAof {
  CanonicalImuModel model;                                        // outputs in the AOF
  Eigen::Matrix3d R_canonical_aof = Eigen::Matrix3d::Identity();  // canonical frame <- AOF (= Q)
};
CanonicalInAof canonical_in_aof(const CanonicalImuModel& model);

/// One triad in Tedaldi's form from a canonical A and b in the same frame: T K = A with T unit
/// diagonal (K = diag(A)), bias = -b. No checks: diag(A) must have no zero.
TedaldiTriad tedaldi_triad(const Eigen::Matrix3d& A, const Eigen::Vector3d& b_canonical);

/// Tedaldi -> canonical (body frame = Tedaldi's AOF, G = 0).
CanonicalImuModel canonical_from_tedaldi(const TedaldiImuModel& model);

struct TedaldiConversion {
  TedaldiImuModel model;
  Eigen::Matrix3d R_canonical_aof = Eigen::Matrix3d::Identity();  // canonical frame <- AOF
};
/// Canonical -> Tedaldi (canonical_in_aof, then tedaldi_triad for each triad). Fails when G is
/// not zero (the Tedaldi form has no g-sensitivity) or a matrix is singular.
[[nodiscard]] Result<TedaldiConversion> tedaldi_from_canonical(const CanonicalImuModel& model);

/// Krebs -> canonical (body frame = Krebs body frame).
[[nodiscard]] Result<CanonicalImuModel> canonical_from_krebs(const KrebsImuModel& model);

struct KrebsConversion {
  KrebsImuModel model;
  Eigen::Matrix3d R_canonical_body = Eigen::Matrix3d::Identity();  // canonical frame <- Krebs body
};
[[nodiscard]] Result<KrebsConversion> krebs_from_canonical(const CanonicalImuModel& model);

}  // namespace imucal
