// SPDX-License-Identifier: BSD-3-Clause
#include "sim/session_operator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "sim/motion.hpp"

namespace imucal::sim {

namespace {

/// A bump 64 tau^3 (1 - tau)^3 over [0, 1] (peak 1 at the middle) and its derivatives: zero value,
/// rate and acceleration at both ends, so a lift joins the rests without a step in acceleration.
void lift_bump(double tau, double* b, double* db, double* ddb) {
  tau = std::clamp(tau, 0.0, 1.0);
  const double u = 1.0 - tau;
  *b = 64.0 * tau * tau * tau * u * u * u;
  *db = 64.0 * 3.0 * tau * tau * u * u * (1.0 - 2.0 * tau);
  *ddb = 64.0 * 6.0 * tau * u * ((1.0 - 2.0 * tau) * (1.0 - 2.0 * tau) - tau * u);
}

/// `n` directions spread evenly over the sphere (a Fibonacci lattice), in a shuffled order so that
/// consecutive poses differ.
std::vector<Eigen::Vector3d> spread_directions(int n, std::mt19937_64& rng) {
  std::vector<Eigen::Vector3d> out;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n;
    const double r = std::sqrt(1.0 - z * z);
    out.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  std::shuffle(out.begin(), out.end(), rng);
  return out;
}

}  // namespace

OperatorTrajectory::OperatorTrajectory(const Eigen::Quaterniond& q_world_body) : q_start_(q_world_body) {}

Eigen::Quaterniond OperatorTrajectory::final_orientation() const {
  std::lock_guard lock(mutex_);
  if (pieces_.empty()) return q_start_;
  const Piece& p = pieces_.back();
  if (p.motion) return follow_state(p, p.t1_ns).q_world_body;
  return Eigen::Quaterniond(p.q0.toRotationMatrix() * so3_exp(p.rotvec_body)).normalized();
}

TimeNs OperatorTrajectory::busy_until_ns() const {
  std::lock_guard lock(mutex_);
  return pieces_.empty() ? 0 : pieces_.back().t1_ns;
}

RigState OperatorTrajectory::follow_state(const Piece& p, TimeNs t_ns) {
  const TimeNs t = std::clamp(t_ns, p.t0_ns, p.t1_ns) - p.t0_ns + p.motion->start_ns();
  RigState m = p.motion->at(t);
  const Eigen::Matrix3d R = p.T_op_motion.linear();
  RigState st;
  st.q_world_body = Eigen::Quaterniond(R * m.q_world_body.toRotationMatrix()).normalized();
  st.p_world_body = p.T_op_motion * m.p_world_body;
  if (t_ns >= p.t0_ns && t_ns <= p.t1_ns) {
    st.v_world = R * m.v_world;
    st.a_world = R * m.a_world;
    st.omega_body = m.omega_body;
  }
  return st;
}

void OperatorTrajectory::follow(TimeNs t0_ns, std::shared_ptr<const Trajectory> motion,
                                const Eigen::Isometry3d& T_op_motion) {
  std::lock_guard lock(mutex_);
  Piece p;
  p.t0_ns = pieces_.empty() ? t0_ns : std::max(t0_ns, pieces_.back().t1_ns);
  p.t1_ns = p.t0_ns + (motion->end_ns() - motion->start_ns());
  p.motion = std::move(motion);
  p.T_op_motion = T_op_motion;
  pieces_.push_back(p);
  segments_.push_back({p.t0_ns, p.t1_ns, "move", ""});
}

void OperatorTrajectory::turn(TimeNs t0_ns, double duration_s, const Eigen::Quaterniond& q_target,
                              double lift_m) {
  const Eigen::Quaterniond q0 = final_orientation();
  const Eigen::AngleAxisd delta(q0.conjugate() * q_target);
  std::lock_guard lock(mutex_);
  Piece p;
  p.t0_ns = pieces_.empty() ? t0_ns : std::max(t0_ns, pieces_.back().t1_ns);
  p.t1_ns = p.t0_ns + static_cast<TimeNs>(duration_s * 1e9);
  p.q0 = q0;
  p.rotvec_body = delta.angle() * delta.axis();
  p.lift_m = lift_m;
  pieces_.push_back(p);
  segments_.push_back({p.t0_ns, p.t1_ns, "move", ""});
}

RigState OperatorTrajectory::at(TimeNs t_ns) const {
  std::lock_guard lock(mutex_);
  RigState st;
  st.q_world_body = q_start_;
  if (pieces_.empty() || t_ns < pieces_.front().t0_ns) return st;
  auto it = std::upper_bound(pieces_.begin(), pieces_.end(), t_ns,
                             [](TimeNs t, const Piece& p) { return t < p.t0_ns; });
  const Piece& pc = *(it - 1);
  if (pc.motion) return follow_state(pc, t_ns);
  const double T = ns_to_s(pc.t1_ns - pc.t0_ns);
  const double tau = std::clamp(ns_to_s(t_ns - pc.t0_ns) / T, 0.0, 1.0);
  double s = 0, ds = 0, dds = 0, b = 0, db = 0, ddb = 0;
  min_jerk(tau, &s, &ds, &dds);
  lift_bump(tau, &b, &db, &ddb);
  if (tau >= 1.0) ds = dds = db = ddb = 0.0;
  st.q_world_body = Eigen::Quaterniond(pc.q0.toRotationMatrix() * so3_exp(s * pc.rotvec_body)).normalized();
  st.omega_body = ds / T * pc.rotvec_body;
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  st.p_world_body = pc.lift_m * b * up;
  st.v_world = pc.lift_m * db / T * up;
  st.a_world = pc.lift_m * ddb / (T * T) * up;
  return st;
}

ScriptedOperator::ScriptedOperator(OperatorTrajectory& trajectory, const ScriptedOperatorOptions& options,
                                   std::function<void(Key key)> press)
    : trajectory_(trajectory), options_(options), press_(std::move(press)), rng_(options.seed) {
  ups_ = spread_directions(26, rng_);
}

void ScriptedOperator::press_at(Key key, TimeNs t_ns) {
  if (!options_.press_keys) return;
  keys_.emplace_back(t_ns, key);
  std::stable_sort(keys_.begin(), keys_.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
}

void ScriptedOperator::on_time(TimeNs now_ns) {
  while (!keys_.empty() && keys_.front().first <= now_ns) {
    const Key key = keys_.front().second;
    keys_.erase(keys_.begin());
    press_(key);
  }
}

void ScriptedOperator::turn_to_up(const Eigen::Vector3d& up_body, TimeNs now_ns) {
  std::uniform_real_distribution<double> yaw(-std::numbers::pi / 2, std::numbers::pi / 2);
  const Eigen::Quaterniond q =
      Eigen::AngleAxisd(yaw(rng_), Eigen::Vector3d::UnitZ()) *
      Eigen::Quaterniond::FromTwoVectors(up_body.normalized(), Eigen::Vector3d::UnitZ());
  const TimeNs t0 = std::max(now_ns + static_cast<TimeNs>(options_.reaction_s * 1e9), busy_until_ns_);
  trajectory_.turn(t0, options_.move_s, q);
  busy_until_ns_ = t0 + static_cast<TimeNs>(options_.move_s * 1e9);
  ++turns_;
}

Eigen::Isometry3d follow_transform(const CheckerboardMotion& motion, double yaw_rad) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = -(T.linear() * motion.p_world_body_nominal());
  return T;
}

void ScriptedOperator::wave(TimeNs now_ns) {
  // Face the board (the motion's rest attitude, carried into this trajectory), then follow it.
  const Eigen::Quaterniond q_face(options_.wave_T_op_motion.linear() *
                                  options_.wave->q_world_body_nominal().toRotationMatrix());
  const TimeNs t0 = std::max(now_ns + static_cast<TimeNs>(options_.reaction_s * 1e9), busy_until_ns_);
  trajectory_.turn(t0, options_.move_s, q_face);
  trajectory_.follow(t0 + static_cast<TimeNs>(options_.move_s * 1e9), options_.wave,
                     options_.wave_T_op_motion);
  busy_until_ns_ = trajectory_.busy_until_ns();
  ++turns_;
}

void ScriptedOperator::on_message(const session_msg::SessionMessage& m, TimeNs now_ns) {
  namespace msg = session_msg;
  const TimeNs react = now_ns + static_cast<TimeNs>(options_.reaction_s * 1e9);
  if (std::holds_alternative<msg::Fault>(m)) {
    if (options_.abort_on_fault) press_at(Key::kAbort, react);
    return;
  }
  if (const auto* prompt = std::get_if<msg::Prompt>(&m)) {
    on_prompt(*prompt, now_ns);
    return;
  }
  // A pose was captured, or the hold was refused as too close to one: on to the next direction.
  if (std::holds_alternative<msg::PoseCaptured>(m)) turn_to_up(ups_[next_up_++ % ups_.size()], now_ns);
  if (const auto* message = std::get_if<msg::Message>(&m)) {
    if (message->cause == msg::MessageCause::kPoseRefused) turn_to_up(ups_[next_up_++ % ups_.size()], now_ns);
    // The wrong face is up: turn to the one asked for.
    if (message->cause == msg::MessageCause::kWrongFace) turn_to_up(face_up_, now_ns);
  }
}

void ScriptedOperator::on_prompt(const session_msg::Prompt& p, TimeNs now_ns) {
  using session_msg::StepId;
  const TimeNs react = now_ns + static_cast<TimeNs>(options_.reaction_s * 1e9);
  if (p.step == StepId::kPreflight && p.offers(Key::kContinue)) press_at(Key::kContinue, react);
  // The poses step prompts again after each capture (naming the next side); the operator turns
  // on its own after each capture, so only the step's start, or a redo after a fault (a prompt
  // that offers only redo and abort), starts a turn.
  const bool restart = last_prompt_step_ != p.step || last_prompt_failed_;
  last_prompt_step_ = p.step;
  last_prompt_failed_ = !p.offers(Key::kContinue) && !p.offers(Key::kSkip) && p.offers(Key::kRedo);
  if (p.step == StepId::kPoses && !p.offers(Key::kRedo)) return;
  if (p.step == StepId::kPoses && restart) turn_to_up(ups_[next_up_++ % ups_.size()], now_ns);
  if (p.step == StepId::kMotion) {
    if (options_.wave) {
      wave(now_ns);
    } else {
      press_at(Key::kSkip, react);  // no target to wave at
    }
  }
  if (p.step == StepId::kReview && p.offers(Key::kAccept))
    press_at(options_.accept ? Key::kAccept : Key::kReject, react);
  // The face asked for, as the prompt gives it (the axis that goes up).
  if (p.step == StepId::kGsens && p.up) {
    face_up_ = *p.up;
    turn_to_up(face_up_, now_ns);
  }
}

}  // namespace imucal::sim
