// SPDX-License-Identifier: BSD-3-Clause
// The six-orientation g-sensitivity experiment on synthetic holds: known G, bias walk and noise.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "calib/gsens_calibration.hpp"

namespace imucal::calib {
namespace {

struct Synth {
  std::vector<ImuSample> samples;
  std::vector<Eigen::Vector3d> bias;  // the gyro bias at each sample
  Eigen::Matrix3d G;
};

struct GsensSynthConfig {
  unsigned seed = 1;
  double rate_hz = 100.0;
  double hold_s = 30.0;
  double move_s = 3.0;
  double gyro_noise_density = 8.73e-5;  // rad/s / sqrt(Hz) (MPU-6000)
  double gyro_random_walk = 2e-5;       // rad/s * sqrt(Hz)
  double accel_noise_density = 0.0039;
  /// Faces up, in order; consecutive faces must be perpendicular.
  std::vector<Eigen::Vector3d> faces = {Eigen::Vector3d::UnitZ(),  Eigen::Vector3d::UnitX(),
                                        Eigen::Vector3d::UnitY(),  -Eigen::Vector3d::UnitZ(),
                                        -Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY()};
  /// A turn about the horizontal inside one hold (index, rad/s): a rig that is not held still.
  int turning_hold = -1;
  double turn_rate = 0.0;
};

/// SI samples: holds with the gravity reaction along each face, smooth quarter turns between them;
/// gyro = bias walk + G a + rotation + white noise, accelerometer = a + white noise.
Synth make_holds(const GsensSynthConfig& cfg) {
  std::mt19937 rng(cfg.seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  auto randn3 = [&] { return Eigen::Vector3d(nd(rng), nd(rng), nd(rng)); };
  Synth s;
  s.G = 2e-4 * Eigen::Matrix3d::NullaryExpr([&](Eigen::Index, Eigen::Index) { return nd(rng); });
  const double dt = 1.0 / cfg.rate_hz, g = kStandardGravity;
  Eigen::Vector3d bias = 0.02 * randn3();
  const double sd_w = cfg.gyro_noise_density * std::sqrt(cfg.rate_hz);
  const double sd_a = cfg.accel_noise_density * std::sqrt(cfg.rate_hz);
  TimeNs t_ns = 1'000'000'000;
  auto emit = [&](const Eigen::Vector3d& up, const Eigen::Vector3d& w) {
    ImuSample smp;
    smp.t_ns = t_ns;
    const Eigen::Vector3d a = g * up;
    smp.accel = a + sd_a * randn3();
    smp.gyro = bias + s.G * a + w + sd_w * randn3();
    s.samples.push_back(smp);
    s.bias.push_back(bias);
    bias += cfg.gyro_random_walk * std::sqrt(dt) * randn3();
    t_ns += static_cast<TimeNs>(std::llround(dt * 1e9));
  };
  const auto hold_n = static_cast<int>(cfg.hold_s * cfg.rate_hz);
  const auto move_n = static_cast<int>(cfg.move_s * cfg.rate_hz);
  for (std::size_t f = 0; f < cfg.faces.size(); ++f) {
    const Eigen::Vector3d u = cfg.faces[f];
    const bool turning = static_cast<int>(f) == cfg.turning_hold;
    const Eigen::Vector3d axis = u.unitOrthogonal();
    for (int i = 0; i < hold_n; ++i) {
      const double angle = turning ? cfg.turn_rate * i * dt : 0.0;
      emit(Eigen::AngleAxisd(angle, axis) * u,
           turning ? Eigen::Vector3d(cfg.turn_rate * axis) : Eigen::Vector3d::Zero());
    }
    if (f + 1 == cfg.faces.size()) break;
    const Eigen::Vector3d start = turning ? Eigen::AngleAxisd(cfg.turn_rate * hold_n * dt, axis) * u : u;
    const Eigen::Vector3d v = cfg.faces[f + 1];
    const Eigen::Vector3d turn_axis = start.cross(v).normalized();
    const double total = std::acos(std::clamp(start.dot(v), -1.0, 1.0));
    for (int i = 0; i < move_n; ++i) {
      const double x = M_PI * i / move_n;
      const double angle = total * 0.5 * (1.0 - std::cos(x));
      const double rate = total * 0.5 * std::sin(x) * M_PI / cfg.move_s;
      emit(Eigen::AngleAxisd(angle, turn_axis) * start, rate * turn_axis);
    }
  }
  return s;
}

GSensitivityOptions si_options() {
  GSensitivityOptions opt;
  opt.gravity_mps2 = kStandardGravity;
  return opt;
}

/// The truth bias at the time the result's b_g refers to.
Eigen::Vector3d bias_at(const Synth& s, TimeNs t_ns) {
  std::size_t i = 0;
  while (i + 1 < s.samples.size() && s.samples[i].t_ns < t_ns) ++i;
  return s.bias[i];
}

TEST(GSensCalibration, RecoversGWithinItsSigmas) {
  GsensSynthConfig cfg;
  cfg.seed = 7;
  const Synth s = make_holds(cfg);
  auto res = calibrate_gsens(s.samples, si_options());
  ASSERT_TRUE(res.ok()) << res.error().message;
  ASSERT_EQ(res->holds.size(), 6u);
  for (const auto& h : res->holds) {
    EXPECT_FALSE(h.face.empty());
    EXPECT_GT(h.samples, 2700u);  // 30 s less one window at each end
    EXPECT_LT(h.tilt_deg, 0.5);
  }
  EXPECT_EQ(res->holds[0].face, "+z");
  EXPECT_EQ(res->holds[3].face, "-z");
  EXPECT_EQ(res->dof.dof(), 6);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_GT(res->G_sigma(r, c), 1e-6);
      EXPECT_LT(res->G_sigma(r, c), 3e-5);  // Krebs's 90 s motion: 1e-4
      EXPECT_NEAR(res->G(r, c), s.G(r, c), 3.5 * res->G_sigma(r, c)) << r << "," << c;
    }
  }
  const Eigen::Vector3d b_true = bias_at(s, res->b_g_t_ns);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(res->b_g[i], b_true[i], 3.5 * res->b_g_sigma[i]);
  // The noise read from the holds is the simulated one.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(res->gyro_noise_density[i], cfg.gyro_noise_density, 0.15 * cfg.gyro_noise_density);
    EXPECT_LT(res->gyro_random_walk[i], 3.0 * cfg.gyro_random_walk);
  }
  EXPECT_LT(res->residual_rms_radps, 5e-4);
  EXPECT_TRUE(res->warnings.empty()) << res->warnings.front();
}

