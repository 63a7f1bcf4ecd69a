// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the operator is asked to do with the rig, in words and as a small drawing: which side goes
// up, named by the rig's own sides when the configuration names them (`sides`: front, left, top)
// and by the IMU's axes otherwise.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "core/rig_config.hpp"

namespace imucal::app::session {

class PoseGuide {
 public:
  /// The session's samples are in the rig frame when the mounting is exact (identity or a signed
  /// permutation, applied to the raw counts) and in the IMU frame otherwise; the named sides are
  /// brought into that frame here.
  explicit PoseGuide(const RigConfig& config);

  /// `up`: a signed unit axis of the samples' frame. "left side up" or "+Y up".
  std::string up_name(const Eigen::Vector3d& up) const;
  /// "Put the rig on its right side, left side up", "Stand the rig upright (top side up)", or
  /// "Turn the rig so that the IMU's +Y axis points up".
  std::string instruction(const Eigen::Vector3d& up) const;
  /// The rig as a box on a table, seen by the operator, with the side that is up, the side that
  /// faces the operator and the one on the right labelled (plain ASCII, at most 44 columns).
  std::vector<std::string> drawing(const Eigen::Vector3d& up) const;
  bool named() const { return sides_.has_value(); }

 private:
  // "LEFT", or "+Y" when the sides are not named (or this axis is none of them).
  std::string label(const Eigen::Vector3d& axis) const;
  std::optional<std::string> side(const Eigen::Vector3d& axis) const;

  std::optional<RigSides> sides_;  // in the samples' frame
};

}  // namespace imucal::app::session
