// SPDX-License-Identifier: BSD-3-Clause
// The IMU error model against its own definition (docs/simulator.md): a still rig measures
// gravity through S, M and the bias; the canonical and Tedaldi corrections invert the model;
// quantisation, saturation, temperature and noise levels.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"
#include "sim/truth.hpp"
#include "tests/support/test_helpers.hpp"

namespace imucal::sim {
namespace {

using test::kDeg;

ImuModelParams noise_free(std::uint64_t seed) {
  ImuModelParams p = ImuModelParams::draw(seed);
  p.accel_noise_density = p.gyro_noise_density = 0.0;
  p.accel_bias_random_walk = p.gyro_bias_random_walk = 0.0;
  return p;
}

RigState still_at(const Eigen::Quaterniond& q) {
  RigState s;
  s.q_world_body = q;
  return s;
}

TEST(ImuModel, StillRigMeasuresGravityThroughScaleMisalignmentAndBias) {
  ImuModelParams p = noise_free(5);
  p.gravity_mps2 = 9.8062;  // local gravity differs from standard
  ImuSimulator imu(p, 5);
  Eigen::Matrix3d S = p.accel_scale.asDiagonal();
  for (int k = 0; k < 10; ++k) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7 * k, Eigen::Vector3d(1, 2, 3 - k).normalized()));
    const ImuSimDetail d = imu.sample_si(k * 10'000'000, still_at(q), 0.01);
    const Eigen::Vector3d f = q.conjugate() * Eigen::Vector3d(0, 0, 9.8062);  // specific force: up
    EXPECT_LT((d.specific_force_body - f).norm(), 1e-12);
    const Eigen::Vector3d expect_a = S * p.accel_misalignment * f + p.accel_bias;
    EXPECT_LT((d.accel_si - expect_a).norm(), 1e-12);
    const Eigen::Vector3d expect_g = p.g_sensitivity * f + p.gyro_bias;
    EXPECT_LT((d.gyro_si - expect_g).norm(), 1e-12);
    EXPECT_NEAR(d.accel_si.norm(), (S * p.accel_misalignment * f + p.accel_bias).norm(), 1e-12);
  }
  // A flat rig with an ideal sensor reads exactly +g on z.
  ImuModelParams ideal;
  ideal.accel_noise_density = ideal.gyro_noise_density = 0.0;
  ideal.accel_bias_random_walk = ideal.gyro_bias_random_walk = 0.0;
  ImuSimulator flat(ideal, 1);
  const ImuSimDetail d = flat.sample_si(0, still_at(Eigen::Quaterniond::Identity()), 0.01);
  EXPECT_EQ(d.accel_si, Eigen::Vector3d(0, 0, kStandardGravity));
  EXPECT_EQ(d.gyro_si, Eigen::Vector3d::Zero());
}

TEST(ImuModel, RotationGoesThroughGyroMisalignmentAndAccelToGyroRotation) {
  ImuModelParams p = noise_free(8);
  ImuSimulator imu(p, 8);
  RigState s;
  s.omega_body = Eigen::Vector3d(0.3, -0.2, 0.5);
  const ImuSimDetail d = imu.sample_si(0, s, 0.01);
  const Eigen::Vector3d f(0, 0, kStandardGravity);
  const Eigen::Vector3d expect = p.gyro_scale.asDiagonal() * p.gyro_misalignment *
                                     p.q_body_gyro.toRotationMatrix().transpose() * s.omega_body +
                                 p.g_sensitivity * f + p.gyro_bias;
  EXPECT_LT((d.gyro_si - expect).norm(), 1e-12);
}

TEST(ImuModel, EarthRotationIsAddedWhenEnabled) {
  ImuModelParams p;
  p.gyro_noise_density = p.gyro_bias_random_walk = 0.0;
  p.earth_rotation = true;
  p.latitude_deg = 90.0;  // at the pole the earth rate is along world z
  ImuSimulator imu(p, 1);
  const ImuSimDetail d = imu.sample_si(0, still_at(Eigen::Quaterniond::Identity()), 0.01);
  EXPECT_NEAR(d.gyro_si.z(), kEarthRateRadps, 1e-15);
  EXPECT_NEAR(d.gyro_si.head<2>().norm(), 0.0, 1e-15);
}