TEST(GSensCalibration, SigmasAreHonestOverSeeds) {
  double sum_sq = 0.0;
  int count = 0;
  for (unsigned seed = 100; seed < 130; ++seed) {
    GsensSynthConfig cfg;
    cfg.seed = seed;
    const Synth s = make_holds(cfg);
    auto res = calibrate_gsens(s.samples, si_options());
    ASSERT_TRUE(res.ok()) << res.error().message;
    for (int e = 0; e < 9; ++e) {
      const double z = (res->G(e / 3, e % 3) - s.G(e / 3, e % 3)) / res->G_sigma(e / 3, e % 3);
      sum_sq += z * z;
      ++count;
    }
  }
  const double rms = std::sqrt(sum_sq / count);
  std::printf("RMS of (G - truth) / sigma over 30 seeds: %.3f\n", rms);
  EXPECT_GT(rms, 0.6);
  EXPECT_LT(rms, 1.6);
}

TEST(GSensCalibration, RefusesMissingFacesAndNamesThem) {
  GsensSynthConfig cfg;
  // -y is never up: +z, +x, +y, -z, -x, +z.
  cfg.faces = {Eigen::Vector3d::UnitZ(),  Eigen::Vector3d::UnitX(),  Eigen::Vector3d::UnitY(),
               -Eigen::Vector3d::UnitZ(), -Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ()};
  auto res = calibrate_gsens(make_holds(cfg).samples, si_options());
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.error().code, Errc::kInsufficientData);
  EXPECT_NE(res.error().message.find("none was found with -y up"), std::string::npos) << res.error().message;
  EXPECT_NE(res.error().message.find("+z 55 s"), std::string::npos) << res.error().message;

  // Holds too short to count: none at all.
  cfg = GsensSynthConfig{};
  cfg.hold_s = 8.0;
  res = calibrate_gsens(make_holds(cfg).samples, si_options());
  ASSERT_FALSE(res.ok());
  EXPECT_NE(res.error().message.find("+x, -x, +y, -y, +z, -z up (found: none"), std::string::npos)
      << res.error().message;
}

