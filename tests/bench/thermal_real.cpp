// SPDX-License-Identifier: BSD-3-Clause
// The thermal calibration on a real recording given as CSV (t_s,gx,gy,gz,ax,ay,az,temp_c with a
// header line; rad/s, m/s^2, deg C; "nan" for a sensor the device does not have), beside PX4's
// thermal calibration as its Tools/process_sensor_caldata.py does it: a 31-sample median filter,
// the samples averaged in 2000 equal-width temperature bins, a cubic by plain least squares on
// the bins. Prints per axis the order imucal chose with its coefficients and sigmas, the drift,
// the RMS of the time bins' means about each curve, and the leave-one-out RMS (each time bin
// predicted by the curve fitted without it); writes the thermal YAML for `imucal report`.
// docs/benchmarks.md, "Thermal calibration", gives the recording and the figures.
//
//   thermal_real CSV OUT.yaml [BIN_S]      (BIN_S default 20)

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "app/results/thermal_results.hpp"
#include "calib/thermal_calibration.hpp"

namespace {

using namespace imucal;

std::vector<ImuSample> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::vector<ImuSample> out;
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    std::string f[8];
    for (auto& x : f) row >> x;
    if (f[7].empty()) continue;
    ImuSample s;
    s.t_ns = s_to_ns(std::strtod(f[0].c_str(), nullptr));
    for (int a = 0; a < 3; ++a) {
      s.gyro[a] = std::strtod(f[1 + a].c_str(), nullptr);  // strtod reads "nan"
      s.accel[a] = std::strtod(f[4 + a].c_str(), nullptr);
    }
    s.temperature = std::strtod(f[7].c_str(), nullptr);
    out.push_back(s);
  }
  return out;
}

/// PX4's way (Tools/process_sensor_caldata.py): median filter of 31 samples (zero-padded at the
/// ends, as scipy's medfilt), 2000 equal-width temperature bins, a cubic through their means.
Eigen::VectorXd px4_fit(const std::vector<double>& T, const std::vector<double>& y, double ref) {
  const int n = static_cast<int>(y.size()), half = 15;
  std::vector<double> filtered(n), window;
  for (int k = 0; k < n; ++k) {
    window.clear();
    for (int j = k - half; j <= k + half; ++j) window.push_back(j < 0 || j >= n ? 0.0 : y[j]);
    std::nth_element(window.begin(), window.begin() + half, window.end());
    filtered[k] = window[half];
  }
  const double lo = *std::min_element(T.begin(), T.end()), hi = *std::max_element(T.begin(), T.end());
  constexpr int kBins = 2000;
  std::vector<double> sum_t(kBins, 0.0), sum_y(kBins, 0.0), count(kBins, 0.0);
  for (int k = 0; k < n; ++k) {
    const int b = std::min(kBins - 1, static_cast<int>((T[k] - lo) / (hi - lo) * kBins));
    sum_t[b] += T[k];
    sum_y[b] += filtered[k];
    count[b] += 1.0;
  }
  std::vector<double> bt, by;
  for (int b = 0; b < kBins; ++b) {
    if (count[b] == 0.0) continue;
    bt.push_back(sum_t[b] / count[b]);
    by.push_back(sum_y[b] / count[b]);
  }
  return calib::fit_polynomial_plain(bt, by, ref, 3);
}

