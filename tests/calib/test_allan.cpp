// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "calib/allan.hpp"

namespace imucal::calib {
namespace {

std::vector<Eigen::Vector3d> noise(std::size_t n, double rate_hz, const Eigen::Vector3d& density,
                                   const Eigen::Vector3d& walk, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  const double dt = 1.0 / rate_hz;
  std::vector<Eigen::Vector3d> out(n);
  Eigen::Vector3d bias = Eigen::Vector3d::Constant(1000.0);  // a large constant offset
  for (auto& v : out) {
    for (int a = 0; a < 3; ++a) {
      bias[a] += walk[a] * std::sqrt(dt) * g(rng);
      v[a] = bias[a] + density[a] / std::sqrt(dt) * g(rng);
    }
  }
  return out;
}

TEST(Allan, WhiteNoiseDensity) {
  const Eigen::Vector3d density(3.92e-3, 8.73e-5, 1e-2);
  const auto x = noise(60000, 100.0, density, Eigen::Vector3d::Zero(), 1);
  auto curve = allan_deviation(x, 100.0);
  ASSERT_TRUE(curve.ok());
  ASSERT_GE(curve->tau_s.size(), 10u);
  EXPECT_DOUBLE_EQ(curve->tau_s[0], 0.01);
  EXPECT_DOUBLE_EQ(curve->tau_s[1], 0.02);
  for (int a = 0; a < 3; ++a) {
    // adev(tau) = N / sqrt(tau) for white noise.
    EXPECT_NEAR(curve->adev[0][a], density[a] / std::sqrt(0.01), 0.02 * density[a] / std::sqrt(0.01));
    const AllanNoise fit = fit_allan_noise(*curve, a);
    EXPECT_NEAR(fit.noise_density, density[a], 0.05 * density[a]) << a;
    EXPECT_TRUE(fit.random_walk_is_bound);
    EXPECT_TRUE(fit.bias_instability_is_bound || fit.bias_instability_tau_s > 10.0);
  }
  // White noise falls all the way: the whole still span is used as T_init.
  EXPECT_DOUBLE_EQ(choose_init_period_s(*curve, 600.0), 600.0);
}

TEST(Allan, RandomWalkIsRecovered) {
  const Eigen::Vector3d density = Eigen::Vector3d::Constant(1e-3);
  const Eigen::Vector3d walk = Eigen::Vector3d::Constant(2e-3);
  const auto x = noise(400000, 100.0, density, walk, 2);  // 4000 s
  auto curve = allan_deviation(x, 100.0);
  ASSERT_TRUE(curve.ok());
  for (int a = 0; a < 3; ++a) {
    const AllanNoise fit = fit_allan_noise(*curve, a);
    EXPECT_NEAR(fit.noise_density, 1e-3, 1e-4);
    EXPECT_FALSE(fit.random_walk_is_bound);
    EXPECT_NEAR(fit.random_walk, 2e-3, 0.6e-3) << a;
    EXPECT_FALSE(fit.bias_instability_is_bound);
    // The crossing of the two lines is at tau = 3 N^2 / K^2 = 0.75 s.
    EXPECT_GT(fit.bias_instability_tau_s, 0.2);
    EXPECT_LT(fit.bias_instability_tau_s, 3.0);
  }
  // The curve flattens near 1 s: T_init is chosen there, far below the span.
  const double t_init = choose_init_period_s(*curve, 4000.0);
  EXPECT_GE(t_init, 1.0);
  EXPECT_LT(t_init, 10.0);
}

TEST(Allan, ShortInputIsAnError) {
  std::vector<Eigen::Vector3d> x(5, Eigen::Vector3d::Zero());
  auto curve = allan_deviation(x, 100.0);
  ASSERT_FALSE(curve.ok());
  EXPECT_EQ(curve.error().code, Errc::kInsufficientData);
  std::vector<Eigen::Vector3d> y(100, Eigen::Vector3d::Zero());
  EXPECT_FALSE(allan_deviation(y, 0.0).ok());
}

}  // namespace
}  // namespace imucal::calib
