// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "core/imu_model.hpp"

namespace imucal::calib {
namespace {

TedaldiImuModel sample_tedaldi() {
  TedaldiImuModel m;
  m.accel.T = accel_misalignment(Eigen::Vector3d(0.0049, -0.0055, 0.0079));
  m.accel.scale = Eigen::Vector3d(0.9908, 1.0068, 1.0066);
  m.accel.bias = Eigen::Vector3d(0.0793, -0.0024, 0.0636);
  Eigen::Matrix<double, 6, 1> g;
  g << 0.0112, -0.0211, 0.0040, -0.0010, 0.0270, 0.0151;  // Tedaldi table 4.2
  m.gyro.T = gyro_misalignment(g);
  m.gyro.scale = Eigen::Vector3d(0.8786, 0.9703, 1.0460);
  m.gyro.bias = Eigen::Vector3d(0.01, -0.02, 0.005);
  return m;
}

KrebsImuModel sample_krebs() {
  KrebsImuModel k;  // values of Krebs 2012, section 5.2.2
  k.S_a = Eigen::Vector3d(1.00218, 1.00008, 1.01080);
  k.M_a = Eigen::Vector3d(-0.00115, 0.00137, 0.00092);
  k.b_a = Eigen::Vector3d(0.1, -0.2, 0.05);
  k.S_g = Eigen::Vector3d(1.00377, 0.99688, 1.00473);
  k.M_g = Eigen::Vector3d(0.00109, 0.00360, 0.01633);
  k.C_bg = Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  k.B_g << 1e-4, -2e-4, 3e-5, 5e-5, 1e-4, -1e-4, 2e-5, 0.0, 1.5e-4;
  k.b_g = Eigen::Vector3d(0.003, 0.001, -0.002);
  return k;
}

TEST(ImuModel, AnglesRoundTrip) {
  const Eigen::Vector3d a(0.1, -0.2, 0.3);
  EXPECT_TRUE(accel_angles(accel_misalignment(a)).isApprox(a));
  Eigen::Matrix<double, 6, 1> g;
  g << 1, 2, 3, 4, 5, 6;
  EXPECT_TRUE(gyro_angles(gyro_misalignment(g)).isApprox(g));
  // Eq. 2.2 and 2.3 layouts.
  const Eigen::Matrix3d T = accel_misalignment(a);
  EXPECT_DOUBLE_EQ(T(0, 1), -0.1);
  EXPECT_DOUBLE_EQ(T(0, 2), -0.2);
  EXPECT_DOUBLE_EQ(T(1, 2), -0.3);
  EXPECT_DOUBLE_EQ(T(1, 0), 0.0);
  const Eigen::Matrix3d Tg = gyro_misalignment(g);
  EXPECT_DOUBLE_EQ(Tg(1, 0), 3.0);
  EXPECT_DOUBLE_EQ(Tg(2, 0), -5.0);
  EXPECT_DOUBLE_EQ(Tg(2, 1), 6.0);
}

TEST(ImuModel, TedaldiCanonicalSameCorrection) {
  const TedaldiImuModel t = sample_tedaldi();
  const CanonicalImuModel c = canonical_from_tedaldi(t);
  const Eigen::Vector3d raw(1.0, -9.0, 3.0);
  EXPECT_TRUE(c.correct_accel(raw).isApprox(t.accel.apply(raw), 1e-14));
  EXPECT_TRUE(c.correct_gyro(raw, Eigen::Vector3d::Zero()).isApprox(t.gyro.apply(raw), 1e-14));
}

TEST(ImuModel, TedaldiRoundTrip) {
  const TedaldiImuModel t = sample_tedaldi();
  auto back = tedaldi_from_canonical(canonical_from_tedaldi(t));
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(back->R_canonical_aof.isIdentity(1e-12));
  EXPECT_TRUE(back->model.accel.T.isApprox(t.accel.T, 1e-12));
  EXPECT_TRUE(back->model.accel.scale.isApprox(t.accel.scale, 1e-12));
  EXPECT_TRUE(back->model.accel.bias.isApprox(t.accel.bias, 1e-12));
  EXPECT_TRUE(back->model.gyro.T.isApprox(t.gyro.T, 1e-12));
  EXPECT_TRUE(back->model.gyro.scale.isApprox(t.gyro.scale, 1e-12));
  EXPECT_TRUE(back->model.gyro.bias.isApprox(t.gyro.bias, 1e-12));
}

TEST(ImuModel, TedaldiFromRotatedCanonicalRecoversFrame) {
  const TedaldiImuModel t = sample_tedaldi();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, -1, 2).normalized()).toRotationMatrix();
  auto back = tedaldi_from_canonical(canonical_from_tedaldi(t).expressed_in(R));
  ASSERT_TRUE(back.ok());
  EXPECT_TRUE(back->R_canonical_aof.isApprox(R, 1e-12));
  EXPECT_TRUE(back->model.accel.T.isApprox(t.accel.T, 1e-12));
  EXPECT_TRUE(back->model.gyro.T.isApprox(t.gyro.T, 1e-12));
  EXPECT_TRUE(back->model.gyro.scale.isApprox(t.gyro.scale, 1e-12));
}