double poly(const Eigen::VectorXd& c, double dT) {
  double v = 0.0;
  for (Eigen::Index j = c.size() - 1; j >= 0; --j) v = v * dT + c[j];
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: thermal_real CSV OUT.yaml [BIN_S]\n");
    return 2;
  }
  const std::string csv = argv[1], out = argv[2];
  const std::vector<ImuSample> samples = read_csv(csv);
  if (samples.empty()) {
    std::fprintf(stderr, "%s: no rows\n", csv.c_str());
    return 1;
  }
  calib::ThermalOptions opt;
  if (argc > 3) opt.bin_s = std::atof(argv[3]);
  auto r = calib::calibrate_thermal(samples, opt);
  if (!r.ok() || !r->determined) {
    std::fprintf(stderr, "%s\n", r.ok() ? r->reason.c_str() : r.error().message.c_str());
    return 1;
  }
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kSi;
  std::ofstream(out) << app::thermal_result_yaml(*r, info, csv);

  std::printf("%s: %zu samples, %.0f s, %d bins of %.1f s, %.2f to %.2f deg C, reference %.2f\n", csv.c_str(),
              r->samples, r->duration_s, r->bins, r->bin_s, r->temp_min_c, r->temp_max_c, r->reference_c);
  std::printf(
      "axis  order  c1..cp +- sigma (unit/K^j)                     drift     bins about the curve (RMS) "
      "imucal | PX4   leave-one-out RMS imucal | PX4\n");
  for (int a = 0; a < 6; ++a) {
    const bool gyro = a < 3;
    const calib::ThermalAxisFit& fit = gyro ? r->gyro[a] : r->accel[a - 3];
    const char* name[] = {"gx", "gy", "gz", "ax", "ay", "az"};
    if (!fit.determined) {
      std::printf("%s    not determined: %s\n", name[a], fit.reason.c_str());
      continue;
    }
    std::vector<double> T, y;
    for (const ImuSample& s : samples) {
      const double v = gyro ? s.gyro[a] : s.accel[a - 3];
      if (!std::isfinite(v) || !std::isfinite(s.temperature)) continue;
      T.push_back(s.temperature);
      y.push_back(v);
    }
    const Eigen::VectorXd px4 = px4_fit(T, y, r->reference_c);
    double in_ours = 0.0, in_px4 = 0.0;
    for (const auto& b : r->bin_means) {
      const double v = gyro ? b.gyro[a] : b.accel[a - 3], dT = b.temperature_c - r->reference_c;
      in_ours += std::pow(v - poly(fit.coeffs, dT), 2);
      in_px4 += std::pow(v - poly(px4, dT), 2);
    }
    // Leave one time bin out: refit without its samples, predict its mean.
    double loo_ours = 0.0, loo_px4 = 0.0;
    int loo_n = 0;
    for (const auto& b : r->bin_means) {
      std::vector<ImuSample> rest;
      std::vector<double> rT, ry;
      const double t0 = samples.front().t_ns * 1e-9;
      for (const ImuSample& s : samples) {
        const double t = s.t_ns * 1e-9 - t0;
        if (std::abs(t - b.t_s) <= 0.5 * r->bin_s) continue;
        rest.push_back(s);
        const double v = gyro ? s.gyro[a] : s.accel[a - 3];
        if (std::isfinite(v) && std::isfinite(s.temperature)) {
          rT.push_back(s.temperature);
          ry.push_back(v);
        }
      }
      calib::ThermalOptions o2 = opt;
      o2.reference_c = r->reference_c;
      o2.bin_s = r->bin_s;
      auto r2 = calib::calibrate_thermal(rest, o2);
      if (!r2.ok() || !r2->determined) continue;
      const calib::ThermalAxisFit& f2 = gyro ? r2->gyro[a] : r2->accel[a - 3];
      if (!f2.determined) continue;
      const double v = gyro ? b.gyro[a] : b.accel[a - 3], dT = b.temperature_c - r->reference_c;
      loo_ours += std::pow(v - poly(f2.coeffs, dT), 2);
      loo_px4 += std::pow(v - poly(px4_fit(rT, ry, r->reference_c), dT), 2);
      ++loo_n;
    }
    const double nb = static_cast<double>(r->bin_means.size());
    std::printf("%s    %d      ", name[a], fit.order);
    for (int j = 1; j <= fit.order; ++j)
      std::printf("%+.3e+-%.1e ", fit.coeffs[j], std::sqrt(fit.covariance(j, j)));
    std::printf("%*s %.3e   %.3e | %.3e           %.3e | %.3e (%d bins)\n", 3 * (3 - fit.order) * 3, "",
                fit.uncompensated_drift, std::sqrt(in_ours / nb), std::sqrt(in_px4 / nb),
                std::sqrt(loo_ours / std::max(1, loo_n)), std::sqrt(loo_px4 / std::max(1, loo_n)), loo_n);
  }
  std::printf("wrote %s (imucal report %s -o REPORT.html draws it)\n", out.c_str(), out.c_str());
  return 0;
}
