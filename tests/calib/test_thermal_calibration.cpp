// SPDX-License-Identifier: BSD-3-Clause
// The thermal calibration (calib/thermal_calibration.hpp) on simulated still warm-ups of the
// virtual MPU-6000 with non-linear bias-temperature truths: coefficients within their sigmas, the
// order the truth has chosen on most seeds, "not determined" for a flat temperature, refusals.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "calib/thermal_calibration.hpp"
#include "core/calibration_record.hpp"
#include "sim/imu_error_model.hpp"
#include "tests/support/polynomial.hpp"

namespace imucal {
namespace {

struct WarmUp {
  sim::ImuModelParams params;
  std::vector<ImuSample> samples;
  calib::ThermalOptions options;
};

/// A still rig (level, on a table) warming from 20 to 60 deg C with a time constant of 900 s, in
/// raw counts as the chip gives them.
WarmUp simulate_warm_up(std::uint64_t seed, int order, double duration_s = 3600.0, double rate_hz = 50.0,
                        double start_c = 20.0, double final_c = 60.0) {
  WarmUp w;
  w.params = sim::ImuModelParams::draw(seed);
  w.params.draw_temperature_coefficients(seed, order);
  w.params.temp_start_c = start_c;
  w.params.temp_final_c = final_c;
  w.params.temp_time_constant_s = 900.0;
  sim::ImuSimulator imu(w.params, seed);
  const sim::RigState still;
  const double dt = 1.0 / rate_hz;
  const auto n = static_cast<std::size_t>(duration_s * rate_hz);
  w.samples.reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    w.samples.push_back(imu.sample(s_to_ns(static_cast<double>(k) * dt), still, dt));
  }
  w.options.accel.scale.setConstant(w.params.accel_mps2_per_count());
  w.options.gyro.scale.setConstant(w.params.gyro_radps_per_count());
  w.options.temperature_scale = 1.0 / sim::kMpu6000TempLsbPerDegC;
  w.options.temperature_offset = sim::kMpu6000TempOffsetDegC;
  return w;
}

using test::shift_poly;

/// error / sigma of every fitted coefficient c_1..c_order against the truth (higher truth terms
/// than fitted are not compared); empty when the fit has a lower order than the truth.
std::vector<double> normalised_errors(const calib::ThermalAxisFit& fit,
                                      const Eigen::Vector4d& truth_about_ref, int truth_order) {
  std::vector<double> z;
  if (!fit.determined || fit.order < truth_order) return z;
  for (int j = 1; j <= fit.order; ++j) {
    z.push_back((fit.coeffs[j] - truth_about_ref[j]) / std::sqrt(fit.covariance(j, j)));
  }
  return z;
}

TEST(ThermalCalibration, CubicTruthWithinSigmasAndOrderChosenOnMostSeeds) {
  int order_right = 0, axes = 0;
  double sum_z2 = 0.0;
  int nz = 0;
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    const WarmUp w = simulate_warm_up(seed, 3);
    auto r = calib::calibrate_thermal(w.samples, w.options);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_TRUE(r->determined) << r->reason;
    EXPECT_NEAR(r->temp_min_c, 20.0, 1.0);
    EXPECT_NEAR(r->temp_max_c, 58.9, 1.0);
    EXPECT_DOUBLE_EQ(r->reference_c, 0.5 * (r->temp_min_c + r->temp_max_c));
    EXPECT_TRUE(r->temperature_monotonic);
    for (int a = 0; a < 3; ++a) {
      for (const bool gyro : {true, false}) {
        const calib::ThermalAxisFit& fit = gyro ? r->gyro[a] : r->accel[a];
        const Eigen::Vector4d truth =
            shift_poly(gyro ? w.params.gyro_bias_temp_poly(a) : w.params.accel_bias_temp_poly(a),
                       w.params.temp_ref_c(), r->reference_c);
        ASSERT_TRUE(fit.determined);
        ++axes;
        if (fit.order == 3) ++order_right;
        for (double z : normalised_errors(fit, truth, 3)) {
          EXPECT_LT(std::abs(z), 4.0) << "seed " << seed << (gyro ? " gyro " : " accel ") << a;
          sum_z2 += z * z;
          ++nz;
        }
        EXPECT_GT(fit.uncompensated_drift, 0.0);
        EXPECT_GT(fit.model_sigma_rms, 0.0);
        EXPECT_LT(fit.model_sigma_rms, 0.1 * fit.uncompensated_drift);
      }
    }
  }
  EXPECT_GE(order_right, axes * 2 / 3) << order_right << " of " << axes << " axes got order 3";
  ASSERT_GT(nz, 0);
  const double rms = std::sqrt(sum_z2 / nz);
  EXPECT_GT(rms, 0.4);
  EXPECT_LT(rms, 2.0);
}

