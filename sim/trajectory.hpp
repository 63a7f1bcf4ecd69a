// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Rigid-body motion of the simulated rig. Frames: world W is z-up with gravity (0, 0, -g);
// body B is the IMU's orthogonal accelerometer frame (the frame the calibration reports in).
// A trajectory is smooth (C2 at least) so that accelerations and rates are exact, not
// differentiated numerically.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "core/time.hpp"

namespace imucal::sim {

struct RigState {
  Eigen::Quaterniond q_world_body = Eigen::Quaterniond::Identity();  // rotates body vectors into world
  Eigen::Vector3d p_world_body = Eigen::Vector3d::Zero();            // body origin in world, m
  Eigen::Vector3d v_world = Eigen::Vector3d::Zero();                 // m/s, in world
  Eigen::Vector3d a_world = Eigen::Vector3d::Zero();                 // m/s^2 kinematic, in world (no gravity)
  Eigen::Vector3d omega_body = Eigen::Vector3d::Zero();              // rad/s, body rate in body frame
};

/// A labelled time span of the script (still period, a pose hold, a motion segment): the
/// ground truth of what a static detector should find.
struct Segment {
  TimeNs t0_ns = 0;
  TimeNs t1_ns = 0;
  std::string kind;   // "still", "hold", "move", "face"
  std::string label;  // the face held ("+z up"), for the six-face script's holds; else empty
};

class Trajectory {
 public:
  virtual ~Trajectory() = default;
  virtual RigState at(TimeNs t_ns) const = 0;
  virtual TimeNs start_ns() const = 0;
  virtual TimeNs end_ns() const = 0;
  virtual const std::vector<Segment>& segments() const = 0;
};

}  // namespace imucal::sim
