// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/mounting.hpp"

#include <Eigen/Dense>
#include <cassert>
#include <cmath>
#include <sstream>

namespace imucal::acq {

const char* mounting_kind_name(MountingKind kind) {
  switch (kind) {
    case MountingKind::kIdentity:
      return "identity";
    case MountingKind::kAxisPermutation:
      return "axis-permutation";
    case MountingKind::kGeneral:
      return "general";
  }
  return "unknown";
}

Result<MountingMap> MountingMap::from_rotation(const Eigen::Matrix3d& R, double tolerance) {
  if (!R.allFinite()) {
    return make_error(Errc::kInvalidArgument, "imu.R_rig_imu has non-finite entries");
  }
  const double ortho_err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (ortho_err > std::max(tolerance, 1e-9)) {
    std::ostringstream os;
    os << "imu.R_rig_imu is not orthonormal (|R^T R - I| = " << ortho_err
       << "); give a rotation matrix, rows are the rig axes in IMU coordinates";
    return make_error(Errc::kInvalidArgument, os.str());
  }
  if (R.determinant() < 0.0) {
    return make_error(Errc::kInvalidArgument,
                      "imu.R_rig_imu has determinant -1 (a reflection, not a rotation); check the sign "
                      "of one axis");
  }
  MountingMap m;
  m.R_rig_imu_ = R;
  bool signed_permutation = true;
  for (int i = 0; i < 3 && signed_permutation; ++i) {
    int found = -1;
    for (int j = 0; j < 3; ++j) {
      const double v = R(i, j);
      if (std::abs(std::abs(v) - 1.0) <= tolerance) {
        if (found >= 0) signed_permutation = false;
        found = j;
        m.sign_[static_cast<std::size_t>(i)] = v > 0 ? 1 : -1;
      } else if (std::abs(v) > tolerance) {
        signed_permutation = false;
      }
    }
    if (found < 0) signed_permutation = false;
    m.axis_[static_cast<std::size_t>(i)] = found;
  }
  if (!signed_permutation) {
    m.kind_ = MountingKind::kGeneral;
    m.axis_ = {0, 1, 2};
    m.sign_ = {1, 1, 1};
    return m;
  }
  // Snap to the exact matrix so SI and raw paths agree bit for bit.
  m.R_rig_imu_.setZero();
  for (int i = 0; i < 3; ++i) m.R_rig_imu_(i, m.source_axis(i)) = m.sign(i);
  const bool identity = m.axis_ == std::array<int, 3>{0, 1, 2} && m.sign_ == std::array<int, 3>{1, 1, 1};
  m.kind_ = identity ? MountingKind::kIdentity : MountingKind::kAxisPermutation;
  return m;
}

Eigen::Vector3d MountingMap::raw_to_rig(const Eigen::Vector3d& raw_imu) const {
  assert(exact_on_raw());
  return {sign_[0] * raw_imu[axis_[0]], sign_[1] * raw_imu[axis_[1]], sign_[2] * raw_imu[axis_[2]]};
}

void MountingMap::remap_raw_sample(ImuSample& sample) const {
  if (kind_ == MountingKind::kIdentity) return;
  sample.accel = raw_to_rig(sample.accel);
  sample.gyro = raw_to_rig(sample.gyro);
}

std::string MountingMap::describe() const {
  std::ostringstream os;
  if (kind_ == MountingKind::kGeneral) {
    const Eigen::IOFormat fmt(6, 0, ", ", "; ", "", "", "[", "]");
    os << "R_rig_imu = " << R_rig_imu_.format(fmt) << " (general rotation, applied in SI)";
    return os.str();
  }
  static const char* names[] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    if (i) os << ", ";
    os << names[i] << "_rig = " << (sign(i) > 0 ? "+" : "-") << names[source_axis(i)] << "_imu";
  }
  return os.str();
}

}  // namespace imucal::acq
