// SPDX-License-Identifier: BSD-3-Clause
#include "calib/thermal_calibration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "core/die_temperature.hpp"
#include "core/text_format.hpp"

namespace imucal::calib {
namespace {

constexpr int kMaxOrder = 3;
constexpr int kColumns = kMaxOrder + 1;
constexpr int kAxes = 6;  // gyro x, y, z, accel x, y, z
/// Bin temperature steps smaller than this do not count against monotonicity, deg C (the
/// MPU-6000's temperature LSB is 1/340 deg C).
constexpr double kMonotonicTolC = 0.05;
constexpr int kMinBins = 8;
/// The order criterion's penalty per parameter (AIC's is 2; docs/thermal.md, "Order").
constexpr double kOrderPenalty = 1.0;
constexpr int kCurvePoints = 101;

struct Point {
  double t_s = 0.0;
  double temp_c = 0.0;
  Eigen::Matrix<double, kAxes, 1> v;  // gyro then accel, SI
};

struct Bin {
  double t_s = 0.0;     // mean time since the first sample
  double span_s = 0.0;  // time from its first to its last sample
  double temp_c = 0.0;  // mean die temperature
  double count = 0.0;   // samples
  Eigen::Matrix<double, kAxes, 1> v = Eigen::Matrix<double, kAxes, 1>::Zero();
};

/// One order's best fit of one axis over the noise ratio.
struct OrderFit {
  bool ok = false;
  double log_likelihood = -std::numeric_limits<double>::infinity();
  double lambda = 0.0;
  double rss = 0.0;  // whitened
  Eigen::VectorXd beta;
  Eigen::MatrixXd information;  // Xw^T Xw, in the scaled variable
  Eigen::VectorXd residual;     // unwhitened y - X beta
};

std::string deg(double v) { return fixed(v, 1); }

/// The first window whose mean steps from the previous one by more than the limits, or -1.
double first_motion_s(const std::vector<Point>& pts, const ThermalOptions& o, int* moving) {
  *moving = 0;
  double first = -1.0;
  Eigen::Matrix<double, kAxes, 1> prev_mean;
  bool have_prev = false;
  std::size_t i = 0;
  while (i < pts.size()) {
    const double w0 = pts[i].t_s;
    Eigen::Matrix<double, kAxes, 1> sum = Eigen::Matrix<double, kAxes, 1>::Zero();
    std::size_t n = 0;
    while (i < pts.size() && pts[i].t_s < w0 + o.motion_window_s) {
      sum += pts[i].v;
      ++n;
      ++i;
    }
    const Eigen::Matrix<double, kAxes, 1> mean = sum / static_cast<double>(n);
    if (have_prev) {
      const double dg = (mean.head<3>() - prev_mean.head<3>()).norm();
      const double da = (mean.tail<3>() - prev_mean.tail<3>()).norm();
      if (dg > o.max_gyro_step_radps || da > o.max_accel_step_mps2) {
        ++*moving;
        if (first < 0.0) first = w0;
      }
    }
    prev_mean = mean;
    have_prev = true;
  }
  return first;
}

/// Samples further than this many robust sigmas (1.4826 MAD) from their bin's median on any
/// axis are left out of the bin's mean: single-sample glitches (a bad bus read) would otherwise
/// shift a mean by far more than its noise. White noise passes: 6 sigma is 2e-9 per sample.
constexpr double kOutlierSigmas = 6.0;

double median_of(std::vector<double>& v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

std::vector<Bin> make_bins(const std::vector<Point>& pts, double bin_s, std::size_t* outliers) {
  std::vector<Bin> bins;
  const double t0 = pts.front().t_s;
  std::size_t i = 0;
  std::vector<double> values;
  while (i < pts.size()) {
    const auto index = std::floor((pts[i].t_s - t0) / bin_s);
    std::size_t end = i;
    while (end < pts.size() && std::floor((pts[end].t_s - t0) / bin_s) == index) ++end;
    // The bin's median and MAD per axis.
    Eigen::Matrix<double, kAxes, 1> median, limit;
    for (int a = 0; a < kAxes; ++a) {
      values.clear();
      for (std::size_t k = i; k < end; ++k) values.push_back(pts[k].v[a]);
      median[a] = median_of(values);
      for (double& x : values) x = std::abs(x - median[a]);
      const double mad = median_of(values);
      limit[a] = mad > 0.0 ? kOutlierSigmas * 1.4826 * mad : std::numeric_limits<double>::infinity();
    }
    Bin b;
    double first_t = -1.0, last_t = 0.0;
    for (std::size_t k = i; k < end; ++k) {
      if (((pts[k].v - median).cwiseAbs().array() > limit.array()).any()) {
        ++*outliers;
        continue;
      }
      if (first_t < 0.0) first_t = pts[k].t_s;
      last_t = pts[k].t_s;
      b.t_s += pts[k].t_s - t0;
      b.temp_c += pts[k].temp_c;
      b.v += pts[k].v;
      b.count += 1.0;
    }
    i = end;
    if (b.count == 0.0) continue;
    b.t_s /= b.count;
    b.temp_c /= b.count;
    b.v /= b.count;
    b.span_s = last_t - first_t;
    bins.push_back(b);
  }
  // Bins with less than half the typical count (the ends, gaps) are left out: their means would
  // carry a different noise than the model gives them.
  std::vector<double> counts;
  for (const Bin& b : bins) counts.push_back(b.count);
  std::nth_element(counts.begin(), counts.begin() + static_cast<std::ptrdiff_t>(counts.size() / 2),
                   counts.end());
  const double typical = counts[counts.size() / 2];
  std::erase_if(bins, [typical](const Bin& b) { return b.count < 0.5 * typical; });
  return bins;
}

double change_of(const Eigen::VectorXd& c, double dT) {
  double v = 0.0;
  for (Eigen::Index j = c.size() - 1; j >= 1; --j) v = (v + c[j]) * dT;
  return v;
}

Eigen::VectorXd change_gradient(Eigen::Index size, double dT) {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(size);
  double p = 1.0;
  for (Eigen::Index j = 1; j < size; ++j) {
    p *= dT;
    g[j] = p;
  }
  return g;
}

}  // namespace

Status ThermalOptions::validate() const {
  if (!(min_span_c > 0.0 && std::isfinite(min_span_c))) {
    return make_error(Errc::kInvalidArgument, "min_span_c must be > 0 deg C");
  }
  if (!(bin_s > 0.0 && std::isfinite(bin_s)))
    return make_error(Errc::kInvalidArgument, "bin_s must be > 0 s");
  if (max_bins < kMinBins || max_bins > 2000) {
    return make_error(Errc::kInvalidArgument, "max_bins must be within 8..2000");
  }
  if (max_order < 0 || max_order > kMaxOrder) {
    return make_error(Errc::kInvalidArgument, "max_order must be within 0..3");
  }
  if (reference_c && !(std::isfinite(*reference_c) && is_die_temperature(*reference_c))) {
    return make_error(Errc::kInvalidArgument, "reference_c must be a die temperature in deg C (-60..150)");
  }
  if (!(motion_window_s > 0.0) || !(max_gyro_step_radps > 0.0) || !(max_accel_step_mps2 > 0.0)) {
    return make_error(Errc::kInvalidArgument,
                      "motion_window_s, max_gyro_step_radps and max_accel_step_mps2 must be > 0");
  }
  if (!(temperature_scale != 0.0 && std::isfinite(temperature_scale) && std::isfinite(temperature_offset))) {
    return make_error(Errc::kInvalidArgument, "temperature_scale must be finite and not 0");
  }
  return {};
}

double ThermalAxisFit::change(double temperature_c, double reference_c) const {
  if (!determined) return std::numeric_limits<double>::quiet_NaN();
  return change_of(coeffs, temperature_c - reference_c);
}

double ThermalAxisFit::change_sigma(double temperature_c, double reference_c) const {
  if (!determined) return std::numeric_limits<double>::quiet_NaN();
  const Eigen::VectorXd g = change_gradient(coeffs.size(), temperature_c - reference_c);
  return std::sqrt(std::max(0.0, g.dot(covariance * g)));
}

// Every order 0..max_order of every axis at its most likely random-walk ratio lambda (a grid
// search over lambda; the white variance and the coefficients are profiled out per lambda).
static std::array<std::array<OrderFit, kColumns>, kAxes> fit_orders(const Eigen::MatrixXd& XY,
                                                                    const Eigen::MatrixXd& K,
                                                                    const Eigen::VectorXd& white,
                                                                    int max_order, double duration) {
  const int n = static_cast<int>(XY.rows());
  std::array<std::array<OrderFit, kColumns>, kAxes> fits{};
  std::vector<double> lambdas{0.0};
  for (double x = -3.0; x <= 6.0 + 1e-9; x += 0.25) lambdas.push_back(std::pow(10.0, x) / duration);
  for (double lambda : lambdas) {
    Eigen::MatrixXd V = lambda * K;
    V.diagonal() += white;
    const Eigen::LLT<Eigen::MatrixXd> llt(V);
    if (llt.info() != Eigen::Success) continue;
    const Eigen::MatrixXd Z = llt.matrixL().solve(XY);
    const double log_det = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
    for (int p = 0; p <= max_order; ++p) {
      const Eigen::MatrixXd Xw = Z.leftCols(p + 1);
      const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Xw);
      if (qr.rank() < p + 1) continue;
      for (int a = 0; a < kAxes; ++a) {
        const Eigen::VectorXd yw = Z.col(kColumns + a);
        const Eigen::VectorXd beta = qr.solve(yw);
        const double rss = (yw - Xw * beta).squaredNorm();
        if (!(rss > 0.0)) continue;
        const double ll = -0.5 * n * (std::log(2.0 * std::numbers::pi * rss / n) + 1.0) - 0.5 * log_det;
        OrderFit& f = fits[a][p];
        if (ll > f.log_likelihood) {
          f.ok = true;
          f.log_likelihood = ll;
          f.lambda = lambda;
          f.rss = rss;
          f.beta = beta;
          f.information = Xw.transpose() * Xw;
          f.residual = XY.col(kColumns + a) - XY.leftCols(p + 1) * beta;
        }
      }
    }
  }

