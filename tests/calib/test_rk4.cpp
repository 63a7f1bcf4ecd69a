// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

#include "calib/rk4.hpp"

namespace imucal::calib {
namespace {

TEST(Rk4n, ConstantRateMatchesClosedForm) {
  const Eigen::Vector3d w(0.3, -0.5, 0.8);
  std::vector<Eigen::Vector3d> rates(201, w);
  std::vector<double> t(201);
  for (int i = 0; i <= 200; ++i) t[i] = 0.01 * i;
  const Quat4 q = integrate_rk4n(rates, t);
  const Eigen::Quaterniond expect(Eigen::AngleAxisd(w.norm() * 2.0, w.normalized()));
  EXPECT_NEAR(q[0], expect.w(), 1e-9);
  EXPECT_NEAR(q[1], expect.x(), 1e-9);
  EXPECT_NEAR(q[2], expect.y(), 1e-9);
  EXPECT_NEAR(q[3], expect.z(), 1e-9);
  EXPECT_NEAR(q.norm(), 1.0, 1e-15);
  // Body-frame rates: the result rotates body vectors into the start frame.
  EXPECT_TRUE(quat_to_matrix(q).isApprox(expect.toRotationMatrix(), 1e-9));
}

TEST(Rk4n, VaryingAxisFourthOrder) {
  // Sampled rates, linearly interpolated at the half step: halving the step reduces the error
  // about 4x (second order in the sampling of w, fourth order in the integration itself).
  auto run = [](int n) {
    std::vector<Eigen::Vector3d> w(n + 1);
    std::vector<double> t(n + 1);
    for (int i = 0; i <= n; ++i) {
      t[i] = 2.0 * i / n;
      w[i] = Eigen::Vector3d(std::sin(3 * t[i]), std::cos(2 * t[i]), 0.5 * t[i]);
    }
    return integrate_rk4n(w, t);
  };
  const Quat4 ref = run(4000);
  const double e1 = (run(50) - ref).norm();
  const double e2 = (run(100) - ref).norm();
  EXPECT_GT(e1 / e2, 3.5);
  EXPECT_LT(e2, 2e-4);
}

// The Jacobian of f(q) = R(q)^T u by central differences (of the polynomial of eq. 2.13, not
// renormalised), as the callback of integrate_rk4n_with_gradient wants it.
auto finite_difference_df_dq(const Eigen::Vector3d& u) {
  return [u](const Quat4& q) {
    const auto f = [&u](const Quat4& p) { return Eigen::Vector3d(quat_to_matrix(p).transpose() * u); };
    Eigen::Matrix<double, 3, 4> J;
    const double h = 1e-7;
    for (int k = 0; k < 4; ++k) {
      Quat4 qp = q, qm = q;
      qp[k] += h;
      qm[k] -= h;
      J.col(k) = (f(qp) - f(qm)) / (2 * h);
    }
    return J;
  };
}

TEST(Rk4n, ReverseGradientMatchesFiniteDifferences) {
  const int n = 60;
  std::vector<Eigen::Vector3d> w(n);
  std::vector<double> t(n);
  for (int i = 0; i < n; ++i) {
    t[i] = 0.01 * i + 0.0003 * std::sin(i);  // jittered steps
    w[i] = Eigen::Vector3d(1.5 * std::sin(0.1 * i), 2.0 * std::cos(0.07 * i), -1.0 + 0.03 * i);
  }
  const Eigen::Vector3d u(0.2, -0.3, 0.93);
  auto f = [&](const Quat4& q) { return Eigen::Vector3d(quat_to_matrix(q).transpose() * u); };
  const auto df_dq = finite_difference_df_dq(u);
  std::vector<Quat4> buf;
  Rk4nGradient g;
  integrate_rk4n_with_gradient(std::span<const Eigen::Vector3d>(w), t, df_dq, buf, g);
  EXPECT_TRUE(g.q_end.isApprox(integrate_rk4n(w, t), 1e-15));
  for (int i : {0, 1, 17, n / 2, n - 2, n - 1}) {
    for (int a = 0; a < 3; ++a) {
      auto wp = w, wm = w;
      const double h = 1e-6;
      wp[i][a] += h;
      wm[i][a] -= h;
      const Eigen::Vector3d num = (f(integrate_rk4n(wp, t)) - f(integrate_rk4n(wm, t))) / (2 * h);
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(g.df_dw[i](r, a), num[r], 1e-7) << "sample " << i << " axis " << a << " row " << r;
      }
    }
  }
}

// The first-order rate derivatives that steer the gyro solve's first pass are within about h w of
// the exact ones, relative to the largest: 1.4e-3 at 100 Hz and up to 2 rad/s, ten times less at
// 1 kHz over the same motion.
TEST(Rk4n, FirstOrderGradientIsCloseToTheExactOne) {
  const Eigen::Vector3d u(0.2, -0.3, 0.93);
  const auto df_dq = finite_difference_df_dq(u);
  double worst[2] = {0.0, 0.0};
  for (int k = 0; k < 2; ++k) {
    const double rate_hz = k == 0 ? 100.0 : 1000.0;
    const int n = static_cast<int>(2.0 * rate_hz);  // a 2 s motion
    std::vector<Eigen::Vector3d> w(static_cast<std::size_t>(n));
    std::vector<double> t(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      t[static_cast<std::size_t>(i)] = i / rate_hz;
      const double s = t[static_cast<std::size_t>(i)];
      w[static_cast<std::size_t>(i)] =
          Eigen::Vector3d(1.5 * std::sin(3 * s), 2.0 * std::cos(2 * s), -1.0 + 0.3 * s);
    }
    std::vector<Quat4> q;
    Rk4nGradient exact;
    integrate_rk4n_with_gradient(std::span<const Eigen::Vector3d>(w), t, df_dq, q, exact);
    std::vector<Eigen::Matrix3d> approx;
    rate_gradient_first_order(q, t, u, approx);
    ASSERT_EQ(approx.size(), exact.df_dw.size());
    double largest = 0.0;
    for (const auto& G : exact.df_dw) largest = std::max(largest, G.cwiseAbs().maxCoeff());
    for (std::size_t i = 0; i < approx.size(); ++i) {
      worst[k] = std::max(worst[k], (approx[i] - exact.df_dw[i]).cwiseAbs().maxCoeff() / largest);
    }
  }
  EXPECT_LT(worst[0], 5e-3);
  EXPECT_LT(worst[1], worst[0] / 5.0) << "100 Hz: " << worst[0] << ", 1 kHz: " << worst[1];
}

}  // namespace
}  // namespace imucal::calib