TEST(ThermalCalibration, QuadraticTruthChosenOverCubicOnMostSeeds) {
  int order_right = 0, axes = 0;
  for (std::uint64_t seed = 11; seed <= 13; ++seed) {
    const WarmUp w = simulate_warm_up(seed, 2);
    auto r = calib::calibrate_thermal(w.samples, w.options);
    ASSERT_TRUE(r.ok()) << r.error().message;
    for (int a = 0; a < 3; ++a) {
      for (const calib::ThermalAxisFit* fit : {&r->gyro[a], &r->accel[a]}) {
        ++axes;
        if (fit->order == 2) ++order_right;
      }
    }
  }
  EXPECT_GE(order_right, axes * 2 / 3) << order_right << " of " << axes << " axes got order 2";
}

TEST(ThermalCalibration, LinearDefaultIsTheEarlierModel) {
  sim::ImuModelParams p;
  p.gyro_bias_temp_coeff = Eigen::Vector3d(1e-3, -2e-3, 3e-4);
  p.accel_bias_temp_coeff = Eigen::Vector3d(1e-2, 0.0, -5e-3);
  for (double T : {-10.0, 30.0, 36.0, 71.3}) {
    const double dT = T - p.temp_start_c;
    EXPECT_EQ(p.gyro_bias_temp(T), Eigen::Vector3d(dT * p.gyro_bias_temp_coeff));
    EXPECT_EQ(p.accel_bias_temp(T), Eigen::Vector3d(dT * p.accel_bias_temp_coeff));
  }
}

TEST(ThermalCalibration, FlatTemperatureIsNotDetermined) {
  const WarmUp w = simulate_warm_up(3, 2, 900.0, 50.0, 35.0, 35.5);
  auto r = calib::calibrate_thermal(w.samples, w.options);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->determined);
  EXPECT_NE(r->reason.find("spans"), std::string::npos) << r->reason;
  for (const calib::ThermalAxisFit& a : r->gyro) {
    EXPECT_FALSE(a.determined);
    EXPECT_EQ(a.coeffs.size(), 0);
    EXPECT_FALSE(a.reason.empty());
    EXPECT_TRUE(std::isnan(a.change(40.0, r->reference_c)));
  }
}

TEST(ThermalCalibration, RefusesWithoutTemperatureOrWhenTheRigMoves) {
  WarmUp w = simulate_warm_up(5, 1, 600.0, 50.0, 20.0, 40.0);
  std::vector<ImuSample> no_temp = w.samples;
  for (ImuSample& s : no_temp) s.temperature = std::numeric_limits<double>::quiet_NaN();
  auto r = calib::calibrate_thermal(no_temp, w.options);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInsufficientData);
  EXPECT_NE(r.error().message.find("temperature"), std::string::npos);

  // Tilted for 20 s in the middle: about 0.3 g on x.
  for (std::size_t k = 15000; k < 16000; ++k) w.samples[k].accel.x() += 0.3 * 8192.0;
  r = calib::calibrate_thermal(w.samples, w.options);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInsufficientData);
  EXPECT_NE(r.error().message.find("moved"), std::string::npos) << r.error().message;
}

// Before: one sample at 1e308 was fitted like any other (a reference of 7e61 deg C, exit 0),
// which `calibrate static --thermal` then applied.
TEST(ThermalCalibration, RefusesATemperatureNoDieReaches) {
  WarmUp w = simulate_warm_up(5, 1, 600.0, 50.0, 20.0, 40.0);
  for (const double raw : {1e308, -1e308, 1e6}) {
    std::vector<ImuSample> hostile = w.samples;
    hostile[100].temperature = raw;
    auto r = calib::calibrate_thermal(hostile, w.options);
    ASSERT_FALSE(r.ok()) << raw;
    EXPECT_EQ(r.error().code, Errc::kCorrupt);
    EXPECT_NE(r.error().message.find("the sample at t_ns " + std::to_string(hostile[100].t_ns) +
                                     " gives a die temperature of"),
              std::string::npos)
        << r.error().message;
    EXPECT_NE(r.error().message.find("which no die reaches"), std::string::npos) << r.error().message;
  }
  EXPECT_TRUE(calib::calibrate_thermal(w.samples, w.options).ok());
}

TEST(ThermalCalibration, StepProfileHoldsThenWarms) {
  sim::ImuModelParams p;
  p.temp_profile = sim::TemperatureProfile::kStep;
  p.temp_start_c = 20.0;
  p.temp_final_c = 50.0;
  p.temp_step_time_s = 100.0;
  p.temp_time_constant_s = 300.0;
  EXPECT_EQ(p.temperature_c(50.0), 20.0);
  EXPECT_EQ(p.temperature_c(100.0), 20.0);
  EXPECT_NEAR(p.temperature_c(400.0), 50.0 - 30.0 * std::exp(-1.0), 1e-12);
  p.temp_profile = sim::TemperatureProfile::kSoak;
  p.temp_ramp_s = 200.0;
  EXPECT_NEAR(p.temperature_c(100.0), 35.0, 1e-12);
  EXPECT_EQ(p.temperature_c(500.0), 50.0);
  auto parsed = sim::parse_temperature_profile("soak");
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(*parsed, sim::TemperatureProfile::kSoak);
  EXPECT_FALSE(sim::parse_temperature_profile("ramp").ok());
}