  return fits;
}

// One axis's order among its fits: the least -2 ln L + kOrderPenalty (p + 3), a term kept when it
// lowers -2 ln L by more than 1 (docs/thermal.md: a bend left out is a bias no sigma covers, a
// needless term costs only variance its sigma shows). Fills `aic` (AIC, reported; NaN where not
// fitted); -1 when no order could be fitted.
static int choose_order(const std::array<OrderFit, kColumns>& fits, int max_order,
                        std::array<double, 4>& aic) {
  aic.fill(std::numeric_limits<double>::quiet_NaN());
  int best = -1;
  double best_criterion = 0.0;
  for (int p = 0; p <= max_order; ++p) {
    if (!fits[p].ok) continue;
    // The parameters: p + 1 coefficients and the two variances.
    aic[p] = -2.0 * fits[p].log_likelihood + 2.0 * (p + 3);
    const double criterion = -2.0 * fits[p].log_likelihood + kOrderPenalty * (p + 3);
    if (best < 0 || criterion < best_criterion) best = p, best_criterion = criterion;
  }
  return best;
}

namespace {

/// The samples with a temperature, in SI, sorted by time; a sensor the recording lacks
/// entirely (a gyro-only device: every value NaN) is carried as zeros, which no order fits.
struct Points {
  std::vector<Point> pts;
  bool has_gyro = true, has_accel = true;
  std::size_t saturated = 0, not_finite = 0;
};

Result<Points> gather_points(std::span<const ImuSample> samples, const ThermalOptions& o) {
  Points out;
  std::vector<Point>& pts = out.pts;
  // A sensor the recording does not have at all (a gyro-only device: every value NaN) is fitted
  // as zeros, which no order fits, and reported as not determined; otherwise a sample with a
  // value that is not finite is left out.
  const auto has = [&](auto member) {
    return std::any_of(samples.begin(), samples.end(),
                       [&](const ImuSample& s) { return (s.*member).allFinite(); });
  };
  const bool has_gyro = has(&ImuSample::gyro), has_accel = has(&ImuSample::accel);
  out.has_gyro = has_gyro;
  out.has_accel = has_accel;
  pts.reserve(samples.size());
  std::size_t &saturated = out.saturated, &not_finite = out.not_finite;
  for (const ImuSample& s : samples) {
    if (!std::isfinite(s.temperature)) continue;
    if ((s.flags & (kImuFlagAccelSaturated | kImuFlagGyroSaturated)) != 0) {
      ++saturated;
      continue;
    }
    if ((has_gyro && !s.gyro.allFinite()) || (has_accel && !s.accel.allFinite())) {
      ++not_finite;
      continue;
    }
    Point p;
    p.t_s = ns_to_s(s.t_ns);
    p.temp_c = o.temperature_scale * s.temperature + o.temperature_offset;
    if (!is_die_temperature(p.temp_c)) {
      return make_error(Errc::kCorrupt,
                        "the sample at t_ns " + std::to_string(s.t_ns) + " gives a die temperature of " +
                            format_number("%g", p.temp_c) + " deg C, outside " +
                            fixed(kMinDieTemperatureC, 0) + ".." + fixed(kMaxDieTemperatureC, 0) +
                            " deg C, which no die reaches: the recording's temperatures are wrong (for an "
                            "import, check the temperature column and its scale and offset)");
    }
    p.v.head<3>() = has_gyro ? o.gyro.to_si(s.gyro) : Eigen::Vector3d::Zero();
    p.v.tail<3>() = has_accel ? o.accel.to_si(s.accel) : Eigen::Vector3d::Zero();
    pts.push_back(p);
  }
  if (!has_gyro && !has_accel) {
    return make_error(Errc::kInsufficientData, "the recording holds no finite gyro or accelerometer value");
  }
  if (pts.empty()) {
    return make_error(Errc::kInsufficientData,
                      samples.empty() ? std::string("the recording holds no IMU sample")
                                      : "no sample carries a die temperature: record with a device (or an "
                                        "import) that gives the temperature of every sample");
  }
  std::sort(pts.begin(), pts.end(), [](const Point& a, const Point& b) { return a.t_s < b.t_s; });

  int moving = 0;
  const double first_motion = first_motion_s(pts, o, &moving);
  if (first_motion >= 0.0) {
    return make_error(Errc::kInsufficientData,
                      "the rig moved (" + std::to_string(moving) + " step(s) between " +
                          fixed(o.motion_window_s, 1) + " s means, the first " +
                          fixed(first_motion - pts.front().t_s, 1) +
                          " s from the start): record the warm-up with the rig standing still on a "
                          "firm surface, untouched");
  }
  return out;
}

/// One axis's result from its chosen order's fit (in u = (T - T_ref) / h): the coefficients and
/// their covariance, the noise model, the drift and the model's sigma over the range.
void set_axis_fit(ThermalAxisFit& out, const OrderFit& f, int best, int n, double h, double mean_count,
                  double dt_s, const ThermalResult& r) {
  // The scale of V from the whitened residuals, with the coefficients' degrees of freedom; the
  // noise ratio lambda is taken as known in the covariance.
  const double s2 = f.rss / std::max(1, n - best - 1);
  Eigen::MatrixXd cov_u = s2 * f.information.inverse();
  Eigen::VectorXd scale(best + 1);
  for (int j = 0; j <= best; ++j) scale[j] = std::pow(h, -j);
  out.coeffs = scale.cwiseProduct(f.beta);
  out.covariance = scale.asDiagonal() * cov_u * scale.asDiagonal();
  out.order = best;
  out.determined = true;
  out.residual_rms = std::sqrt(f.residual.squaredNorm() / n);
  const double white_var = f.rss / n;  // of a bin mean of mean_count samples
  out.white_noise_density = std::sqrt(white_var * mean_count * dt_s);
  out.random_walk = std::sqrt(f.lambda * white_var);
  double lo = 0.0, hi = 0.0, sum_var = 0.0;
  for (int i = 0; i < kCurvePoints; ++i) {
    const double T = r.temp_min_c + (r.temp_max_c - r.temp_min_c) * i / (kCurvePoints - 1);
    const double c = out.change(T, r.reference_c);
    const double s = out.change_sigma(T, r.reference_c);
    lo = i == 0 ? c : std::min(lo, c);
    hi = i == 0 ? c : std::max(hi, c);
    sum_var += s * s / kCurvePoints;
  }
  out.uncompensated_drift = hi - lo;
  out.model_sigma_rms = std::sqrt(sum_var);
}

/// The fit's inputs: the design [1, u, u^2, u^3 | bin means] in u = (T - T_ref) / h, and the
/// covariance of the bin means in units of the white variance of a mean of mean_count samples,
/// V = diag(white) + lambda K.
struct Design {
  double h = 1.0;
  double mean_count = 0.0;
  Eigen::MatrixXd XY, K;
  Eigen::VectorXd white;
};

Design make_design(const std::vector<Bin>& bins, const ThermalResult& r) {
  const int n = static_cast<int>(bins.size());
  Design d;
  // The design in u = (T - T_ref) / h, so that the columns are of similar size.
  const double h = d.h =
      std::max(std::abs(r.temp_max_c - r.reference_c), std::abs(r.temp_min_c - r.reference_c));
  Eigen::MatrixXd& XY = d.XY;
  XY.resize(n, kColumns + kAxes);
  double& mean_count = d.mean_count;
  for (int k = 0; k < n; ++k) {
    const double u = (bins[k].temp_c - r.reference_c) / h;
    double p = 1.0;
    for (int j = 0; j < kColumns; ++j, p *= u) XY(k, j) = p;
    XY.row(k).tail<kAxes>() = bins[k].v.transpose();
    mean_count += bins[k].count / n;
  }
  // Covariance of the bin means, in units of the white variance of a mean of mean_count samples:
  // V = diag(mean_count / count_k) + lambda K, K_ij = E[r_i r_j] / q of the random walk's bin
  // means (time since the first sample: min(t_i, t_j), less span/6 on the diagonal).
  Eigen::MatrixXd& K = d.K;
  K.resize(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) K(i, j) = std::min(bins[i].t_s, bins[j].t_s);
    K(i, i) = std::max(bins[i].t_s - bins[i].span_s / 6.0, 1e-9);
  }
  Eigen::VectorXd& white = d.white;
  white.resize(n);
  for (int k = 0; k < n; ++k) white[k] = mean_count / bins[k].count;
  return d;
}

}  // namespace

