// SPDX-License-Identifier: BSD-3-Clause
// Uniform B-splines (calib/spline.hpp): basis properties, time derivatives against finite
// differences of the value, and every analytic Jacobian against a numeric one.

#include <gtest/gtest.h>

#include <random>

#include "calib/spline.hpp"

namespace imucal::calib {
namespace {

Eigen::Vector3d random_vec(std::mt19937& rng, double scale) {
  std::normal_distribution<double> n(0.0, scale);
  return {n(rng), n(rng), n(rng)};
}

template <int N>
So3Spline<N> random_so3_spline(std::uint32_t seed, int knots, double dt) {
  std::mt19937 rng(seed);
  So3Spline<N> spline(0.3, dt, knots);
  Eigen::Matrix3d R = so3::exp(random_vec(rng, 1.0));
  for (auto& k : spline.knots()) {
    k = R;
    R = R * so3::exp(random_vec(rng, 0.4));  // up to about 1 rad between knots
  }
  return spline;
}

TEST(Spline, BasisIsAPartitionOfUnityAndCumulativeStartsAtOne) {
  for (double u : {0.0, 0.25, 0.5, 0.999}) {
    const auto w4 = spline_weights<4>(u, false);
    EXPECT_NEAR(w4.w.sum(), 1.0, 1e-14);
    EXPECT_NEAR(w4.dw.sum(), 0.0, 1e-13);
    EXPECT_NEAR(w4.ddw.sum(), 0.0, 1e-12);
    const auto c6 = spline_weights<6>(u, true);
    EXPECT_NEAR(c6.w(0), 1.0, 1e-14);
    EXPECT_NEAR(c6.dw(0), 0.0, 1e-14);
  }
  // The cubic B-spline's well-known basis at u = 0: 1/6, 4/6, 1/6, 0.
  const auto w = spline_weights<4>(0.0, false);
  EXPECT_NEAR(w.w(0), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(w.w(1), 4.0 / 6.0, 1e-15);
  EXPECT_NEAR(w.w(2), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(w.w(3), 0.0, 1e-15);
}

TEST(Spline, RdSplineDerivativesMatchFiniteDifferencesAndIsContinuous) {
  std::mt19937 rng(3);
  RdSpline<5> spline(1.0, 0.2, 12);
  for (auto& k : spline.knots()) k = random_vec(rng, 1.0);
  const double h = 1e-5;
  for (double t = 1.01; t < spline.timing().end_s() - 0.01; t += 0.137) {
    const Eigen::Vector3d v = spline.evaluate(t, 1);
    const Eigen::Vector3d v_num = (spline.evaluate(t + h) - spline.evaluate(t - h)) / (2 * h);
    EXPECT_LT((v - v_num).norm(), 1e-7) << t;
    const Eigen::Vector3d a = spline.evaluate(t, 2);
    const Eigen::Vector3d a_num = (spline.evaluate(t + h, 1) - spline.evaluate(t - h, 1)) / (2 * h);
    EXPECT_LT((a - a_num).norm(), 1e-6) << t;
  }
  // C^(N-2) across a knot: the second derivative is continuous for order 5.
  const double tk = 1.0 + 3 * 0.2;
  // (A jump would be of the order of knot / dt^2 = 25; the third derivative moves it by ~1e-6.)
  EXPECT_LT((spline.evaluate(tk - 1e-9, 2) - spline.evaluate(tk + 1e-9, 2)).norm(), 1e-4);
}

template <int N>
void check_so3_time_derivatives(std::uint32_t seed) {
  const So3Spline<N> spline = random_so3_spline<N>(seed, N + 6, 0.1);
  const double h = 1e-5;
  for (double t = 0.31; t < spline.timing().end_s() - 0.01; t += 0.0731) {
    const auto e = spline.evaluate(t, So3Derivs::kAcceleration);
    const auto ep = spline.evaluate(t + h, So3Derivs::kAcceleration);
    const auto em = spline.evaluate(t - h, So3Derivs::kAcceleration);
    const Eigen::Vector3d w_num = so3::log(em.R.transpose() * ep.R) / (2 * h);
    EXPECT_LT((e.omega - w_num).norm(), 1e-6 * (1 + e.omega.norm())) << "N " << N << " t " << t;
    const Eigen::Vector3d a_num = (ep.omega - em.omega) / (2 * h);
    EXPECT_LT((e.alpha - a_num).norm(), 1e-5 * (1 + e.alpha.norm())) << "N " << N << " t " << t;
  }
}

TEST(Spline, So3AngularVelocityAndAccelerationMatchFiniteDifferences) {
  check_so3_time_derivatives<3>(1);
  check_so3_time_derivatives<4>(2);
  check_so3_time_derivatives<5>(3);
  check_so3_time_derivatives<6>(4);
}

// d(value)/d(knot_i) by central differences of right perturbations of the knot.
template <int N>
void check_so3_jacobians(std::uint32_t seed) {
  So3Spline<N> spline = random_so3_spline<N>(seed, N + 4, 0.1);
  const double h = 1e-6;
  for (double t : {0.3, 0.347, 0.41, 0.5555, 0.699}) {
    SplineSegment seg;
    const auto e = spline.evaluate(t, So3Derivs::kAcceleration, true, &seg);
    for (int i = 0; i < N; ++i) {
      Eigen::Matrix3d& knot = spline.knots()[seg.first_knot + i];
      const Eigen::Matrix3d saved = knot;
      Eigen::Matrix3d dR, dw, da;
      for (int c = 0; c < 3; ++c) {
        const Eigen::Vector3d delta = h * Eigen::Vector3d::Unit(c);
        knot = saved * so3::exp(delta);
        const auto p = spline.evaluate(t, So3Derivs::kAcceleration);
        knot = saved * so3::exp(-delta);
        const auto m = spline.evaluate(t, So3Derivs::kAcceleration);
        knot = saved;
        dR.col(c) = so3::log(m.R.transpose() * p.R) / (2 * h);
        dw.col(c) = (p.omega - m.omega) / (2 * h);
        da.col(c) = (p.alpha - m.alpha) / (2 * h);
      }
      EXPECT_LT((e.dR_dknot[i] - dR).norm(), 1e-7) << "N " << N << " t " << t << " knot " << i;
      EXPECT_LT((e.domega_dknot[i] - dw).norm(), 1e-6 * (1 + dw.norm()))
          << "N " << N << " t " << t << " knot " << i;
      EXPECT_LT((e.dalpha_dknot[i] - da).norm(), 1e-5 * (1 + da.norm()))
          << "N " << N << " t " << t << " knot " << i;
    }
  }
}

TEST(Spline, So3JacobiansMatchNumericOnes) {
  check_so3_jacobians<3>(11);
  check_so3_jacobians<4>(12);
  check_so3_jacobians<5>(13);
  check_so3_jacobians<6>(14);
}

TEST(Spline, So3SplineThroughEqualKnotsIsConstantWithZeroRates) {
  So3Spline<4> spline(0.0, 0.05, 8);
  const Eigen::Matrix3d R = so3::exp(Eigen::Vector3d(0.3, -1.2, 2.0));
  for (auto& k : spline.knots()) k = R;
  const auto e = spline.evaluate(0.123, So3Derivs::kAcceleration);
  EXPECT_LT((e.R - R).norm(), 1e-12);
  EXPECT_LT(e.omega.norm(), 1e-12);
  EXPECT_LT(e.alpha.norm(), 1e-12);
}

TEST(Spline, So3HelpersAreConsistentNearZeroAndPi) {
  for (const Eigen::Vector3d& phi : {Eigen::Vector3d(1e-9, -2e-9, 0.0), Eigen::Vector3d(0.2, -0.1, 0.4),
                                     Eigen::Vector3d(0.0, 0.0, 3.1415)}) {
    EXPECT_LT((so3::log(so3::exp(phi)) - phi).norm(), 1e-9) << phi.transpose();
    EXPECT_LT(
        (so3::right_jacobian(phi) * so3::right_jacobian_inverse(phi) - Eigen::Matrix3d::Identity()).norm(),
        1e-6)
        << phi.transpose();
  }
}

}  // namespace
}  // namespace imucal::calib
