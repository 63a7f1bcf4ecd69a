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
