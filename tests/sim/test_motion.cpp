// SPDX-License-Identifier: BSD-3-Clause
// Motion scripts against their own definitions: rates and accelerations equal finite
// differences of attitude and position, segments match the motion, determinism, excitation.

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <numbers>

#include "core/target.hpp"
#include "sim/motion.hpp"
#include "tests/support/test_helpers.hpp"

namespace imucal::sim {
namespace {

using test::kDeg;

Eigen::Vector3d so3_log(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

/// Compares a state's rate, velocity and acceleration with central differences at t.
void expect_consistent(const Trajectory& traj, TimeNs t_ns, const std::string& what,
                       double accel_tol = 1e-5) {
  const TimeNs h_ns = 20'000;  // 20 us
  const double h = ns_to_s(h_ns);
  const RigState s = traj.at(t_ns), sm = traj.at(t_ns - h_ns), sp = traj.at(t_ns + h_ns);
  const Eigen::Vector3d w_fd =
      so3_log(sm.q_world_body.toRotationMatrix().transpose() * sp.q_world_body.toRotationMatrix()) / (2 * h);
  const Eigen::Vector3d v_fd = (sp.p_world_body - sm.p_world_body) / (2 * h);
  const Eigen::Vector3d a_fd = (sp.v_world - sm.v_world) / (2 * h);
  const Eigen::Vector3d a_fd2 = (sp.p_world_body - 2 * s.p_world_body + sm.p_world_body) / (h * h);
  EXPECT_LT((s.omega_body - w_fd).norm(), 1e-5 + 1e-5 * s.omega_body.norm()) << what << " t=" << t_ns;
  EXPECT_LT((s.v_world - v_fd).norm(), 1e-6 + 1e-6 * s.v_world.norm()) << what << " t=" << t_ns;
  EXPECT_LT((s.a_world - a_fd).norm(), accel_tol + 1e-5 * s.a_world.norm()) << what << " t=" << t_ns;
  EXPECT_LT((s.a_world - a_fd2).norm(), 2e-3 + 1e-3 * s.a_world.norm()) << what << " t=" << t_ns;
  EXPECT_NEAR(s.q_world_body.norm(), 1.0, 1e-12);
}

void check_all(const Trajectory& traj, const std::string& what, int n) {
  const TimeNs span = traj.end_ns() - traj.start_ns();
  for (int i = 1; i < n; ++i) {
    expect_consistent(traj, traj.start_ns() + span / n * i + 12'345, what);
  }
  // Boundaries of segments: the script is C2 there (the jerk jumps, so the central difference of
  // the velocity is only O(h) accurate; a jump in acceleration would show as an O(1) error).
  for (const Segment& s : traj.segments()) {
    if (s.t0_ns > traj.start_ns()) {
      expect_consistent(traj, s.t0_ns, what + " boundary", 1e-3);
    }
  }
}

TEST(Motion, StaticProtocolRatesMatchFiniteDifferences) {
  StaticProtocolOptions o;
  o.poses = 12;
  o.initial_still_s = 5.0;
  o.tremor.enabled = true;
  auto traj = make_static_protocol(o, 7);
  ASSERT_TRUE(traj.ok()) << traj.error().message;
  check_all(**traj, "static", 400);
}

TEST(Motion, SixFaceAndStillRatesMatchFiniteDifferences) {
  SixFaceOptions f;
  f.hold_s = 2.0;
  auto faces = make_six_face(f, 3);
  ASSERT_TRUE(faces.ok());
  check_all(**faces, "six-face", 200);
  StillOptions s;
  s.duration_s = 20.0;
  s.tremor.enabled = true;
  auto still = make_still(s, 3);
  ASSERT_TRUE(still.ok());
  check_all(**still, "still", 100);
}

TEST(Motion, CheckerboardRatesMatchFiniteDifferences) {
  CheckerboardMotionOptions o;
  o.tremor.enabled = true;
  auto traj = CheckerboardMotion::create(o, 5);
  ASSERT_TRUE(traj.ok()) << traj.error().message;
  check_all(**traj, "checkerboard", 400);
}

TEST(Motion, SegmentsCoverTheScriptAndHoldsAreStill) {
  StaticProtocolOptions o;
  o.poses = 20;
  o.initial_still_s = 10.0;
  auto traj = make_static_protocol(o, 11);
  ASSERT_TRUE(traj.ok());
  const auto& segs = (*traj)->segments();
  ASSERT_EQ(segs.size(), 1u + 2u * 20u);
  EXPECT_EQ(segs.front().kind, "still");
  EXPECT_EQ(segs.front().t0_ns, (*traj)->start_ns());
  EXPECT_EQ(segs.back().t1_ns, (*traj)->end_ns());
  EXPECT_NEAR(ns_to_s(segs.front().t1_ns - segs.front().t0_ns), 10.0, 1e-9);
  int holds = 0;
  for (std::size_t i = 0; i < segs.size(); ++i) {
    if (i > 0) {
      EXPECT_EQ(segs[i].t0_ns, segs[i - 1].t1_ns);
    }
    const Segment& s = segs[i];
    double max_w = 0.0, max_a = 0.0;
    for (int k = 0; k <= 50; ++k) {
      const RigState st = (*traj)->at(s.t0_ns + (s.t1_ns - s.t0_ns) * k / 50);
      max_w = std::max(max_w, st.omega_body.norm());
      max_a = std::max(max_a, st.a_world.norm());
    }
    if (s.kind == "hold" || s.kind == "still") {
      EXPECT_LT(max_w, 1e-12) << i;
      EXPECT_LT(max_a, 1e-12) << i;
      if (s.kind == "hold") {
        ++holds;
        const double d = ns_to_s(s.t1_ns - s.t0_ns);
        EXPECT_GE(d, 1.0 - 1e-3);
        EXPECT_LE(d, 4.0 + 1e-3);
      }
    } else {
      EXPECT_EQ(s.kind, "move");
      EXPECT_GT(max_w, 0.1) << "a move must rotate the rig";
      EXPECT_LT(max_w, 4.0) << "a calm hand does not spin the rig this fast";
    }
  }
  EXPECT_EQ(holds, 20);
  EXPECT_EQ((*traj)->poses(), 20);
}

TEST(Motion, StaticAttitudesAreDistinctAndSpreadOverTheSphere) {
  StaticProtocolOptions o;
  o.poses = 40;
  auto traj = make_static_protocol(o, 23);
  ASSERT_TRUE(traj.ok());
  std::vector<Eigen::Quaterniond> q;
  std::vector<Eigen::Vector3d> up_body;
  for (const Segment& s : (*traj)->segments()) {
    if (s.kind != "hold" && s.kind != "still") continue;
    const RigState st = (*traj)->at((s.t0_ns + s.t1_ns) / 2);
    q.push_back(st.q_world_body);
    up_body.push_back(st.q_world_body.conjugate() * Eigen::Vector3d::UnitZ());
  }
  ASSERT_EQ(q.size(), 41u);
  for (std::size_t i = 1; i < q.size(); ++i) EXPECT_GT(q[i].angularDistance(q[i - 1]), 19.0 * kDeg) << i;
  // Every direction of the sphere is within 40 deg of some pose's "up".
  for (int k = 0; k < 200; ++k) {
    const double z = 1.0 - 2.0 * (k + 0.5) / 200.0, r = std::sqrt(1 - z * z), phi = 2.39996 * k;
    const Eigen::Vector3d d(r * std::cos(phi), r * std::sin(phi), z);
    double best = -1.0;
    for (const auto& u : up_body) best = std::max(best, u.dot(d));
    EXPECT_GT(best, std::cos(40.0 * kDeg)) << "direction " << d.transpose() << " not covered";
  }
}

TEST(Motion, SixFacesPutEachAxisUp) {
  SixFaceOptions f;
  f.hold_s = 5.0;
  auto traj = make_six_face(f, 1);
  ASSERT_TRUE(traj.ok());
  std::vector<Eigen::Vector3d> expected = {Eigen::Vector3d::UnitZ(),  -Eigen::Vector3d::UnitY(),
                                           -Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitY(),
                                           Eigen::Vector3d::UnitX(),  -Eigen::Vector3d::UnitX()};
  std::size_t face = 0;
  for (const Segment& s : (*traj)->segments()) {
    if (s.kind != "face") continue;
    ASSERT_LT(face, expected.size());
    const RigState st = (*traj)->at((s.t0_ns + s.t1_ns) / 2);
    const Eigen::Vector3d up = st.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
    EXPECT_LT((up - expected[face]).norm(), 1e-9) << six_face_names()[face];
    EXPECT_NEAR(ns_to_s(s.t1_ns - s.t0_ns), 5.0, 1e-9);
    ++face;
  }
  EXPECT_EQ(face, 6u);
}

TEST(Motion, ChosenFacesAndRevisitsAreLabelledWithTheFaceUp) {
  // Each hold's label names the axis the rig really has up, for the chosen faces and for the
  // revisits alike.
  SixFaceOptions f;
  f.hold_s = 5.0;
  f.faces = {0, 4, 5};  // +z, +x, -x
  f.revisits = 8;
  auto traj = make_six_face(f, 3);
  ASSERT_TRUE(traj.ok());
  const std::map<std::string, Eigen::Vector3d> axis = {
      {"+z up", Eigen::Vector3d::UnitZ()},  {"-y up", -Eigen::Vector3d::UnitY()},
      {"-z up", -Eigen::Vector3d::UnitZ()}, {"+y up", Eigen::Vector3d::UnitY()},
      {"+x up", Eigen::Vector3d::UnitX()},  {"-x up", -Eigen::Vector3d::UnitX()}};
  std::vector<std::string> labels;
  for (const Segment& s : (*traj)->segments()) {
    if (s.kind != "face" && s.kind != "hold") continue;
    ASSERT_EQ(axis.count(s.label), 1u) << "'" << s.label << "'";
    const RigState st = (*traj)->at((s.t0_ns + s.t1_ns) / 2);
    const Eigen::Vector3d up = st.q_world_body.conjugate() * Eigen::Vector3d::UnitZ();
    EXPECT_LT((up - axis.at(s.label)).norm(), 1e-9) << s.label;
    labels.push_back(s.label);
  }
  ASSERT_EQ(labels.size(), 11u);
  EXPECT_EQ(labels[0], "+z up");
  EXPECT_EQ(labels[1], "+x up");
  EXPECT_EQ(labels[2], "-x up");
  for (std::size_t k = 3; k < labels.size(); ++k) EXPECT_NE(labels[k], labels[k - 1]) << "revisit " << k;
}

TEST(Motion, SameSeedSameMotionOtherSeedOtherMotion) {
  StaticProtocolOptions o;
  o.poses = 10;
  auto a = make_static_protocol(o, 99), b = make_static_protocol(o, 99), c = make_static_protocol(o, 100);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  ASSERT_EQ((*a)->end_ns(), (*b)->end_ns());
  bool differs = (*a)->end_ns() != (*c)->end_ns();
  for (int k = 0; k < 100; ++k) {
    const TimeNs t = (*a)->end_ns() / 100 * k;
    const RigState sa = (*a)->at(t), sb = (*b)->at(t), sc = (*c)->at(t);
    EXPECT_EQ(sa.q_world_body.coeffs(), sb.q_world_body.coeffs());
    EXPECT_EQ(sa.p_world_body, sb.p_world_body);
    EXPECT_EQ(sa.omega_body, sb.omega_body);
    if (!sa.q_world_body.coeffs().isApprox(sc.q_world_body.coeffs())) differs = true;
  }
  EXPECT_TRUE(differs);
}

TEST(Motion, CheckerboardMeetsExcitationTargetsAndKeepsBoardInView) {
  CheckerboardMotionOptions o;  // 90 s, Krebs 5.1.1 targets
  auto traj = CheckerboardMotion::create(o, 42);
  ASSERT_TRUE(traj.ok());
  const CheckerboardMotion& m = **traj;
  EXPECT_EQ(m.end_ns(), 90 * kNsPerSecond);
  double sum_a = 0, sum_w = 0;
  const int n = 9000;
  double worst_off_axis = 0.0;
  for (int k = 0; k <= n; ++k) {
    const RigState s = m.at(m.end_ns() / n * k);
    sum_a += s.a_world.norm();
    sum_w += s.omega_body.norm();
    const Eigen::Vector3d to_board = o.board_centre_world - s.p_world_body;
    const Eigen::Vector3d view = s.q_world_body * Eigen::Vector3d::UnitZ();
    worst_off_axis = std::max(worst_off_axis, std::acos(view.dot(to_board.normalized())));
  }
  EXPECT_NEAR(sum_a / (n + 1), 3.12, 0.03 * 3.12);
  EXPECT_NEAR(sum_w / (n + 1), 0.366, 0.03 * 0.366);
  EXPECT_LT(worst_off_axis, 40.0 * kDeg) << "the board centre leaves a typical field of view";
  // Still at both ends.
  EXPECT_LT(m.at(0).omega_body.norm(), 1e-12);
  EXPECT_LT(m.at(m.end_ns()).a_world.norm(), 1e-12);

  // The board frame: centred on board_centre_world, z away from the rig.
  TargetDescription target;
  target.cols = 7;
  target.rows = 6;
  target.col_spacing_m = target.row_spacing_m = 0.05;
  const Eigen::Isometry3d T = m.T_world_board(target);
  const Eigen::Vector3d centre = T * Eigen::Vector3d(0.15, 0.125, 0.0);
  EXPECT_LT((centre - o.board_centre_world).norm(), 1e-12);
  EXPECT_GT((T.linear() * Eigen::Vector3d::UnitZ()).dot(o.board_centre_world - m.p_world_body_nominal()),
            0.0);

  // Excitation scales the targets.
  o.excitation = 2.0;
  auto fast = CheckerboardMotion::create(o, 42);
  ASSERT_TRUE(fast.ok());
  double sum2 = 0;
  for (int k = 0; k <= n; ++k) sum2 += (*fast)->at((*fast)->end_ns() / n * k).a_world.norm();
  EXPECT_NEAR(sum2 / (n + 1), 6.24, 0.03 * 6.24);
}

TEST(Motion, OptionsAreValidated) {
  StaticProtocolOptions o;
  o.poses = 8;
  auto r = make_static_protocol(o, 1);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("9..100"), std::string::npos);
  o.poses = 101;
  EXPECT_FALSE(make_static_protocol(o, 1).ok());
  CheckerboardMotionOptions c;
  c.duration_s = 5.0;
  EXPECT_FALSE(CheckerboardMotion::create(c, 1).ok());
  StillOptions s;
  s.duration_s = 0.0;
  EXPECT_FALSE(make_still(s, 1).ok());
}

}  // namespace
}  // namespace imucal::sim