TEST(ImuModel, CanonicalCorrectionInvertsTheModelInSiAndCounts) {
  const ImuModelParams p = noise_free(17);
  ImuSimulator imu(p, 17);
  const CanonicalImuModel si = canonical_correction(p, false);
  const CanonicalImuModel counts = canonical_correction(p, true);
  RigState s;
  s.q_world_body = Eigen::Quaterniond(Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -1, 0.2).normalized()));
  s.a_world = Eigen::Vector3d(1.5, -0.7, 2.0);
  s.omega_body = Eigen::Vector3d(-0.4, 0.9, 0.25);
  const ImuSimDetail d = imu.sample_si(0, s, 0.01);
  const Eigen::Vector3d a = si.A_a * (d.accel_si - si.b_a);
  const Eigen::Vector3d w = si.A_g * (d.gyro_si - si.b_g) - si.G * a;
  EXPECT_LT((a - d.specific_force_body).norm(), 1e-12);
  EXPECT_LT((w - s.omega_body).norm(), 1e-12);
  const Eigen::Vector3d ac = d.accel_si / p.accel_mps2_per_count(), gc = d.gyro_si / p.gyro_radps_per_count();
  const Eigen::Vector3d a2 = counts.A_a * (ac - counts.b_a);
  EXPECT_LT((a2 - d.specific_force_body).norm(), 1e-11);
  EXPECT_LT((counts.A_g * (gc - counts.b_g) - counts.G * a2 - s.omega_body).norm(), 1e-11);
  // The body frame is the AOF: A_a is lower-triangular.
  EXPECT_EQ(si.A_a(0, 1), 0.0);
  EXPECT_EQ(si.A_a(0, 2), 0.0);
  EXPECT_EQ(si.A_a(1, 2), 0.0);
}

TEST(ImuModel, TedaldiFormReproducesTheCalibratedVectorInItsFrame) {
  const ImuModelParams p = noise_free(29);
  ImuSimulator imu(p, 29);
  for (bool counts : {false, true}) {
    const TedaldiConversion t = tedaldi_form(p, counts);
    const TedaldiTriad& ta = t.model.accel;
    const TedaldiTriad& tg = t.model.gyro;
    // Shapes: T_a unit upper-triangular, T_g unit diagonal, K diagonal.
    EXPECT_NEAR(ta.T(1, 0), 0.0, 1e-15);
    EXPECT_NEAR(ta.T(2, 0), 0.0, 1e-15);
    EXPECT_NEAR(ta.T(2, 1), 0.0, 1e-15);
    EXPECT_NEAR((ta.T.diagonal() - Eigen::Vector3d::Ones()).norm(), 0.0, 1e-15);
    EXPECT_NEAR((tg.T.diagonal() - Eigen::Vector3d::Ones()).norm(), 0.0, 1e-15);
    // Frame O differs from the body frame by a rotation of the order of the misalignments.
    ASSERT_NEAR(t.R_canonical_aof.determinant(), 1.0, 1e-12);
    const Eigen::Quaterniond q_tedaldi_body(Eigen::Matrix3d(t.R_canonical_aof.transpose()));
    const double angle = Eigen::AngleAxisd(q_tedaldi_body).angle();
    EXPECT_GT(angle, 0.1 * kDeg);
    EXPECT_LT(angle, 4.0 * kDeg);
    const double sa = counts ? p.accel_mps2_per_count() : 1.0, sg = counts ? p.gyro_radps_per_count() : 1.0;
    RigState s;
    s.q_world_body = Eigen::Quaterniond(Eigen::AngleAxisd(2.0, Eigen::Vector3d(1, 1, -0.5).normalized()));
    s.omega_body = Eigen::Vector3d(0.2, 0.1, -0.3);
    const ImuSimDetail d = imu.sample_si(0, s, 0.01);
    const Eigen::Vector3d a_O = ta.apply(d.accel_si / sa);
    EXPECT_LT((a_O - q_tedaldi_body * d.specific_force_body).norm(), 1e-10);
    // Tedaldi's gyro model has no g-sensitivity: remove B_g f before comparing.
    const Eigen::Vector3d w_S = (d.gyro_si - p.g_sensitivity * d.specific_force_body) / sg;
    const Eigen::Vector3d w_O = tg.apply(w_S);
    EXPECT_LT((w_O - q_tedaldi_body * s.omega_body).norm(), 1e-10);
    // The canonical correction in frame O is the same correction, rotated, with A_a exactly
    // upper-triangular.
    const CanonicalImuModel o = canonical_in_tedaldi_frame(p, counts);
    EXPECT_EQ(o.A_a(1, 0), 0.0);
    EXPECT_EQ(o.A_a(2, 0), 0.0);
    EXPECT_EQ(o.A_a(2, 1), 0.0);
    EXPECT_LT((o.correct_accel(d.accel_si / sa) - q_tedaldi_body * d.specific_force_body).norm(), 1e-10);
  }
}