TEST(ThermalCalibration, PlainPolynomialFitRecoversAnExactCubic) {
  std::vector<double> T, y;
  for (int k = 0; k <= 40; ++k) {
    T.push_back(20.0 + k);
    const double d = T.back() - 30.0;
    y.push_back(1.0 + 0.5 * d - 0.01 * d * d + 2e-4 * d * d * d);
  }
  const Eigen::VectorXd c = calib::fit_polynomial_plain(T, y, 30.0, 3);
  ASSERT_EQ(c.size(), 4);
  EXPECT_NEAR(c[0], 1.0, 1e-9);
  EXPECT_NEAR(c[1], 0.5, 1e-9);
  EXPECT_NEAR(c[2], -0.01, 1e-9);
  EXPECT_NEAR(c[3], 2e-4, 1e-9);
}

TEST(ThermalCalibration, ScaleAgainstTemperatureIsTheWeightedLineThroughTheStaticCalibrations) {
  // Three static calibrations on the line s(T) = 1.01 (1 + 2e-4 (T - 40)) for every axis but the
  // accelerometer's z, whose middle point has no sigma (not determined).
  const auto point = [](double t, double sigma) {
    calib::ThermalScalePoint p;
    p.source = "poses at " + std::to_string(t);
    p.temperature_c = t;
    const double s = 1.01 * (1.0 + 2e-4 * (t - 40.0));
    p.gyro = p.accel = Eigen::Vector3d::Constant(s);
    p.gyro_sigma = p.accel_sigma = Eigen::Vector3d::Constant(sigma);
    return p;
  };
  std::vector<calib::ThermalScalePoint> pts = {point(20.0, 1e-4), point(40.0, 2e-4), point(60.0, 1e-4)};
  pts[1].accel_sigma.z() = std::numeric_limits<double>::quiet_NaN();
  const auto fit = calib::fit_scale_against_temperature(pts, 40.0, 3.0);
  ASSERT_TRUE(fit.determined) << fit.reason;
  for (int a = 0; a < 3; ++a) {
    // The model's scale rises by 2e-4 per K: the sensitivity (its inverse) falls by as much.
    EXPECT_NEAR(fit.model.gyro_k[a], -2e-4, 1e-12);
    // k = -b / a: sigma_b = sigma / (20 sqrt 2) with the middle point at x = 0; a's own sigma
    // adds b^2 var_a / a^4, a share of 4e-8 of that.
    EXPECT_NEAR(fit.model.gyro_sigma[a], 1e-4 / (20.0 * std::sqrt(2.0)) / 1.01, 1e-8);
    EXPECT_NEAR(fit.gyro_chi2_dof[a], 0.0, 1e-12);  // the points lie on the line
  }
  EXPECT_TRUE(std::isnan(fit.model.accel_k.z()));
  EXPECT_TRUE(std::isnan(fit.model.accel_sigma.z()));
  EXPECT_NEAR(fit.model.accel_k.x(), -2e-4, 1e-12);
  EXPECT_EQ(fit.model.temperatures_c, (std::vector<double>{20.0, 40.0, 60.0}));

  // Too few points, or too close in temperature: not determined, with the reason.
  const auto one = calib::fit_scale_against_temperature({point(20.0, 1e-4)}, 40.0, 3.0);
  EXPECT_FALSE(one.determined);
  EXPECT_NE(one.reason.find("two or more"), std::string::npos) << one.reason;
  const auto close = calib::fit_scale_against_temperature({point(20.0, 1e-4), point(21.0, 1e-4)}, 40.0, 3.0);
  EXPECT_FALSE(close.determined);
  EXPECT_NE(close.reason.find("span 1.00 deg C"), std::string::npos) << close.reason;

  // The model carries it; the record's JSON form keeps it.
  calib::ThermalResult r;
  r.determined = true;
  r.reference_c = 40.0;
  r.scale = fit;
  const ThermalModel m = calib::thermal_model(r);
  ASSERT_TRUE(m.scale_model);
  auto back = thermal_model_from_json(thermal_model_json(m));
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_TRUE(back->scale_model);
  EXPECT_DOUBLE_EQ(back->scale_model->gyro_k.y(), m.scale_model->gyro_k.y());
  EXPECT_TRUE(std::isnan(back->scale_model->accel_k.z()));
  r.scale = one;
  EXPECT_EQ(calib::thermal_model(r).scale, "not determined: " + one.reason);
}

}  // namespace
}  // namespace imucal