Result<ThermalResult> calibrate_thermal(std::span<const ImuSample> samples, const ThermalOptions& o) {
  IMUCAL_TRY(o.validate());
  auto gathered = gather_points(samples, o);
  if (!gathered.ok()) return gathered.error();
  const std::vector<Point>& pts = gathered->pts;
  const bool has_gyro = gathered->has_gyro, has_accel = gathered->has_accel;
  const std::size_t saturated = gathered->saturated, not_finite = gathered->not_finite;

  ThermalResult r;
  r.duration_s = pts.back().t_s - pts.front().t_s;
  r.samples = pts.size();
  r.bin_s = std::max(o.bin_s, r.duration_s / o.max_bins);
  if (saturated > 0) r.warnings.push_back(std::to_string(saturated) + " saturated samples left out");
  if (not_finite > 0)
    r.warnings.push_back(std::to_string(not_finite) + " samples with a value that is not finite left out");
  std::size_t outliers = 0;
  const std::vector<Bin> bins = make_bins(pts, r.bin_s, &outliers);
  if (outliers > 0) {
    r.warnings.push_back(std::to_string(outliers) + " samples more than " + fixed(kOutlierSigmas, 0) +
                         " robust sigmas from their bin's median (glitches) left out of the bin means");
  }
  const int n = static_cast<int>(bins.size());
  r.bins = n;
  r.temp_min_c = r.temp_max_c = bins.front().temp_c;
  for (const Bin& b : bins) {
    r.bin_means.push_back({b.t_s, b.temp_c, b.v.head<3>(), b.v.tail<3>(), static_cast<std::size_t>(b.count)});
    r.temp_min_c = std::min(r.temp_min_c, b.temp_c);
    r.temp_max_c = std::max(r.temp_max_c, b.temp_c);
  }
  r.reference_c = o.reference_c.value_or(0.5 * (r.temp_min_c + r.temp_max_c));
  bool rises = true, falls = true;
  for (int k = 1; k < n; ++k) {
    const double step = bins[k].temp_c - bins[k - 1].temp_c;
    if (step < -kMonotonicTolC) rises = false;
    if (step > kMonotonicTolC) falls = false;
  }
  r.temperature_monotonic = rises || falls;

  auto not_determined = [&r](std::string reason) {
    r.determined = false;
    r.reason = reason;
    for (auto* axes : {&r.gyro, &r.accel}) {
      for (ThermalAxisFit& a : *axes) a.reason = reason;
    }
    return r;
  };
  const double span = r.temp_max_c - r.temp_min_c;
  if (span < o.min_span_c) {
    return not_determined("the die temperature spans " + fixed(span, 2) + " deg C (" + deg(r.temp_min_c) +
                          " to " + deg(r.temp_max_c) + "), less than the " + fixed(o.min_span_c, 1) +
                          " deg C needed: record from a colder start (or with a heater) until the die "
                          "has warmed by more");
  }
  if (n < kMinBins) {
    return not_determined("only " + std::to_string(n) + " bins of " + fixed(r.bin_s, 1) +
                          " s: record for longer (at least " + std::to_string(kMinBins) + " bins)");
  }

  const Design design = make_design(bins, r);
  const double h = design.h, mean_count = design.mean_count;
  const int max_order = std::min(o.max_order, n - 4);
  const auto fits = fit_orders(design.XY, design.K, design.white, max_order, std::max(bins.back().t_s, 1.0));

  double dt_s = r.duration_s / std::max<double>(1.0, static_cast<double>(pts.size()) - 1.0);
  for (int a = 0; a < kAxes; ++a) {
    ThermalAxisFit& out = a < 3 ? r.gyro[a] : r.accel[a - 3];
    const int best = choose_order(fits[a], max_order, out.aic);
    if (!(a < 3 ? has_gyro : has_accel)) {
      out.reason = a < 3 ? "the recording has no gyro values" : "the recording has no accelerometer values";
      continue;
    }
    if (best < 0) {
      out.reason = "no order could be fitted (the bin means are degenerate)";
      continue;
    }
    set_axis_fit(out, fits[a][best], best, n, h, mean_count, dt_s, r);
    if (best == o.max_order && best > 0) {
      r.warnings.push_back(std::string(a < 3 ? "gyro " : "accelerometer ") + "xyz"[a % 3] +
                           ": the highest order tried (" + std::to_string(best) +
                           ") fits best; the curve may need more over this range");
    }
  }
  r.determined = true;
  if (r.temperature_monotonic) {
    r.warnings.push_back(
        "the temperature only moved one way, so time and temperature are tied: the bias random walk and "
        "the temperature curve are told apart by their shapes alone (the sigmas include this); holds at "
        "several temperatures, or a warm-up and a cool-down, separate them better");
  }
  return r;
}