TEST(ImuModel, QuantisesToCountsAndFlagsSaturation) {
  ImuModelParams p;
  p.accel_noise_density = p.gyro_noise_density = 0.0;
  p.accel_bias_random_walk = p.gyro_bias_random_walk = 0.0;
  p.accel_full_scale_g = 2;
  p.gyro_full_scale_dps = 250;
  ImuSimulator imu(p, 1);
  RigState s;
  s.omega_body = Eigen::Vector3d(100.0 * kDeg, -10.0 * kDeg, 0.0);
  ImuSample q = imu.sample(0, s, 0.01);
  EXPECT_EQ(q.accel, Eigen::Vector3d(0, 0, 16384));
  EXPECT_EQ(q.gyro, Eigen::Vector3d(13100, -1310, 0));
  EXPECT_EQ(q.flags, 0u);
  // 1.5 g upwards plus gravity is 2.5 g on z; 300 deg/s on x.
  s.a_world = Eigen::Vector3d(0, 0, 1.5 * kStandardGravity);
  s.omega_body = Eigen::Vector3d(300.0 * kDeg, -300.0 * kDeg, 0.0);
  q = imu.sample(10'000'000, s, 0.01);
  EXPECT_EQ(q.accel.z(), 32767.0);
  EXPECT_EQ(q.gyro.x(), 32767.0);
  EXPECT_EQ(q.gyro.y(), -32768.0);
  EXPECT_TRUE(q.flags & kImuFlagAccelSaturated);
  EXPECT_TRUE(q.flags & kImuFlagGyroSaturated);
  // At +-16 g / 2000 deg/s the same motion fits.
  p.accel_full_scale_g = 16;
  p.gyro_full_scale_dps = 2000;
  ImuSimulator wide(p, 1);
  q = wide.sample(0, s, 0.01);
  EXPECT_EQ(q.flags, 0u);
  EXPECT_EQ(q.accel.z(), std::nearbyint(2.5 * 2048));
  EXPECT_EQ(q.gyro.x(), std::nearbyint(300.0 * 16.4));
}

TEST(ImuModel, FullScaleTables) {
  EXPECT_EQ(*accel_lsb_per_g(2), 16384.0);
  EXPECT_EQ(*accel_lsb_per_g(16), 2048.0);
  EXPECT_EQ(*gyro_lsb_per_dps(250), 131.0);
  EXPECT_EQ(*gyro_lsb_per_dps(500), 65.5);
  EXPECT_EQ(*gyro_lsb_per_dps(1000), 32.8);
  EXPECT_EQ(*gyro_lsb_per_dps(2000), 16.4);
  EXPECT_FALSE(accel_lsb_per_g(3).ok());
  EXPECT_FALSE(gyro_lsb_per_dps(300).ok());
}

TEST(ImuModel, TemperatureFollowsTheWarmUpAndTheRegisterFormula) {
  ImuModelParams p;
  p.temp_start_c = 25.0;
  p.temp_final_c = 40.0;
  p.temp_time_constant_s = 100.0;
  p.gyro_bias_temp_coeff = Eigen::Vector3d(1e-3, 0, 0);
  p.accel_noise_density = p.gyro_noise_density = 0.0;
  p.accel_bias_random_walk = p.gyro_bias_random_walk = 0.0;
  ImuSimulator imu(p, 1);
  ImuSimDetail d;
  const ImuSample s0 = imu.sample(0, RigState{}, 0.01, &d);
  EXPECT_NEAR(s0.temperature / 340.0 + 36.53, 25.0, 0.5 / 340.0);
  const ImuSample s1 = imu.sample(100 * kNsPerSecond, RigState{}, 0.01, &d);
  const double t1 = 40.0 - 15.0 * std::exp(-1.0);
  EXPECT_NEAR(s1.temperature / 340.0 + 36.53, t1, 0.5 / 340.0);
  EXPECT_NEAR(d.gyro_bias.x(), 1e-3 * (t1 - 25.0), 1e-12);
}

