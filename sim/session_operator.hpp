// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig's operator for guided sessions (imucald --sim, `make demo`, the service's
// tests): a trajectory that is extended while it runs, and a scripted operator that reads the
// session's messages and moves the rig or presses keys as a person at the console would, at a
// human pace (a reaction time, 1-2 s per pose change).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <vector>

#include "core/session_messages.hpp"
#include "core/time.hpp"
#include "sim/trajectory.hpp"

namespace imucal::sim {

class CheckerboardMotion;

/// A trajectory made of rests and minimum-jerk turns (rotations about a body-fixed axis), appended
/// as the session goes on. Before the first turn and after the last one the rig rests. Safe to
/// read from another thread than the one that appends (the real-time rig's ticker).
class OperatorTrajectory final : public Trajectory {
 public:
  explicit OperatorTrajectory(const Eigen::Quaterniond& q_world_body = Eigen::Quaterniond::Identity());
  RigState at(TimeNs t_ns) const override;
  TimeNs start_ns() const override { return 0; }
  /// Open-ended: the rig rests after the last turn for as long as the session runs (the sensor
  /// clamps time to the trajectory, which would freeze the bias walk and the temperature).
  TimeNs end_ns() const override { return kOpenEndNs; }
  static constexpr TimeNs kOpenEndNs = TimeNs{1} << 60;
  const std::vector<Segment>& segments() const override { return segments_; }

  /// Turns from wherever the rig is at `t0_ns` to `q_target` over `duration_s`, with a lift of
  /// `lift_m` in the middle (a hand moves the rig while it turns it). t0 must not precede the
  /// end of the previous turn.
  void turn(TimeNs t0_ns, double duration_s, const Eigen::Quaterniond& q_target, double lift_m = 0.05);
  /// Moves the rig along `motion` from `t0_ns` on (its time 0 at t0), carried by T_op_motion
  /// (the motion's world into this trajectory's). The motion must start and end at rest at the
  /// rig's position then (CheckerboardMotion does, at its nominal pose); the caller turns the rig
  /// to the motion's start attitude first (wave_start()).
  void follow(TimeNs t0_ns, std::shared_ptr<const Trajectory> motion, const Eigen::Isometry3d& T_op_motion);
  /// When the last piece ends (the rig rests from then on).
  TimeNs busy_until_ns() const;
  /// The orientation the rig rests in after every turn so far.
  Eigen::Quaterniond final_orientation() const;

 private:
  struct Piece {
    TimeNs t0_ns = 0, t1_ns = 0;
    Eigen::Quaterniond q0 = Eigen::Quaterniond::Identity();
    Eigen::Vector3d rotvec_body = Eigen::Vector3d::Zero();
    double lift_m = 0.0;
    std::shared_ptr<const Trajectory> motion;  // a followed motion instead of a turn
    Eigen::Isometry3d T_op_motion = Eigen::Isometry3d::Identity();
  };
  static RigState follow_state(const Piece& p, TimeNs t_ns);
  mutable std::mutex mutex_;
  Eigen::Quaterniond q_start_;
  std::vector<Piece> pieces_;
  std::vector<Segment> segments_;
};

/// Where a CheckerboardMotion goes in an OperatorTrajectory: turned by `yaw_rad` about the
/// vertical and shifted so that its rest pose is at the origin, where the operator's rig rests.
Eigen::Isometry3d follow_transform(const CheckerboardMotion& motion, double yaw_rad = 0.0);

struct ScriptedOperatorOptions {
  double reaction_s = 0.8;     // from a prompt or a capture to the start of the operator's move
  double move_s = 1.5;         // one pose change
  bool accept = true;          // the review's answer: accept (y) or reject (n)
  bool abort_on_fault = true;  // a script cannot fix a device: abort instead of waiting for ever
  bool press_keys = true;      // false: only move the rig, a person at the console presses the keys
  /// The motion step: the rig is moved along this motion in front of the target (the board where
  /// wave_T_op_motion puts the motion's board); empty: the operator skips the step.
  std::shared_ptr<const CheckerboardMotion> wave;
  Eigen::Isometry3d wave_T_op_motion = Eigen::Isometry3d::Identity();
  std::uint64_t seed = 1;
};

/// Reads the session's messages (core/session_messages.hpp) as the engine emits them and acts on
/// the trajectory or presses keys: on what a prompt asks and the keys it offers, on a captured
/// pose and on the engine's reasons for refusing a hold, never on the text meant for a person.
/// Call on_message() for each message and on_time() as sample time passes; keys go to `press`
/// at their time.
class ScriptedOperator {
 public:
  using Key = session_msg::OperatorKey;
  ScriptedOperator(OperatorTrajectory& trajectory, const ScriptedOperatorOptions& options,
                   std::function<void(Key key)> press);
  void on_message(const session_msg::SessionMessage& message, TimeNs now_ns);
  void on_time(TimeNs now_ns);
  int turns() const { return turns_; }

 private:
  void turn_to_up(const Eigen::Vector3d& up_body, TimeNs now_ns);
  void wave(TimeNs now_ns);
  void press_at(Key key, TimeNs t_ns);
  void on_prompt(const session_msg::Prompt& prompt, TimeNs now_ns);

  OperatorTrajectory& trajectory_;
  ScriptedOperatorOptions options_;
  std::function<void(Key)> press_;
  std::mt19937_64 rng_;
  std::vector<Eigen::Vector3d> ups_;  // pose directions, well spread over the sphere
  std::size_t next_up_ = 0;
  std::vector<std::pair<TimeNs, Key>> keys_;  // pending, in time order
  int turns_ = 0;
  TimeNs busy_until_ns_ = 0;
  std::optional<session_msg::StepId> last_prompt_step_;  // the poses step's later prompts (the next
                                                         // side) are no new start
  bool last_prompt_failed_ = false;  // ... unless the one before was a fault's (redo, abort)
  Eigen::Vector3d face_up_ = Eigen::Vector3d::UnitX();  // the six-face step's face asked for
};

}  // namespace imucal::sim
