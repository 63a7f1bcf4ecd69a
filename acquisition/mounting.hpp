// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The IMU's mounting on the rig: R_rig_imu rotates IMU-frame vectors into the rig frame
// (v_rig = R_rig_imu * v_imu), as given by the rig configuration (imu.R_rig_imu).
//
// Raw int16 triads can be remapped exactly only by an axis permutation with sign flips (the
// 24 proper rotations by multiples of 90 degrees): each rig axis is then +-one IMU axis. Any
// other rotation would mix counts of different axes and need rounding, so raw samples stay in
// the IMU frame and the rotation is applied in SI, after calibration. See docs/acquisition.md.

#include <Eigen/Core>
#include <array>
#include <string>

#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::acq {

enum class MountingKind {
  kIdentity,         // rig axes are the IMU axes
  kAxisPermutation,  // a signed permutation: exact on raw counts
  kGeneral,          // any other rotation: applied in SI only
};

const char* mounting_kind_name(MountingKind kind);

class MountingMap {
 public:
  MountingMap() = default;

  /// Checks that R_rig_imu is a rotation (orthonormal to `tolerance`, determinant +1) and
  /// classifies it; entries within `tolerance` of 0 or +-1 count as exact.
  [[nodiscard]] static Result<MountingMap> from_rotation(const Eigen::Matrix3d& R_rig_imu,
                                                         double tolerance = 1e-6);

  MountingKind kind() const { return kind_; }
  /// True when raw counts can be remapped without loss (identity or signed permutation).
  bool exact_on_raw() const { return kind_ != MountingKind::kGeneral; }
  const Eigen::Matrix3d& R_rig_imu() const { return R_rig_imu_; }

  /// For exact maps: rig axis i takes IMU axis source_axis(i) times sign(i).
  int source_axis(int rig_axis) const { return axis_[static_cast<std::size_t>(rig_axis)]; }
  int sign(int rig_axis) const { return sign_[static_cast<std::size_t>(rig_axis)]; }

  /// Remaps a raw triad (counts; signed, so -32768 becomes +32768, which a double holds).
  /// Only for exact maps (asserted).
  Eigen::Vector3d raw_to_rig(const Eigen::Vector3d& raw_imu) const;
  /// Rotates an SI vector (any kind).
  Eigen::Vector3d si_to_rig(const Eigen::Vector3d& v_imu) const { return R_rig_imu_ * v_imu; }

  /// Remaps accel and gyro of a raw sample in place (exact maps only; asserted).
  void remap_raw_sample(ImuSample& sample) const;

  /// "x_rig = -y_imu, y_rig = +x_imu, z_rig = +z_imu", or the matrix for a general rotation.
  std::string describe() const;

 private:
  MountingKind kind_ = MountingKind::kIdentity;
  Eigen::Matrix3d R_rig_imu_ = Eigen::Matrix3d::Identity();
  std::array<int, 3> axis_{0, 1, 2};
  std::array<int, 3> sign_{1, 1, 1};
};

}  // namespace imucal::acq