TEST(ImuModel, WhiteNoiseHasTheDensityOfTheModel) {
  ImuModelParams p;  // datasheet densities, no random walk
  p.accel_bias_random_walk = p.gyro_bias_random_walk = 0.0;
  ImuSimulator imu(p, 77);
  const int n = 20000;
  const double rate = 200.0;
  Eigen::Vector3d sa = Eigen::Vector3d::Zero(), sg = sa;
  for (int k = 0; k < n; ++k) {
    const ImuSimDetail d = imu.sample_si(static_cast<TimeNs>(k) * 5'000'000, RigState{}, 1.0 / rate);
    Eigen::Vector3d ea = d.accel_si - Eigen::Vector3d(0, 0, kStandardGravity);
    sa += ea.cwiseProduct(ea);
    sg += d.gyro_si.cwiseProduct(d.gyro_si);
  }
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(std::sqrt(sa[i] / n), 3.92e-3 * std::sqrt(rate), 0.03 * 3.92e-3 * std::sqrt(rate));
    EXPECT_NEAR(std::sqrt(sg[i] / n), 8.73e-5 * std::sqrt(rate), 0.03 * 8.73e-5 * std::sqrt(rate));
  }
}

TEST(ImuModel, BiasRandomWalkGrowsWithTheSquareRootOfTime) {
  ImuModelParams p;
  p.accel_noise_density = p.gyro_noise_density = 0.0;
  p.gyro_bias_random_walk = 1e-3;
  // Many independent walks of 100 s: the end spread is rw * sqrt(100 s).
  double sum2 = 0.0;
  const int walks = 300;
  for (int w = 0; w < walks; ++w) {
    ImuSimulator imu(p, 1000 + w);
    ImuSimDetail d;
    for (int k = 1; k <= 100; ++k) d = imu.sample_si(k * kNsPerSecond, RigState{}, 1.0);
    sum2 += d.gyro_bias.squaredNorm() / 3.0;
  }
  EXPECT_NEAR(std::sqrt(sum2 / walks), 1e-3 * 10.0, 0.1 * 1e-3 * 10.0);
}

TEST(ImuModel, DrawnParametersHaveRealisticSpreadsAndAreDeterministic) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const ImuModelParams p = ImuModelParams::draw(seed);
    ASSERT_TRUE(p.validate().ok()) << p.validate().error().message;
    for (int i = 0; i < 3; ++i) {
      EXPECT_GE(std::abs(p.accel_scale[i] - 1.0), 0.01 - 1e-12);
      EXPECT_LE(std::abs(p.accel_scale[i] - 1.0), 0.03 + 1e-12);
      EXPECT_LE(std::abs(p.gyro_bias[i]), 5.0 * kDeg);
    }
    const double m = std::asin(std::abs(p.accel_misalignment(2, 1)));
    EXPECT_GE(m, 0.5 * kDeg - 1e-12);
    EXPECT_LE(m, 2.0 * kDeg + 1e-12);
    EXPECT_LE(std::abs(p.accel_bias.x()), 0.05 * kStandardGravity);
    EXPECT_LE(std::abs(p.accel_bias.z()), 0.08 * kStandardGravity);
  }
  const ImuModelParams a = ImuModelParams::draw(3), b = ImuModelParams::draw(3), c = ImuModelParams::draw(4);
  EXPECT_EQ(a.accel_misalignment, b.accel_misalignment);
  EXPECT_EQ(a.g_sensitivity, b.g_sensitivity);
  EXPECT_NE(a.accel_scale, c.accel_scale);
}

TEST(ImuModel, ValidationNamesWhatIsWrong) {
  ImuModelParams p;
  p.accel_misalignment(0, 1) = 0.01;
  EXPECT_NE(p.validate().error().message.find("lower-triangular"), std::string::npos);
  p = ImuModelParams();
  p.gyro_bias = Eigen::Vector3d(2.0, 0, 0);  // deg/s given as rad/s
  EXPECT_NE(p.validate().error().message.find("rad/s"), std::string::npos);
  p = ImuModelParams();
  p.accel_full_scale_g = 3;
  EXPECT_FALSE(p.validate().ok());
  p = ImuModelParams();
  p.gravity_mps2 = 1.0;  // in g, not m/s^2
  EXPECT_NE(p.validate().error().message.find("m/s^2"), std::string::npos);
}

}  // namespace
}  // namespace imucal::sim