ThermalScaleFit fit_scale_against_temperature(std::vector<ThermalScalePoint> points, double reference_c,
                                              double min_span_c) {
  ThermalScaleFit fit;
  fit.points = std::move(points);
  const auto& pts = fit.points;
  if (pts.size() < 2) {
    fit.reason = "static calibrations at two or more die temperatures are needed, " +
                 std::to_string(pts.size()) + " given";
    return fit;
  }
  double lo = pts.front().temperature_c, hi = lo;
  for (const auto& p : pts) lo = std::min(lo, p.temperature_c), hi = std::max(hi, p.temperature_c);
  if (hi - lo < min_span_c) {
    fit.reason = "the static calibrations span " + fixed(hi - lo, 2) +
                 " deg C of die temperature, less than " + fixed(min_span_c, 2);
    return fit;
  }
  fit.determined = true;
  for (const auto& p : pts) fit.model.temperatures_c.push_back(p.temperature_c);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto axis = [&](const Eigen::Vector3d ThermalScalePoint::*value,
                        const Eigen::Vector3d ThermalScalePoint::*sigma, int i, double* k, double* k_sigma,
                        double* chi2_dof) {
    *k = *k_sigma = *chi2_dof = nan;
    double sw = 0, swx = 0, swxx = 0, swy = 0, swxy = 0;
    for (const auto& p : pts) {
      const double s = (p.*sigma)[i], y = (p.*value)[i];
      if (!(std::isfinite(s) && s > 0.0 && std::isfinite(y))) return;  // an input sigma not determined
      const double w = 1.0 / (s * s), x = p.temperature_c - reference_c;
      sw += w, swx += w * x, swxx += w * x * x, swy += w * y, swxy += w * x * y;
    }
    const double det = sw * swxx - swx * swx;
    if (!(det > 0.0)) return;
    const double a = (swxx * swy - swx * swxy) / det, b = (sw * swxy - swx * swy) / det;
    double var_a = swxx / det, var_b = sw / det, cov_ab = -swx / det;
    if (pts.size() > 2) {
      double chi2 = 0.0;
      for (const auto& p : pts) {
        const double r = ((p.*value)[i] - a - b * (p.temperature_c - reference_c)) / (p.*sigma)[i];
        chi2 += r * r;
      }
      *chi2_dof = chi2 / static_cast<double>(pts.size() - 2);
      const double inflate = std::max(1.0, *chi2_dof);
      var_a *= inflate, var_b *= inflate, cov_ab *= inflate;
    }
    // The sensitivity is 1 / s: d ln(1 / s) / dT = -b / a at the reference.
    *k = -b / a;
    // First-order propagation of the covariance of (a, b).
    const double dk_db = -1.0 / a, dk_da = b / (a * a);
    *k_sigma = std::sqrt(
        std::max(0.0, dk_db * dk_db * var_b + 2.0 * dk_db * dk_da * cov_ab + dk_da * dk_da * var_a));
  };
  for (int i = 0; i < 3; ++i) {
    axis(&ThermalScalePoint::gyro, &ThermalScalePoint::gyro_sigma, i, &fit.model.gyro_k[i],
         &fit.model.gyro_sigma[i], &fit.gyro_chi2_dof[i]);
    axis(&ThermalScalePoint::accel, &ThermalScalePoint::accel_sigma, i, &fit.model.accel_k[i],
         &fit.model.accel_sigma[i], &fit.accel_chi2_dof[i]);
  }
  return fit;
}