TEST(ImuModel, TedaldiRejectsGSensitivity) {
  CanonicalImuModel c;
  c.G(0, 0) = 1e-4;
  auto r = tedaldi_from_canonical(c);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("g-sensitivity"), std::string::npos);
}

TEST(ImuModel, KrebsRoundTrip) {
  const KrebsImuModel k = sample_krebs();
  auto c = canonical_from_krebs(k);
  ASSERT_TRUE(c.ok());
  // The canonical model inverts the Krebs forward model.
  const Eigen::Vector3d a(0.3, -9.7, 1.2), w(0.5, -0.2, 1.1);
  const Eigen::Vector3d a_raw = k.S_a.asDiagonal() * krebs_misalignment(k.M_a) * a + k.b_a;
  const Eigen::Vector3d w_raw = k.S_g.asDiagonal() * krebs_misalignment(k.M_g) * k.C_bg.transpose() * w +
                                k.B_g * k.C_bg.transpose() * a + k.b_g;
  EXPECT_TRUE(c->correct_accel(a_raw).isApprox(a, 1e-12));
  EXPECT_TRUE(c->correct_gyro(w_raw, a).isApprox(w, 1e-12));

  auto back = krebs_from_canonical(*c);
  ASSERT_TRUE(back.ok());
  EXPECT_TRUE(back->R_canonical_body.isIdentity(1e-12));
  EXPECT_TRUE(back->model.S_a.isApprox(k.S_a, 1e-12));
  EXPECT_TRUE(back->model.M_a.isApprox(k.M_a, 1e-10));
  EXPECT_TRUE(back->model.S_g.isApprox(k.S_g, 1e-12));
  EXPECT_TRUE(back->model.M_g.isApprox(k.M_g, 1e-10));
  EXPECT_TRUE(back->model.C_bg.isApprox(k.C_bg, 1e-12));
  EXPECT_TRUE(back->model.B_g.isApprox(k.B_g, 1e-10));
  EXPECT_TRUE(back->model.b_g.isApprox(k.b_g, 1e-12));
}

TEST(ImuModel, TedaldiToKrebsToCanonicalIsSameCorrectionUpToFrame) {
  const TedaldiImuModel t = sample_tedaldi();
  const CanonicalImuModel c = canonical_from_tedaldi(t);
  auto k = krebs_from_canonical(c);
  ASSERT_TRUE(k.ok());
  auto c2 = canonical_from_krebs(k->model);
  ASSERT_TRUE(c2.ok());
  const CanonicalImuModel c3 = c2->expressed_in(k->R_canonical_body);
  EXPECT_TRUE(c3.A_a.isApprox(c.A_a, 1e-12));
  EXPECT_TRUE(c3.A_g.isApprox(c.A_g, 1e-12));
  EXPECT_TRUE(c3.b_a.isApprox(c.b_a, 1e-12));
  EXPECT_LT(c3.G.norm(), 1e-14);
  // And back to Tedaldi through the canonical form.
  auto t2 = tedaldi_from_canonical(c3);
  ASSERT_TRUE(t2.ok());
  EXPECT_TRUE(t2->model.gyro.T.isApprox(t.gyro.T, 1e-10));
  EXPECT_TRUE(t2->model.accel.scale.isApprox(t.accel.scale, 1e-12));
}

/// A general canonical model: full A_a, A_g in an arbitrary body frame, no g-sensitivity.
CanonicalImuModel sample_canonical() {
  CanonicalImuModel c;
  c.A_a << 1.02, 0.013, -0.021, -0.008, 0.97, 0.017, 0.011, -0.019, 1.04;
  c.b_a = Eigen::Vector3d(0.12, -0.07, 0.3);
  c.A_g << 0.99, -0.024, 0.015, 0.031, 1.03, -0.012, -0.017, 0.026, 0.96;
  c.b_g = Eigen::Vector3d(0.004, -0.002, 0.001);
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(-1, 2, 0.5).normalized()).toRotationMatrix();
  return c.expressed_in(R);
}

void expect_same_correction(const CanonicalImuModel& a, const CanonicalImuModel& b, double tol) {
  EXPECT_TRUE(a.A_a.isApprox(b.A_a, tol)) << a.A_a << "\n" << b.A_a;
  EXPECT_TRUE(a.b_a.isApprox(b.b_a, tol));
  EXPECT_TRUE(a.A_g.isApprox(b.A_g, tol)) << a.A_g << "\n" << b.A_g;
  EXPECT_TRUE(a.b_g.isApprox(b.b_g, tol));
  EXPECT_LT((a.G - b.G).norm(), tol);
}

void expect_rotation(const Eigen::Matrix3d& R) {
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_TRUE((R.transpose() * R).isIdentity(1e-12));
}

