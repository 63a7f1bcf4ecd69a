// SPDX-License-Identifier: BSD-3-Clause
// The guided session's virtual operator in front of the target: the operator trajectory follows
// the simulator's checkerboard motion after a turn that faces the board, without a jump in
// position, velocity or attitude, and the virtual camera sees the board through the motion.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

#include "sim/camera_scene.hpp"
#include "sim/camimu.hpp"
#include "sim/motion.hpp"
#include "sim/session_operator.hpp"

namespace imucal::sim {
namespace {

constexpr TimeNs kS = 1'000'000'000;

std::shared_ptr<const CheckerboardMotion> board_motion(double duration_s) {
  CheckerboardMotionOptions mo = CamImuSimOptions::default_motion();
  mo.duration_s = duration_s;
  auto motion = CheckerboardMotion::create(mo, 5);
  EXPECT_TRUE(motion.ok());
  return std::shared_ptr<const CheckerboardMotion>(std::move(*motion));
}

TEST(SessionOperator, FollowingTheBoardMotionJoinsTheRestsWithoutAJump) {
  auto motion = board_motion(20.0);
  const Eigen::Isometry3d T = follow_transform(*motion, 0.7);
  OperatorTrajectory traj(Eigen::Quaterniond(Eigen::AngleAxisd(2.0, Eigen::Vector3d(1, 1, 0).normalized())));
  const Eigen::Quaterniond q_face(T.linear() * motion->q_world_body_nominal().toRotationMatrix());
  traj.turn(1 * kS, 1.5, q_face);
  const TimeNs t0 = 1 * kS + 1'500'000'000;
  traj.follow(t0, motion, T);
  const TimeNs t1 = t0 + motion->end_ns();
  EXPECT_EQ(traj.busy_until_ns(), t1);

  // At both joins: at rest at the origin (where the turns keep the rig), the attitude continuous.
  for (TimeNs t : {t0, t1}) {
    const RigState before = traj.at(t - 1'000'000), after = traj.at(t + 1'000'000);
    EXPECT_LT(before.p_world_body.norm(), 1e-3) << t;
    EXPECT_LT(after.p_world_body.norm(), 1e-3) << t;
    EXPECT_LT(after.v_world.norm(), 1e-2) << t;
    EXPECT_LT(before.q_world_body.angularDistance(after.q_world_body), 1e-3) << t;
  }
  EXPECT_LT(traj.at(t0).q_world_body.angularDistance(q_face), 1e-9);
  EXPECT_LT(traj.final_orientation().angularDistance(traj.at(t1 + 5 * kS).q_world_body), 1e-9);

  // Inside, the motion carried by T: velocity and rate are the motion's, rotated.
  const TimeNs tm = t0 + 9 * kS;
  const RigState m = motion->at(tm - t0), s = traj.at(tm);
  EXPECT_LT((s.p_world_body - T * m.p_world_body).norm(), 1e-12);
  EXPECT_LT((s.v_world - T.linear() * m.v_world).norm(), 1e-12);
  EXPECT_LT((s.omega_body - m.omega_body).norm(), 1e-12);
  EXPECT_GT(s.v_world.norm() + s.omega_body.norm(), 0.05) << "the rig moves in the middle";
  // And it is a consistent motion: the position's change over 1 ms is the velocity's.
  const RigState s2 = traj.at(tm + 1'000'000);
  EXPECT_LT(((s2.p_world_body - s.p_world_body) / 1e-3 - s.v_world).norm(), 1e-2);
}

TEST(SessionOperator, TheScriptedOperatorFacesTheBoardAndTheCameraSeesIt) {
  auto motion = board_motion(30.0);
  OperatorTrajectory traj;
  ScriptedOperatorOptions oo;
  oo.wave = motion;
  oo.wave_T_op_motion = follow_transform(*motion);
  std::vector<session_msg::OperatorKey> keys;
  ScriptedOperator op(traj, oo, [&](session_msg::OperatorKey k) { keys.push_back(k); });
  op.on_message(session_msg::Prompt{std::nullopt,
                                    session_msg::StepId::kMotion,
                                    "Move the rig",
                                    {session_msg::OperatorKey::kSkip},
                                    {},
                                    std::nullopt},
                2 * kS);
  op.on_time(40 * kS);
  EXPECT_TRUE(keys.empty()) << "the operator moves instead of skipping";
  EXPECT_GT(traj.busy_until_ns(), 30 * kS);

  SimCameraScene scene;
  scene.camera = sim_camera_for(320, 240);
  scene.target = CamImuSimOptions::default_sim_target();
  scene.T_cam_imu = CamImuSimOptions::default_T_cam_imu();
  scene.motion_blur = false;
  auto source =
      SceneFrameSource::create(scene, traj, oo.wave_T_op_motion * motion->T_world_board(scene.target));
  ASSERT_TRUE(source.ok()) << source.error().message;
  std::vector<std::uint8_t> pixels(320 * 240);
  // Before the operator moves, the rig faces away; through the motion the board is in view.
  for (TimeNs t = 6 * kS; t < 30 * kS; t += kS / 2) ASSERT_TRUE((*source)->render(t, pixels).ok());
  const auto& stats = (*source)->stats();
  EXPECT_EQ(stats.frames, 48);
  EXPECT_GE(stats.frames_all_points_visible, 40) << "the whole board in most frames";
}

namespace msg = session_msg;

msg::Prompt operator_prompt(msg::StepId step, std::vector<msg::OperatorKey> keys,
                            std::optional<Eigen::Vector3d> up = std::nullopt) {
  return {std::nullopt, step, "words a person reads", std::move(keys), {}, up};
}

TEST(SessionOperator, TheScriptedOperatorActsOnTypedMessagesNotOnTheirText) {
  using K = msg::OperatorKey;
  OperatorTrajectory traj;
  ScriptedOperatorOptions oo;
  oo.reaction_s = 0.5;
  std::vector<std::pair<TimeNs, K>> pressed;
  TimeNs now = 0;
  ScriptedOperator op(traj, oo, [&](K k) { pressed.emplace_back(now, k); });
  auto at = [&](TimeNs t) {
    now = t;
    op.on_time(t);
  };

  // The preflight's prompt offers continue: pressed after the reaction time.
  op.on_message(operator_prompt(msg::StepId::kPreflight, {K::kContinue, K::kAbort}), 1 * kS);
  at(1 * kS + kS / 4);
  EXPECT_TRUE(pressed.empty());
  at(2 * kS);
  ASSERT_EQ(pressed.size(), 1u);
  EXPECT_EQ(pressed[0].second, K::kContinue);
  // A failed preflight offers redo and abort: nothing to press for a script.
  op.on_message(operator_prompt(msg::StepId::kPreflight, {K::kRedo, K::kAbort}), 2 * kS);
  at(4 * kS);
  EXPECT_EQ(pressed.size(), 1u);

  // The poses step: its first prompt starts a turn, its later prompts (the next side) do not.
  op.on_message(operator_prompt(msg::StepId::kPoses, {K::kContinue, K::kRedo, K::kAbort}), 4 * kS);
  EXPECT_EQ(op.turns(), 1);
  op.on_message(operator_prompt(msg::StepId::kPoses, {K::kContinue, K::kRedo, K::kAbort}), 5 * kS);
  EXPECT_EQ(op.turns(), 1);
  // A captured pose and a refused hold each start the next turn; the same words without the
  // engine's reason do not.
  op.on_message(msg::PoseCaptured{std::nullopt, 1, Eigen::Vector3d::UnitZ()}, 8 * kS);
  EXPECT_EQ(op.turns(), 2);
  op.on_message(
      msg::Message{std::nullopt, msg::MessageLevel::kWarning, "anything", msg::MessageCause::kPoseRefused},
      12 * kS);
  EXPECT_EQ(op.turns(), 3);
  op.on_message(
      msg::Message{std::nullopt, msg::MessageLevel::kInfo, "Pose 2 captured", msg::MessageCause::kNone},
      16 * kS);
  op.on_message(msg::Message{std::nullopt, msg::MessageLevel::kWarning, "Too close to pose 1",
                             msg::MessageCause::kNone},
                16 * kS);
  EXPECT_EQ(op.turns(), 3);

  // The six-face step: the face the prompt asks for goes up; the wrong face up turns to it again.
  const Eigen::Vector3d face(0.0, -1.0, 0.0);
  op.on_message(operator_prompt(msg::StepId::kGsens, {K::kRedo, K::kSkip, K::kAbort}, face), 20 * kS);
  EXPECT_EQ(op.turns(), 4);
  const TimeNs settled = traj.busy_until_ns() + kS;
  const Eigen::Vector3d up_in_body = traj.at(settled).q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
  EXPECT_LT((up_in_body - face).norm(), 1e-6) << up_in_body.transpose();
  op.on_message(msg::Message{std::nullopt, msg::MessageLevel::kWarning, "x", msg::MessageCause::kWrongFace},
                30 * kS);
  EXPECT_EQ(op.turns(), 5);

  // The review offers accept: accepted. A fault: aborted.
  op.on_message(operator_prompt(msg::StepId::kReview, {K::kAccept, K::kReject, K::kAbort}), 40 * kS);
  op.on_message(msg::Fault{std::nullopt, "imu", msg::StepId::kReview, "gone", ""}, 41 * kS);
  at(45 * kS);
  ASSERT_EQ(pressed.size(), 3u);
  EXPECT_EQ(pressed[1].second, K::kAccept);
  EXPECT_EQ(pressed[2].second, K::kAbort);
}

}  // namespace
}  // namespace imucal::sim
