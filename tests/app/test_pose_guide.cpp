// SPDX-License-Identifier: BSD-3-Clause
// The operator's pose guidance: words and drawing by the rig's named sides or the IMU's axes.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "app/session/pose_guide.hpp"

namespace imucal::app::session {
namespace {

const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(),
                      Z = Eigen::Vector3d::UnitZ();

bool has(const std::vector<std::string>& lines, const std::string& part) {
  for (const auto& line : lines)
    if (line.find(part) != std::string::npos) return true;
  return false;
}

TEST(PoseGuide, WithoutNamedSidesTheIMUsAxesAreNamed) {
  const PoseGuide guide{RigConfig{}};
  EXPECT_FALSE(guide.named());
  EXPECT_EQ(guide.up_name(-Y), "-Y up");
  EXPECT_EQ(guide.instruction(Z), "Turn the rig so that the IMU's +Z axis points up");
  const auto art = guide.drawing(Z);  // +Z up, +X toward the operator, right = Z x X = +Y
  EXPECT_TRUE(has(art, "/    +Z     /|")) << art[1];
  EXPECT_TRUE(has(art, "|    +X     |")) << art[4];
  EXPECT_TRUE(has(art, "right: +Y")) << art[3];
}

TEST(PoseGuide, NamedSidesGiveWordsAndARightHandedDrawing) {
  RigConfig config;
  config.sides = RigSides{};  // front +x, left +y, top +z
  const PoseGuide guide{config};
  EXPECT_TRUE(guide.named());
  EXPECT_EQ(guide.up_name(Y), "left side up");
  EXPECT_EQ(guide.instruction(Y), "Put the rig on its right side, left side up");
  EXPECT_EQ(guide.instruction(-X), "Put the rig on its front side, back side up");
  EXPECT_EQ(guide.instruction(Z), "Stand the rig upright (top side up)");
  EXPECT_EQ(guide.instruction(-Z), "Turn the rig upside down (bottom side up)");
  // Upright, front to the operator: the rig's left is on the operator's right.
  EXPECT_TRUE(has(guide.drawing(Z), "right: LEFT"));
  // On its right side, front to the operator: the top has turned to the operator's left.
  const auto side = guide.drawing(Y);
  EXPECT_TRUE(has(side, "LEFT")) << side[1];
  EXPECT_TRUE(has(side, "FRONT")) << side[4];
  EXPECT_TRUE(has(side, "right: BOTTOM")) << side[3];
  // Front up: the top faces the operator.
  const auto back = guide.drawing(X);
  EXPECT_TRUE(has(back, "FRONT")) << back[1];
  EXPECT_TRUE(has(back, "|    TOP    |")) << back[4];
  for (const auto& line : back) EXPECT_LE(line.size(), 44u) << line;
}

TEST(PoseGuide, SidesFollowTheMountingIntoTheSamplesFrame) {
  RigConfig config;
  config.sides = RigSides{};
  // A signed permutation is applied to the counts: samples are in rig axes, names unchanged.
  config.imu.R_rig_imu << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  EXPECT_EQ(PoseGuide{config}.up_name(Z), "top side up");
  // A mounting between the axes (30 deg about z) leaves samples in IMU axes: top stays +z, the
  // IMU's x is between front and left and named by its axis.
  config.imu.R_rig_imu = Eigen::AngleAxisd(0.5235987755982988, Z).toRotationMatrix();
  const PoseGuide tilted{config};
  EXPECT_EQ(tilted.up_name(Z), "top side up");
  EXPECT_EQ(tilted.up_name(X), "+X up");
  EXPECT_EQ(tilted.instruction(X), "Turn the rig so that the IMU's +X axis points up");
}

}  // namespace
}  // namespace imucal::app::session