TEST(GSensCalibration, WarnsAboutARotatingHold) {
  GsensSynthConfig cfg;
  cfg.seed = 3;
  cfg.turning_hold = 2;
  cfg.turn_rate = 0.003;  // 5 deg over the 30 s hold
  auto res = calibrate_gsens(make_holds(cfg).samples, si_options());
  ASSERT_TRUE(res.ok()) << res.error().message;
  bool named = false;
  for (const auto& w : res->warnings)
    named = named || w.find("hold 3 (+y up) is rotating: its gravity direction turns") == 0;
  EXPECT_TRUE(named) << (res->warnings.empty() ? "no warnings" : res->warnings.front());
  EXPECT_GT(res->holds[2].tilt_deg, 4.0);
}

TEST(GSensCalibration, LatitudeRemovesTheVerticalEarthRate) {
  GsensSynthConfig cfg;
  cfg.seed = 11;
  const Synth s = make_holds(cfg);
  GSensitivityOptions opt = si_options();
  auto without = calibrate_gsens(s.samples, opt);
  opt.latitude_deg = 47.37;
  auto with = calibrate_gsens(s.samples, opt);
  ASSERT_TRUE(without.ok() && with.ok());
  const double e = 7.2921150e-5 * std::sin(47.37 * M_PI / 180.0) / kStandardGravity;
  EXPECT_NEAR(with->earth_rate_removed, e, 1e-12);
  EXPECT_TRUE((without->G - with->G).isApprox(e * Eigen::Matrix3d::Identity(), 1e-9));
}

TEST(GSensCalibration, RandomWalkCovarianceMatchesItsDefinition) {
  const std::vector<double> t0 = {0.0, 3.0, 6.5}, t1 = {2.0, 5.5, 8.0};
  const double t_ref = 4.0;
  const Eigen::MatrixXd C = random_walk_mean_covariance(t0, t1, t_ref);
  // E[W(s) W(t)] = min(|s - t_ref|, |t - t_ref|) on one side of t_ref, 0 across it, averaged on a grid.
  const int m = 2000;
  for (std::size_t k = 0; k < 3; ++k) {
    for (std::size_t j = 0; j < 3; ++j) {
      double sum = 0.0;
      for (int a = 0; a < m; ++a) {
        const double s = t0[k] + (a + 0.5) * (t1[k] - t0[k]) / m - t_ref;
        for (int b = 0; b < m; ++b) {
          const double t = t0[j] + (b + 0.5) * (t1[j] - t0[j]) / m - t_ref;
          if (s * t > 0.0) sum += std::min(std::abs(s), std::abs(t));
        }
      }
      EXPECT_NEAR(C(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(j)), sum / (double(m) * m), 1e-3)
          << k << "," << j;
    }
  }
}

TEST(GSensCalibration, OptionsAreChecked) {
  GSensitivityOptions opt;
  opt.gravity_mps2 = 1.0;
  EXPECT_FALSE(opt.validate().ok());
  opt = GSensitivityOptions{};
  opt.A_g.setZero();
  EXPECT_FALSE(opt.validate().ok());
  opt = GSensitivityOptions{};
  opt.min_hold_s = 0.5;
  EXPECT_FALSE(opt.validate().ok());
  EXPECT_TRUE(GSensitivityOptions{}.validate().ok());
}

}  // namespace
}  // namespace imucal::calib
