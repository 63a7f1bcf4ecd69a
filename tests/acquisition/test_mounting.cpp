// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <vector>

#include "acquisition/mounting.hpp"

namespace imucal::acq {
namespace {

Eigen::Matrix3d rot(const Eigen::Vector3d& axis, double deg) {
  return Eigen::AngleAxisd(deg * std::numbers::pi / 180.0, axis.normalized()).toRotationMatrix();
}

MountingMap map_of(const Eigen::Matrix3d& R) {
  auto m = MountingMap::from_rotation(R);
  EXPECT_TRUE(m.ok()) << (m.ok() ? "" : m.error().message);
  return m.ok() ? *m : MountingMap{};
}

TEST(Mounting, IdentityIsIdentity) {
  const auto m = map_of(Eigen::Matrix3d::Identity());
  EXPECT_EQ(m.kind(), MountingKind::kIdentity);
  EXPECT_EQ(m.raw_to_rig({1, 2, 3}), Eigen::Vector3d(1, 2, 3));
}

// Hand-written expectations, axis by axis: each case says where every IMU axis must end up,
// independently of the code's own matrix arithmetic.
struct AxisCase {
  const char* name;
  Eigen::Matrix3d R;
  Eigen::Vector3d rig_of_x, rig_of_y, rig_of_z;  // rig-frame image of the IMU unit axes
};

TEST(Mounting, AxisByAxis) {
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(),
                        Z = Eigen::Vector3d::UnitZ();
  const std::vector<AxisCase> cases = {
      // Yaw 90: IMU x points along rig y, IMU y along rig -x.
      {"yaw90", rot(Z, 90), Y, -X, Z},
      {"yaw180", rot(Z, 180), -X, -Y, Z},
      {"yaw270", rot(Z, 270), -Y, X, Z},
      // Roll 180 (upside down about x): y and z flip.
      {"roll180", rot(X, 180), X, -Y, -Z},
      // Pitch 90: IMU x along rig -z, IMU z along rig x.
      {"pitch90", rot(Y, 90), -Z, Y, X},
      {"roll90", rot(X, 90), X, Z, -Y},
      // Roll 180 then yaw 90 (R = Rz(90) Rx(180)).
      {"roll180_yaw90", rot(Z, 90) * rot(X, 180), Y, X, -Z},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const auto m = map_of(c.R);
    ASSERT_EQ(m.kind(), MountingKind::kAxisPermutation);
    ASSERT_TRUE(m.exact_on_raw());
    // Unit counts on one IMU axis at a time.
    EXPECT_EQ(m.raw_to_rig(X), c.rig_of_x);
    EXPECT_EQ(m.raw_to_rig(Y), c.rig_of_y);
    EXPECT_EQ(m.raw_to_rig(Z), c.rig_of_z);
    // The SI path agrees exactly with the raw path.
    const Eigen::Vector3d v(123, -4567, 891);
    EXPECT_EQ(m.raw_to_rig(v), m.si_to_rig(v));
    // Accel and gyro get the same map.
    ImuSample s;
    s.accel = Eigen::Vector3d(1, 2, 3);
    s.gyro = Eigen::Vector3d(1, 2, 3);
    m.remap_raw_sample(s);
    EXPECT_EQ(s.accel, s.gyro);
    EXPECT_EQ(s.accel, Eigen::Vector3d(1 * c.rig_of_x + 2 * c.rig_of_y + 3 * c.rig_of_z));
  }
}

TEST(Mounting, AllTwentyFourSignedPermutationsAreExact) {
  int exact = 0;
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (const auto& p : perms) {
    for (int signs = 0; signs < 8; ++signs) {
      Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
      for (int i = 0; i < 3; ++i) R(i, p[i]) = (signs >> i) & 1 ? -1.0 : 1.0;
      auto m = MountingMap::from_rotation(R);
      if (R.determinant() < 0) {
        EXPECT_FALSE(m.ok());  // reflections are rejected
        continue;
      }
      ASSERT_TRUE(m.ok());
      ++exact;
      EXPECT_TRUE(m->exact_on_raw());
      for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(m->source_axis(i), p[i]);
        Eigen::Vector3d e = Eigen::Vector3d::Zero();
        e[p[i]] = 1.0;
        EXPECT_EQ(m->raw_to_rig(e)[i], R(i, p[i]));
      }
    }
  }
  EXPECT_EQ(exact, 24);
}

TEST(Mounting, MostNegativeCountFlipsWithoutOverflow) {
  const auto m = map_of(rot(Eigen::Vector3d::UnitX(), 180));
  const Eigen::Vector3d out = m.raw_to_rig({-32768, -32768, 32767});
  EXPECT_EQ(out, Eigen::Vector3d(-32768, 32768, -32767));
}

TEST(Mounting, NearlyExactMatricesSnap) {
  Eigen::Matrix3d R = rot(Eigen::Vector3d::UnitZ(), 90);  // cos(90 deg) is 6e-17, not 0
  EXPECT_NE(R(0, 0), 0.0);
  const auto m = map_of(R);
  EXPECT_EQ(m.kind(), MountingKind::kAxisPermutation);
  EXPECT_EQ(m.R_rig_imu()(0, 0), 0.0);
  EXPECT_EQ(m.describe(), "x_rig = -y_imu, y_rig = +x_imu, z_rig = +z_imu");
}

TEST(Mounting, GeneralRotationStaysInSi) {
  const Eigen::Matrix3d R = rot(Eigen::Vector3d(0, 0, 1), 30);
  const auto m = map_of(R);
  EXPECT_EQ(m.kind(), MountingKind::kGeneral);
  EXPECT_FALSE(m.exact_on_raw());
  const Eigen::Vector3d v(1, 0, 0);
  EXPECT_TRUE(m.si_to_rig(v).isApprox(Eigen::Vector3d(std::cos(std::numbers::pi / 6), 0.5, 0)));
  EXPECT_NE(m.describe().find("general"), std::string::npos);
}

TEST(Mounting, RejectsNonRotations) {
  Eigen::Matrix3d scaled = 2.0 * Eigen::Matrix3d::Identity();
  auto a = MountingMap::from_rotation(scaled);
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.error().message.find("not orthonormal"), std::string::npos);
  Eigen::Matrix3d mirror = Eigen::Matrix3d::Identity();
  mirror(2, 2) = -1;
  auto b = MountingMap::from_rotation(mirror);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().message.find("reflection"), std::string::npos);
  Eigen::Matrix3d nan = Eigen::Matrix3d::Identity();
  nan(0, 1) = std::nan("");
  EXPECT_FALSE(MountingMap::from_rotation(nan).ok());
}

}  // namespace
}  // namespace imucal::acq