TEST(ImuModel, RotationTriangularSplitIsAProperRotationTimesUpperTriangular) {
  Eigen::Matrix3d X = sample_canonical().A_a;
  for (bool reflect : {false, true}) {
    if (reflect) X.col(1) *= -1.0;  // det < 0
    ASSERT_EQ(X.determinant() < 0, reflect);
    const RotationTriangular s = rotation_triangular_split(X);
    expect_rotation(s.Q);
    EXPECT_TRUE((s.Q * s.U).isApprox(X, 1e-14));
    EXPECT_EQ(s.U(1, 0), 0.0);
    EXPECT_EQ(s.U(2, 0), 0.0);
    EXPECT_EQ(s.U(2, 1), 0.0);
    EXPECT_GT(s.U(0, 0), 0.0);
    EXPECT_GT(s.U(1, 1), 0.0);
    // The reflection stays in U, at (2, 2).
    EXPECT_EQ(s.U(2, 2) < 0, reflect);
  }
}

TEST(ImuModel, CanonicalTedaldiCanonicalRoundTrip) {
  const CanonicalImuModel c = sample_canonical();
  auto t = tedaldi_from_canonical(c);
  ASSERT_TRUE(t.ok()) << t.error().message;
  expect_rotation(t->R_canonical_aof);
  EXPECT_TRUE(t->model.accel.T.isUpperTriangular(0.0));
  EXPECT_TRUE(t->model.accel.T.diagonal().isOnes(1e-15));
  EXPECT_TRUE(t->model.gyro.T.diagonal().isOnes(1e-15));
  EXPECT_TRUE((t->model.accel.scale.array() > 0).all());
  expect_same_correction(canonical_from_tedaldi(t->model).expressed_in(t->R_canonical_aof), c, 1e-12);
}

// An accelerometer axis wired with the wrong sign (det A_a < 0): the frame change must stay a
// rotation, the sign goes into the z scale, and the round trip gives back the same correction.
TEST(ImuModel, TedaldiFormOfAReflectedAccelerometerKeepsAProperFrame) {
  CanonicalImuModel c = sample_canonical();
  c.A_a.col(0) *= -1.0;
  ASSERT_LT(c.A_a.determinant(), 0.0);
  auto t = tedaldi_from_canonical(c);
  ASSERT_TRUE(t.ok()) << t.error().message;
  expect_rotation(t->R_canonical_aof);
  EXPECT_LT(t->model.accel.scale[2], 0.0);
  EXPECT_GT(t->model.accel.scale[0], 0.0);
  EXPECT_GT(t->model.accel.scale[1], 0.0);
  expect_same_correction(canonical_from_tedaldi(t->model).expressed_in(t->R_canonical_aof), c, 1e-12);
  // The same split serves the Krebs form.
  auto k = krebs_from_canonical(c);
  ASSERT_TRUE(k.ok()) << k.error().message;
  expect_rotation(k->R_canonical_body);
}

TEST(ImuModel, CanonicalInAofKeepsGAndMakesAaExactlyUpperTriangular) {
  CanonicalImuModel c = sample_canonical();
  c.G << 1e-4, -2e-4, 3e-5, 5e-5, 1e-4, -1e-4, 2e-5, 0.0, 1.5e-4;
  const CanonicalInAof o = canonical_in_aof(c);
  expect_rotation(o.R_canonical_aof);
  EXPECT_EQ(o.model.A_a(1, 0), 0.0);
  EXPECT_EQ(o.model.A_a(2, 0), 0.0);
  EXPECT_EQ(o.model.A_a(2, 1), 0.0);
  expect_same_correction(o.model.expressed_in(o.R_canonical_aof), c, 1e-12);
  // The strict conversion refuses what canonical_in_aof carries along.
  EXPECT_FALSE(tedaldi_from_canonical(c).ok());
}

TEST(ImuModel, TedaldiTriadSplitsTKWithUnitDiagonal) {
  Eigen::Matrix3d A;
  A << 2.0, 0.1, -0.2, 0.05, 0.5, 0.3, -0.1, 0.02, -1.5;
  const TedaldiTriad t = tedaldi_triad(A, Eigen::Vector3d(1, 2, 3));
  EXPECT_TRUE(t.TK().isApprox(A, 1e-15));
  EXPECT_TRUE(t.T.diagonal().isOnes(1e-15));
  EXPECT_EQ(t.scale, Eigen::Vector3d(2.0, 0.5, -1.5));
  EXPECT_EQ(t.bias, Eigen::Vector3d(-1, -2, -3));
}

TEST(ImuModel, SingularModelsAreRejected) {
  CanonicalImuModel c;
  c.A_a.setZero();
  EXPECT_FALSE(tedaldi_from_canonical(c).ok());
  EXPECT_FALSE(krebs_from_canonical(c).ok());
  KrebsImuModel k;
  k.S_g[1] = 0.0;
  EXPECT_FALSE(canonical_from_krebs(k).ok());
}

}  // namespace
}  // namespace imucal::calib
