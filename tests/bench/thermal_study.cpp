// SPDX-License-Identifier: BSD-3-Clause
// The thermal calibration against the virtual MPU-6000's truth over many seeds: still warm-ups
// from 20 towards 60 deg C with cubic bias-temperature truths (docs/benchmarks.md, "Thermal
// calibration"). Prints the RMS of error/sigma of the fitted coefficients, the orders chosen, and
// the residual gyro bias over the range as a fraction of the uncompensated drift, for imucal's fit
// and for PX4's (a cubic by plain least squares on every sample, no order choice, no sigmas).
//
//   thermal_study [SEEDS [DURATION_S [RATE_HZ]]]     (default 20 seeds, 3600 s, 50 Hz)

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "calib/thermal_calibration.hpp"
#include "sim/imu_error_model.hpp"
#include "tests/support/polynomial.hpp"

namespace {

using namespace imucal;

using test::shift_poly;

double poly_change(const Eigen::VectorXd& c, double dT) {
  double v = 0.0, p = 1.0;
  for (Eigen::Index j = 1; j < c.size(); ++j) {
    p *= dT;
    v += c[j] * p;
  }
  return v;
}

/// RMS over the range of (fitted change - true change), and the true change's max - min.
void residual_and_drift(const Eigen::VectorXd& fit, const Eigen::Vector4d& truth, double ref, double lo,
                        double hi, double* residual, double* drift) {
  double sum = 0.0, mn = 0.0, mx = 0.0;
  const int n = 101;
  for (int i = 0; i < n; ++i) {
    const double T = lo + (hi - lo) * i / (n - 1);
    const double t = poly_change(truth, T - ref);
    const double e = poly_change(fit, T - ref) - t;
    sum += e * e / n;
    mn = i == 0 ? t : std::min(mn, t);
    mx = i == 0 ? t : std::max(mx, t);
  }
  *residual = std::sqrt(sum);
  *drift = mx - mn;
}

}  // namespace