ThermalModel thermal_model(const ThermalResult& r) {
  ThermalModel m;
  m.reference_c = r.reference_c;
  m.min_c = r.temp_min_c;
  m.max_c = r.temp_max_c;
  if (r.scale.determined) {
    m.scale_model = r.scale.model;
    m.scale = kThermalScaleForm;
  } else {
    m.scale = "not determined: " + r.scale.reason;
  }
  for (int a = 0; a < 6; ++a) {
    const ThermalAxisFit& f = a < 3 ? r.gyro[a] : r.accel[a - 3];
    ThermalAxisModel& out = a < 3 ? m.gyro[a] : m.accel[a - 3];
    out.determined = f.determined;
    out.reason = f.reason;
    if (!f.determined) continue;
    // c_0 is the value at T_ref (for the accelerometer with gravity's projection): not a change.
    out.coeffs = f.coeffs.tail(f.order);
    out.sigma = f.covariance.diagonal().tail(f.order).cwiseSqrt();
  }
  return m;
}

Eigen::VectorXd fit_polynomial_plain(std::span<const double> temperature_c, std::span<const double> values,
                                     double reference_c, int order) {
  const auto n = static_cast<Eigen::Index>(std::min(temperature_c.size(), values.size()));
  double h = 0.0;
  for (Eigen::Index k = 0; k < n; ++k) h = std::max(h, std::abs(temperature_c[k] - reference_c));
  if (h <= 0.0) h = 1.0;
  Eigen::MatrixXd X(n, order + 1);
  Eigen::VectorXd y(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    const double u = (temperature_c[k] - reference_c) / h;
    double p = 1.0;
    for (int j = 0; j <= order; ++j, p *= u) X(k, j) = p;
    y[k] = values[k];
  }
  Eigen::VectorXd c = X.colPivHouseholderQr().solve(y);
  for (int j = 0; j <= order; ++j) c[j] *= std::pow(h, -j);
  return c;
}

}  // namespace imucal::calib