int main(int argc, char** argv) {
  const int seeds = argc > 1 ? std::atoi(argv[1]) : 20;
  const double duration_s = argc > 2 ? std::atof(argv[2]) : 3600.0;
  const double rate_hz = argc > 3 ? std::atof(argv[3]) : 50.0;
  constexpr int kTruthOrder = 3;
  double z2_gyro = 0.0, z2_accel = 0.0;
  int nz_gyro = 0, nz_accel = 0, order_hits = 0, axes = 0, lower_order = 0;
  std::vector<double> ratio_ours, ratio_px4;
  std::printf("seed  orders(gx gy gz ax ay az)  gyro residual/drift %% (imucal | PX4)\n");
  for (int seed = 1; seed <= seeds; ++seed) {
    sim::ImuModelParams p = sim::ImuModelParams::draw(static_cast<std::uint64_t>(seed));
    p.draw_temperature_coefficients(static_cast<std::uint64_t>(seed), kTruthOrder);
    p.temp_start_c = 20.0;
    p.temp_final_c = 60.0;
    p.temp_time_constant_s = 900.0;
    sim::ImuSimulator imu(p, static_cast<std::uint64_t>(seed));
    const sim::RigState still;
    const double dt = 1.0 / rate_hz;
    const auto n = static_cast<std::size_t>(duration_s * rate_hz);
    std::vector<ImuSample> samples;
    samples.reserve(n);
    for (std::size_t k = 0; k < n; ++k)
      samples.push_back(imu.sample(s_to_ns(static_cast<double>(k) * dt), still, dt));
    calib::ThermalOptions opt;
    opt.accel.scale.setConstant(p.accel_mps2_per_count());
    opt.gyro.scale.setConstant(p.gyro_radps_per_count());
    opt.temperature_scale = 1.0 / sim::kMpu6000TempLsbPerDegC;
    opt.temperature_offset = sim::kMpu6000TempOffsetDegC;
    auto r = calib::calibrate_thermal(samples, opt);
    if (!r.ok() || !r->determined) {
      std::printf("seed %d: %s\n", seed, r.ok() ? r->reason.c_str() : r.error().message.c_str());
      return 1;
    }
    // PX4's way on the same samples: every sample, a cubic by plain least squares.
    std::vector<double> temps(n);
    std::vector<std::vector<double>> gyro(3, std::vector<double>(n));
    for (std::size_t k = 0; k < n; ++k) {
      temps[k] = opt.temperature_scale * samples[k].temperature + opt.temperature_offset;
      const Eigen::Vector3d g = opt.gyro.to_si(samples[k].gyro);
      for (int a = 0; a < 3; ++a) gyro[a][k] = g[a];
    }
    std::printf("%4d  ", seed);
    for (int a = 0; a < 6; ++a) std::printf("%d ", a < 3 ? r->gyro[a].order : r->accel[a - 3].order);
    std::printf("      ");
    for (int a = 0; a < 6; ++a) {
      const bool is_gyro = a < 3;
      const calib::ThermalAxisFit& fit = is_gyro ? r->gyro[a] : r->accel[a - 3];
      const Eigen::Vector4d truth = shift_poly(
          is_gyro ? p.gyro_bias_temp_poly(a) : p.accel_bias_temp_poly(a - 3), p.temp_ref_c(), r->reference_c);
      ++axes;
      if (fit.order == kTruthOrder) ++order_hits;
      if (fit.order < kTruthOrder) {
        ++lower_order;
      } else {
        for (int j = 1; j <= fit.order; ++j) {
          const double z = (fit.coeffs[j] - truth[j]) / std::sqrt(fit.covariance(j, j));
          (is_gyro ? z2_gyro : z2_accel) += z * z;
          ++(is_gyro ? nz_gyro : nz_accel);
        }
      }
      if (!is_gyro) continue;
      double res = 0.0, drift = 0.0, res_px4 = 0.0, drift_px4 = 0.0;
      residual_and_drift(fit.coeffs, truth, r->reference_c, r->temp_min_c, r->temp_max_c, &res, &drift);
      const Eigen::VectorXd px4 = calib::fit_polynomial_plain(temps, gyro[a], r->reference_c, 3);
      residual_and_drift(px4, truth, r->reference_c, r->temp_min_c, r->temp_max_c, &res_px4, &drift_px4);
      ratio_ours.push_back(res / drift);
      ratio_px4.push_back(res_px4 / drift_px4);
      std::printf("%5.2f | %5.2f  ", 100.0 * res / drift, 100.0 * res_px4 / drift_px4);
    }
    std::printf("\n");
  }
  auto mean = [](const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return s / static_cast<double>(v.size());
  };
  auto max = [](const std::vector<double>& v) { return *std::max_element(v.begin(), v.end()); };
  std::printf("\n%d seeds, %.0f s at %.0f Hz, 20 -> 60 deg C (time constant 900 s), cubic truth\n", seeds,
              duration_s, rate_hz);
  std::printf("orders: %d of %d axes got the truth's order 3 (%d lower)\n", order_hits, axes, lower_order);
  std::printf("RMS of error/sigma of c1..c_order: gyro %.2f (%d coefficients), accel %.2f (%d), all %.2f\n",
              std::sqrt(z2_gyro / std::max(1, nz_gyro)), nz_gyro, std::sqrt(z2_accel / std::max(1, nz_accel)),
              nz_accel, std::sqrt((z2_gyro + z2_accel) / std::max(1, nz_gyro + nz_accel)));
  std::printf(
      "gyro residual over the range / uncompensated drift: imucal mean %.2f %% max %.2f %%; PX4 cubic "
      "mean %.2f %% max %.2f %% (no sigmas)\n",
      100.0 * mean(ratio_ours), 100.0 * max(ratio_ours), 100.0 * mean(ratio_px4), 100.0 * max(ratio_px4));
  return 0;
}
