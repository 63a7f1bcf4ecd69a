#include "calib/static_calibration.hpp"

#include <ceres/ceres.h>
#include <time.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "calib/allan.hpp"
#include "calib/ellipsoid.hpp"
#include "calib/rk4.hpp"
#include "calib/static_detector.hpp"

namespace imucal::calib {
namespace {

/// CPU time of the calling thread: the timings mean the same on a loaded machine as on an idle one.
struct Clock {
  using time_point = double;
  static double now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
};

double seconds_since(Clock::time_point t0) { return Clock::now() - t0; }

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

// ---- accelerometer (eqs. 3.1-3.4) ---------------------------------------------------------

using Vec9 = Eigen::Matrix<double, 9, 1>;

/// Residual of eq. 3.4 for one static mean: g^2 - |T_a K_a (a + b_a)|^2, parameters in the order
/// of eq. 3.2: [alpha_yz, alpha_zy, alpha_zx, s_x, s_y, s_z, b_x, b_y, b_z], each divided by a
/// fixed unit c_i so that all columns of the Jacobian have similar size (raw counts would
/// otherwise make the bias columns 1e7 times smaller than the scale columns, and the covariance
/// would lose them).
struct AccelMagnitudeCost {
  Eigen::Vector3d a;
  double g2;
  Vec9 c;

  template <class T>
  bool operator()(const T* pn, T* r) const {
    T p[9];
    for (int i = 0; i < 9; ++i) p[i] = pn[i] * c[i];
    const T x = p[3] * (a[0] + p[6]);
    const T y = p[4] * (a[1] + p[7]);
    const T z = p[5] * (a[2] + p[8]);
    const T ox = x - p[0] * y + p[1] * z;
    const T oy = y - p[2] * z;
    r[0] = T(g2) - (ox * ox + oy * oy + z * z);
    return true;
  }
  static ceres::CostFunction* Create(const Eigen::Vector3d& a, double g, const Vec9& c) {
    return new ceres::AutoDiffCostFunction<AccelMagnitudeCost, 1, 9>(new AccelMagnitudeCost{a, g * g, c});
  }
};

Vec9 accel_params(const TedaldiTriad& t) {
  Vec9 p;
  p << accel_angles(t.T), t.scale, t.bias;
  return p;
}

TedaldiTriad accel_triad(const Vec9& p) {
  TedaldiTriad t;
  t.T = accel_misalignment(p.head<3>());
  t.scale = p.segment<3>(3);
  t.bias = p.tail<3>();
  return t;
}

ceres::Solver::Options solver_options(int max_iterations) {
  ceres::Solver::Options o;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = ceres::DENSE_QR;
  o.num_threads = 1;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-14;
  o.parameter_tolerance = 1e-12;
  o.logging_type = ceres::SILENT;
  o.minimizer_progress_to_stdout = false;
  return o;
}

struct AccelSolve {
  Vec9 p;
  double cost = 0.0;
  double rms = 0.0;
  int iterations = 0;
  bool ok = false;
};

AccelSolve solve_accel(std::span<const Eigen::Vector3d> means, double g, const TedaldiTriad& init,
                       Eigen::MatrixXd* covariance) {
  AccelSolve out;
  Vec9 c;
  for (int i = 0; i < 3; ++i) {
    const double s = std::max(std::abs(init.scale[i]), 1e-12);
    c[i] = 1.0;
    c[3 + i] = s;
    c[6 + i] = g / s;
  }
  Vec9 pn = accel_params(init).cwiseQuotient(c);
  ceres::Problem problem;
  for (const auto& m : means)
    problem.AddResidualBlock(AccelMagnitudeCost::Create(m, g, c), nullptr, pn.data());
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options(200), &problem, &summary);
  out.p = pn.cwiseProduct(c);
  out.ok = summary.IsSolutionUsable() && out.p.allFinite();
  out.cost = summary.final_cost;
  out.iterations = static_cast<int>(summary.iterations.size());
  const double n = static_cast<double>(means.size());
  out.rms = std::sqrt(2.0 * out.cost / n);
  if (covariance && out.ok) {
    ceres::Covariance::Options copt;
    copt.algorithm_type = ceres::DENSE_SVD;
    copt.null_space_rank = -1;
    copt.num_threads = 1;
    ceres::Covariance cov(copt);
    std::vector<std::pair<const double*, const double*>> blocks = {{pn.data(), pn.data()}};
    Eigen::Matrix<double, 9, 9, Eigen::RowMajor> cn;
    if (cov.Compute(blocks, &problem) && cov.GetCovarianceBlock(pn.data(), pn.data(), cn.data())) {
      const double dof = std::max(1.0, n - 9.0);
      *covariance =
          c.asDiagonal() * Eigen::Matrix<double, 9, 9>(cn) * c.asDiagonal() * (2.0 * out.cost / dof);
    } else {
      out.ok = false;
    }
  }
  return out;
}

// ---- gyroscope (eqs. 3.5-3.8, 3.10-3.16) --------------------------------------------------

/// One gravity transfer between consecutive static poses.
struct Transfer {
  std::vector<Eigen::Vector3d> gyro_raw;
  std::vector<double> t_s;
  Eigen::Vector3d u0, u1;
  std::size_t pose0 = 0;  // index of the static interval the motion starts from
};

/// f(q) = R(q)^T u (eq. 2.13), the gravity direction of the start pose seen at the end pose.
template <class T>
Eigen::Matrix<T, 3, 1> rotate_back(const T* q, const Eigen::Vector3d& u) {
  const T a = q[0], b = q[1], c = q[2], d = q[3];
  Eigen::Matrix<T, 3, 3> R;
  R << a * a + b * b - c * c - d * d, T(2) * (b * c - a * d), T(2) * (b * d + a * c),  //
      T(2) * (b * c + a * d), a * a - b * b + c * c - d * d, T(2) * (c * d - a * b),   //
      T(2) * (b * d - a * c), T(2) * (c * d + a * b), a * a - b * b - c * c + d * d;
  return R.transpose() * u.cast<T>();
}

/// Residual of eq. 3.8 for one transfer: u_1 - R(Psi[w])^T u_0 with w = T_g K_g (w_S + b_g).
/// Parameters: [gamma (6, eq. 3.6 order), s_g (3)] and, when estimated, b_g (3). The Jacobian
/// is exact: reverse-mode differentiation of the RK4n recursion (calib/rk4.hpp).
class GyroTransferCost : public ceres::CostFunction {
 public:
  GyroTransferCost(const Transfer* transfer, const Eigen::Vector3d* fixed_bias)
      : tr_(transfer), fixed_bias_(fixed_bias) {
    set_num_residuals(3);
    mutable_parameter_block_sizes()->push_back(9);
    if (!fixed_bias_) mutable_parameter_block_sizes()->push_back(3);
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* p = parameters[0];
    const Eigen::Matrix<double, 6, 1> gamma = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(p);
    const Eigen::Vector3d s(p[6], p[7], p[8]);
    const Eigen::Vector3d b = fixed_bias_ ? *fixed_bias_ : Eigen::Vector3d(parameters[1]);
    const Eigen::Matrix3d Tg = gyro_misalignment(gamma);
    const Eigen::Matrix3d A = Tg * s.asDiagonal();
    const std::size_t n = tr_->gyro_raw.size();
    w_.resize(n);
    for (std::size_t i = 0; i < n; ++i) w_[i] = A * (tr_->gyro_raw[i] + b);
    const Eigen::Vector3d& u0 = tr_->u0;
    auto df_dq = [&u0](const Quat4& q) {
      using Jet = ceres::Jet<double, 4>;
      const Jet qj[4] = {Jet(q[0], 0), Jet(q[1], 1), Jet(q[2], 2), Jet(q[3], 3)};
      const Eigen::Matrix<Jet, 3, 1> f = rotate_back(qj, u0);
      Eigen::Matrix<double, 3, 4> J;
      for (int r = 0; r < 3; ++r) J.row(r) = f[r].v.transpose();
      return J;
    };
    const bool want_jacobian = jacobians && (jacobians[0] || (!fixed_bias_ && jacobians[1]));
    // The solver evaluates the residual at a candidate step and, once it is accepted, the
    // Jacobian at the same point: keep the forward quaternions of the last evaluation.
    Eigen::Matrix<double, 12, 1> key;
    key << Eigen::Map<const Eigen::Matrix<double, 9, 1>>(p), b;
    const bool cached = cache_valid_ && key == cache_key_;
    if (!cached) {
      q_buf_.resize(n == 0 ? 1 : n);
      q_buf_[0] = Quat4(1, 0, 0, 0);
      for (std::size_t i = 0; i + 1 < n; ++i) {
        q_buf_[i + 1] = rk4n_step(q_buf_[i], w_[i], w_[i + 1], tr_->t_s[i + 1] - tr_->t_s[i]);
      }
      cache_key_ = key;
      cache_valid_ = true;
    }
    Quat4 q_end = q_buf_[n == 0 ? 0 : n - 1];
    if (want_jacobian) {
      integrate_rk4n_with_gradient(std::span<const Eigen::Vector3d>(w_), tr_->t_s, df_dq, q_buf_, grad_,
                                   true);
      q_end = grad_.q_end;
    }
    const Eigen::Vector3d f = rotate_back(q_end.data(), u0);
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = tr_->u1 - f;
    if (!want_jacobian) return true;

    // dr/dw_i = -df/dw_i. Chain through w_i = A v_i, v_i = raw_i + b.
    Eigen::Matrix<double, 3, 9> J_A = Eigen::Matrix<double, 3, 9>::Zero();  // column 3a+c: dA(a,c)
    Eigen::Matrix3d sum_G = Eigen::Matrix3d::Zero();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Matrix3d& G = grad_.df_dw[i];
      const Eigen::Vector3d v = tr_->gyro_raw[i] + b;
      for (int a = 0; a < 3; ++a) J_A.middleCols<3>(3 * a) -= G.col(a) * v.transpose();
      sum_G -= G;
    }
    if (jacobians[0]) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jacobians[0]);
      J.col(0) = -s[1] * J_A.col(1);  // T(0,1) = -gamma_yz
      J.col(1) = s[2] * J_A.col(2);   // T(0,2) =  gamma_zy
      J.col(2) = s[0] * J_A.col(3);   // T(1,0) =  gamma_xz
      J.col(3) = -s[2] * J_A.col(5);  // T(1,2) = -gamma_zx
      J.col(4) = -s[0] * J_A.col(6);  // T(2,0) = -gamma_xy
      J.col(5) = s[1] * J_A.col(7);   // T(2,1) =  gamma_yx
      for (int c = 0; c < 3; ++c) {
        J.col(6 + c) = Tg(0, c) * J_A.col(c) + Tg(1, c) * J_A.col(3 + c) + Tg(2, c) * J_A.col(6 + c);
      }
    }
    if (!fixed_bias_ && jacobians[1]) {
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> Jb(jacobians[1]);
      Jb = sum_G * A;
    }
    return true;
  }

 private:
  const Transfer* tr_;
  const Eigen::Vector3d* fixed_bias_;
  // Scratch, reused between evaluations (the solver runs on one thread).
  mutable std::vector<Eigen::Vector3d> w_;
  mutable std::vector<Quat4> q_buf_;
  mutable Rk4nGradient grad_;
  mutable Eigen::Matrix<double, 12, 1> cache_key_ = Eigen::Matrix<double, 12, 1>::Zero();
  mutable bool cache_valid_ = false;
};

// ---- helpers ---------------------------------------------------------------------------------

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  const std::size_t k = std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

int count_distinct(std::span<const Eigen::Vector3d> directions, double min_angle_rad) {
  std::vector<Eigen::Vector3d> reps;
  const double cos_min = std::cos(min_angle_rad);
  for (const auto& d : directions) {
    bool found = false;
    for (const auto& r : reps) {
      if (r.dot(d) > cos_min) {
        found = true;
        break;
      }
    }
    if (!found) reps.push_back(d);
  }
  return static_cast<int>(reps.size());
}

TedaldiTriad triad_from_conversion(const AxisConversion& c) {
  TedaldiTriad t;
  t.scale = c.scale;
  t.bias = -c.offset;
  return t;
}

TriadSigma accel_sigma(const Eigen::MatrixXd& cov) {
  TriadSigma s;
  const Eigen::VectorXd d = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  s.T(0, 1) = d[0];
  s.T(0, 2) = d[1];
  s.T(1, 2) = d[2];
  s.scale = d.segment<3>(3);
  s.bias = d.segment<3>(6);
  return s;
}

/// Gravity direction at the first and at the last sample of a static interval. Every sample's
/// calibrated acceleration is carried to the first sample by the gyro-integrated rotation before
/// averaging, so slow motion the variance detector let into the interval (the start or the end of
/// a move) does not bias the directions used by eq. 3.8.
struct PoseDirections {
  Eigen::Vector3d u_start, u_end;
};

std::vector<PoseDirections> pose_directions(const std::vector<StaticInterval>& intervals,
                                            const std::vector<Eigen::Vector3d>& accel,
                                            const std::vector<Eigen::Vector3d>& gyro,
                                            std::span<const ImuSample> samples,
                                            const TedaldiTriad& accel_model, const TedaldiTriad& gyro_model) {
  std::vector<PoseDirections> out;
  out.reserve(intervals.size());
  const Eigen::Matrix3d Aa = accel_model.TK(), Ag = gyro_model.TK();
  for (const auto& iv : intervals) {
    Quat4 q(1, 0, 0, 0);
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    Eigen::Vector3d sum = Aa * (accel[iv.begin] + accel_model.bias);
    Eigen::Vector3d w_prev = Ag * (gyro[iv.begin] + gyro_model.bias);
    for (std::size_t j = iv.begin + 1; j < iv.end; ++j) {
      const Eigen::Vector3d w = Ag * (gyro[j] + gyro_model.bias);
      q = rk4n_step(q, w_prev, w, ns_to_s(samples[j].t_ns - samples[j - 1].t_ns));
      w_prev = w;
      R = quat_to_matrix(q);
      sum += R * (Aa * (accel[j] + accel_model.bias));
    }
    out.push_back({sum.normalized(), (R.transpose() * sum).normalized()});
  }
  return out;
}

}  // namespace

Status StaticCalibrationOptions::validate() const {
  auto fail = [](const std::string& msg) -> Status { return make_error(Errc::kInvalidArgument, msg); };
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9)) {
    return fail("gravity " + fmt("%g", gravity_mps2) + " m/s^2 is not a terrestrial value (9.7..9.9)");
  }
  if (!(init_still_s >= 0.0) || !std::isfinite(init_still_s))
    return fail("the initial still period must be >= 0 s");
  if (!(window_s > 0.0 && window_s <= 10.0)) return fail("the detector window must be in (0, 10] s");
  if (!(min_interval_s > 0.0)) return fail("the minimum static interval must be positive");
  if (multiplier_min < 1 || multiplier_max < multiplier_min)
    return fail("threshold multipliers must satisfy 1 <= min <= max");
  if (min_attitudes < 9)
    return fail("at least 9 distinct attitudes are needed for observability (Tedaldi 3.5)");
  if (!(distinct_attitude_deg > 0.0)) return fail("the distinct-attitude angle must be positive");
  if (!(max_rotation_in_static_deg > 0.0))
    return fail("the rotation limit inside a static interval must be positive");
  for (const auto* c : {&accel_init, &gyro_init}) {
    if (*c &&
        (!(*c)->scale.allFinite() || !(*c)->offset.allFinite() || (*c)->scale.cwiseAbs().minCoeff() == 0.0)) {
      return fail("a nominal scale is zero or not finite");
    }
  }
  return {};
}

Result<StaticCalibrationResult> calibrate_static(std::span<const ImuSample> samples,
                                                 const StaticCalibrationOptions& opt) {
  IMUCAL_TRY(opt.validate());
  StaticCalibrationResult res;
  res.gravity_mps2 = opt.gravity_mps2;
  const std::size_t n = samples.size();
  if (n < 1000) {
    return make_error(Errc::kInsufficientData,
                      "the recording has " + std::to_string(n) +
                          " samples: a static calibration needs a still start (about 50 s) and 36-50 "
                          "held poses; record again");
  }

  // Time base, gaps, saturation.
  std::vector<double> dt_s(n - 1);
  for (std::size_t i = 1; i < n; ++i) {
    const TimeNs d = samples[i].t_ns - samples[i - 1].t_ns;
    if (d <= 0) {
      return make_error(Errc::kCorrupt, "timestamps do not increase at sample " + std::to_string(i) +
                                            ": the log is damaged or its samples are out of order");
    }
    dt_s[i - 1] = ns_to_s(d);
  }
  const double period_s = percentile(dt_s, 0.5);
  const double rate_hz = 1.0 / period_s;
  std::vector<bool> break_before(n, false), reset_before(n, false), accel_ok(n, true), gyro_ok(n, true);
  int gaps = 0, accel_sat = 0, gyro_sat = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const auto f = samples[i].flags;
    if (i > 0 && ((f & (kImuFlagGapBefore | kImuFlagDeviceReset)) || dt_s[i - 1] > 1.5 * period_s)) {
      break_before[i] = true;
      reset_before[i] = (f & kImuFlagDeviceReset) != 0;
      ++gaps;
    }
    if ((f & kImuFlagAccelSaturated) || !samples[i].accel.allFinite()) {
      accel_ok[i] = false;
      ++accel_sat;
    }
    if ((f & kImuFlagGyroSaturated) || !samples[i].gyro.allFinite()) {
      gyro_ok[i] = false;
      ++gyro_sat;
    }
  }
  if (accel_sat + gyro_sat > 0) {
    res.warnings.push_back(std::to_string(accel_sat) + " accelerometer and " + std::to_string(gyro_sat) +
                           " gyroscope samples are saturated or invalid: they were excluded (static "
                           "intervals never contain them and no gyro integration crosses them); if this "
                           "is frequent, raise the full-scale range or move the rig more gently");
  }
  if (gaps > 0) {
    res.warnings.push_back("the log has " + std::to_string(gaps) +
                           " gap(s) or device reset(s): static intervals are split there and no gyro "
                           "integration crosses them");
  }

  std::vector<Eigen::Vector3d> accel(n), gyro(n);
  for (std::size_t i = 0; i < n; ++i) {
    accel[i] = accel_ok[i] ? samples[i].accel : Eigen::Vector3d::Zero();
    gyro[i] = samples[i].gyro;
  }
  // Replace invalid accel values by their neighbours so that the running sums stay finite (they
  // are never part of a static interval).
  for (std::size_t i = 0; i < n; ++i) {
    if (!accel_ok[i]) accel[i] = i > 0 ? accel[i - 1] : Eigen::Vector3d::Zero();
  }

  // ---- static detector (eq. 3.9) ----
  auto t0 = Clock::now();
  const std::size_t window =
      std::max<std::size_t>(3, static_cast<std::size_t>(std::lround(opt.window_s * rate_hz)));
  const std::size_t half = window / 2;
  const std::vector<double> sigma_sq = variance_magnitude_sq(accel, window);
  std::vector<double> usable_sigma;
  usable_sigma.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (accel_ok[i]) usable_sigma.push_back(sigma_sq[i]);
  }
  const double floor_sq = std::max(percentile(usable_sigma, 0.1), 1e-300);

  // ---- initial still period ----
  auto time_of = [&](std::size_t i) { return ns_to_s(samples[i].t_ns - samples[0].t_ns); };
  std::size_t n_init = 0;
  if (opt.init_still_s > 0.0) {
    while (n_init < n && time_of(n_init) < opt.init_still_s) ++n_init;
    if (n_init >= n) {
      return make_error(Errc::kInvalidArgument, "the initial still period " + fmt("%.1f", opt.init_still_s) +
                                                    " s is longer than the recording (" +
                                                    fmt("%.1f", time_of(n - 1)) + " s)");
    }
    std::vector<double> inner;
    for (std::size_t i = std::min(half, n_init); i + half < n_init; ++i) inner.push_back(sigma_sq[i]);
    const double med = percentile(inner, 0.5);
    for (std::size_t i = 0; i < n_init; ++i) {
      const bool interior = i >= half && i + half < n_init;
      if ((interior && (sigma_sq[i] > 10.0 * med || sigma_sq[i] > 10.0 * floor_sq)) || !accel_ok[i] ||
          (i > 0 && reset_before[i])) {
        return make_error(Errc::kInsufficientData,
                          "the given initial still period is not still: the rig moves (or the log has a "
                          "device reset or saturation) at t = " +
                              fmt("%.2f", time_of(i)) +
                              " s. Give --init-still no longer than the still start, "
                              "or record again starting with the rig at rest for about 50 s");
      }
    }
  } else {
    std::size_t end = 0;
    // A gap (samples lost while the rig stays still) does not end the still start: the bias mean
    // and the white-noise level do not depend on it. A device reset does.
    while (end < n && accel_ok[end] && sigma_sq[end] <= 10.0 * floor_sq && (end == 0 || !reset_before[end]))
      ++end;
    const double still_s = end > 0 ? time_of(end - 1) : 0.0;
    if (still_s < opt.min_init_still_s) {
      return make_error(Errc::kInsufficientData,
                        "no still period at the start of the recording: the rig is still for only " +
                            fmt("%.1f", still_s) + " s (at least " + fmt("%.0f", opt.min_init_still_s) +
                            " s needed). Record again starting with the rig at rest for about 50 s, or give "
                            "--init-still if the start is still but noisier than the later poses");
    }
    auto curve = allan_deviation(std::span<const Eigen::Vector3d>(gyro.data(), end), rate_hz);
    if (!curve.ok()) return curve.error();
    const double t_init = choose_init_period_s(*curve, still_s);
    res.init_still_from_allan = true;
    while (n_init < end && time_of(n_init) <= t_init) ++n_init;
  }
  {
    int init_gaps = 0;
    for (std::size_t i = 1; i < n_init; ++i) init_gaps += break_before[i] ? 1 : 0;
    if (init_gaps > 0) {
      res.warnings.push_back("the initial still period contains " + std::to_string(init_gaps) +
                             " gap(s): its samples were used as one still period (bias mean and Allan "
                             "deviation); no integration crosses a gap");
    }
  }
  res.init_still_s = time_of(n_init - 1) + period_s;
  res.sigma_init_sq = variance_magnitude_sq_of(std::span<const Eigen::Vector3d>(accel.data(), n_init));
  Eigen::Vector3d gyro_bias_raw = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_sq = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n_init; ++i) gyro_bias_raw += gyro[i];
  gyro_bias_raw /= static_cast<double>(n_init);
  for (std::size_t i = 0; i < n_init; ++i) gyro_sq += (gyro[i] - gyro_bias_raw).cwiseAbs2();
  const Eigen::Vector3d gyro_bias_sigma =
      (gyro_sq / static_cast<double>(n_init - 1)).cwiseSqrt() / std::sqrt(static_cast<double>(n_init));
  res.timings.detector_s = seconds_since(t0);

  // ---- threshold search (Algorithm 1) ----
  t0 = Clock::now();
  const Eigen::Vector3d gyro_scale0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  std::vector<Eigen::Vector3d> accel_sum(n + 1), gyro_sum(n + 1);
  accel_sum[0].setZero();
  gyro_sum[0].setZero();
  const Eigen::Vector3d accel_center = accel[0];
  for (std::size_t i = 0; i < n; ++i) {
    accel_sum[i + 1] = accel_sum[i] + (accel[i] - accel_center);
    gyro_sum[i + 1] = gyro_sum[i] + (gyro[i] - gyro_bias_raw);
  }
  const std::size_t min_samples =
      std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(opt.min_interval_s * rate_hz)));
  const double max_rot_rad = opt.max_rotation_in_static_deg * M_PI / 180.0;

  struct Candidate {
    int multiplier = 0;
    std::vector<StaticInterval> intervals;
    std::vector<Eigen::Vector3d> means;
    AccelSolve solve;
    int distinct = 0;
    int rotated = 0;
  };
  std::optional<Candidate> best;
  int best_distinct_seen = 0;
  std::size_t best_intervals_seen = 0;
  for (int k = opt.multiplier_min; k <= opt.multiplier_max; ++k) {
    Candidate c;
    c.multiplier = k;
    const auto raw_intervals =
        detect_static_intervals(sigma_sq, k * res.sigma_init_sq, accel_ok, break_before, min_samples);
    for (const auto& iv : raw_intervals) {
      const double m = static_cast<double>(iv.size());
      const Eigen::Vector3d rot = gyro_scale0.cwiseProduct(gyro_sum[iv.end] - gyro_sum[iv.begin]) * period_s;
      if (rot.norm() > max_rot_rad) {
        ++c.rotated;
        continue;
      }
      c.intervals.push_back(iv);
      c.means.push_back((accel_sum[iv.end] - accel_sum[iv.begin]) / m + accel_center);
    }
    // Directions for counting attitudes: through the nominal conversion, else about the centre
    // of the means' bounding box.
    std::vector<Eigen::Vector3d> dirs;
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (const auto& m : c.means) {
      lo = lo.cwiseMin(m);
      hi = hi.cwiseMax(m);
    }
    for (const auto& m : c.means) {
      const Eigen::Vector3d d =
          opt.accel_init ? opt.accel_init->to_si(m) : Eigen::Vector3d(m - 0.5 * (lo + hi));
      dirs.push_back(d.normalized());
    }
    c.distinct = count_distinct(dirs, opt.distinct_attitude_deg * M_PI / 180.0);
    if (c.distinct > best_distinct_seen) {
      best_distinct_seen = c.distinct;
      best_intervals_seen = c.intervals.size();
    }
    if (c.distinct < opt.min_attitudes) continue;
    std::optional<TedaldiTriad> init;
    if (opt.accel_init) init = triad_from_conversion(*opt.accel_init);
    if (init) c.solve = solve_accel(c.means, opt.gravity_mps2, *init, nullptr);
    // A poor fit from the nominal guess (or no guess): start from the ellipsoid fit instead.
    if (!init || !c.solve.ok || c.solve.rms > 0.02 * opt.gravity_mps2 * opt.gravity_mps2) {
      auto ell = fit_ellipsoid(c.means, opt.gravity_mps2);
      if (ell.ok()) {
        AccelSolve s2 = solve_accel(c.means, opt.gravity_mps2, *ell, nullptr);
        if (s2.ok && (!c.solve.ok || s2.rms < c.solve.rms)) c.solve = s2;
      }
    }
    if (!c.solve.ok) continue;
    if (!best || c.solve.rms < best->solve.rms) best = std::move(c);
  }
  res.timings.threshold_search_s = seconds_since(t0);
  if (!best) {
    return make_error(Errc::kInsufficientData,
                      "found at most " + std::to_string(best_distinct_seen) + " distinct static attitudes (" +
                          std::to_string(best_intervals_seen) + " static intervals of at least " +
                          fmt("%.1f", opt.min_interval_s) + " s) with any threshold multiplier in [" +
                          std::to_string(opt.multiplier_min) + ", " + std::to_string(opt.multiplier_max) +
                          "]; at least " + std::to_string(opt.min_attitudes) + " are needed (" +
                          std::to_string(opt.recommended_attitudes) +
                          " or more recommended). Record again: after the still start, hold the rig still "
                          "for 1-4 s in 36-50 different attitudes, turning it between holds");
  }
  if (best->distinct < opt.recommended_attitudes) {
    res.warnings.push_back("only " + std::to_string(best->distinct) + " distinct attitudes were found (" +
                           std::to_string(opt.recommended_attitudes) +
                           " or more recommended, 36-50 ideal): the result is less certain, see the sigmas");
  }
  if (best->rotated > 0) {
    res.warnings.push_back(
        std::to_string(best->rotated) +
        " static interval(s) were dropped because the gyro shows rotation inside them (more "
        "than " +
        fmt("%.1f", opt.max_rotation_in_static_deg) + " deg): hold the poses steadier");
  }
  res.threshold_multiplier = best->multiplier;
  res.threshold = best->multiplier * res.sigma_init_sq;
  res.distinct_attitudes = best->distinct;

  // ---- accelerometer: final solve with covariance ----
  t0 = Clock::now();
  {
    const AccelSolve final =
        solve_accel(best->means, opt.gravity_mps2, accel_triad(best->solve.p), &res.accel_covariance);
    if (!final.ok) {
      return make_error(Errc::kSolverFailed,
                        "the accelerometer covariance could not be computed: the static attitudes do not "
                        "constrain all 9 parameters; record poses covering more directions");
    }
    res.model.accel = accel_triad(final.p);
    res.accel_residual_rms = final.rms;
    res.accel_iterations = best->solve.iterations + final.iterations;
    res.accel_sigma = accel_sigma(res.accel_covariance);
  }
  for (std::size_t k = 0; k < best->intervals.size(); ++k) {
    const auto& iv = best->intervals[k];
    res.intervals.push_back({samples[iv.begin].t_ns, samples[iv.end - 1].t_ns, iv.size(), best->means[k]});
  }
  res.timings.accel_s = seconds_since(t0);

  // ---- gyroscope ----
  t0 = Clock::now();
  std::vector<Transfer> transfers;
  int dropped = 0, dropped_gap = 0, dropped_sat = 0;
  for (std::size_t k = 0; k + 1 < best->intervals.size(); ++k) {
    const std::size_t a = best->intervals[k].end - 1;
    const std::size_t b = best->intervals[k + 1].begin;
    bool has_gap = false, has_sat = false;
    for (std::size_t i = a; i <= b; ++i) {
      has_sat = has_sat || !gyro_ok[i];
      has_gap = has_gap || (i > a && break_before[i]);
    }
    if (has_gap || has_sat) {
      ++dropped;
      dropped_gap += has_gap ? 1 : 0;
      dropped_sat += has_sat ? 1 : 0;
      continue;
    }
    Transfer tr;
    tr.gyro_raw.assign(gyro.begin() + static_cast<std::ptrdiff_t>(a),
                       gyro.begin() + static_cast<std::ptrdiff_t>(b) + 1);
    tr.t_s.resize(tr.gyro_raw.size());
    for (std::size_t i = a; i <= b; ++i) tr.t_s[i - a] = ns_to_s(samples[i].t_ns - samples[a].t_ns);
    tr.pose0 = k;
    transfers.push_back(std::move(tr));
  }
  if (dropped > 0) {
    res.warnings.push_back(
        std::to_string(dropped) + " motion(s) between static poses were not used for the " +
        "gyroscope: " + std::to_string(dropped_gap) + " contain a gap or a device reset, " +
        std::to_string(dropped_sat) + " contain saturated gyro samples");
  }
  res.gyro_transfers = static_cast<int>(transfers.size());
  const int min_transfers = opt.min_attitudes - 1;
  if (res.gyro_transfers < min_transfers) {
    return make_error(Errc::kInsufficientData,
                      "only " + std::to_string(res.gyro_transfers) + " of " +
                          std::to_string(res.gyro_transfers + dropped) +
                          " motions between consecutive static poses can be integrated (at least " +
                          std::to_string(min_transfers) + " needed for the gyroscope; " +
                          std::to_string(dropped_sat) + " contain saturated gyro samples (" +
                          std::to_string(gyro_sat) + " saturated in all), " + std::to_string(dropped_gap) +
                          " contain a gap or a device reset): turn the rig more slowly than the gyro "
                          "full-scale range (or raise it), avoid gaps, and record more poses");
  }

  TedaldiTriad gyro0;
  gyro0.scale = gyro_scale0;
  gyro0.bias = -gyro_bias_raw;
  Eigen::Matrix<double, 9, 1> gp;
  gp << gyro_angles(gyro0.T), gyro0.scale;
  Eigen::Vector3d gb = gyro0.bias;
  ceres::Problem problem;
  for (const auto& tr : transfers) {
    if (opt.estimate_gyro_bias) {
      problem.AddResidualBlock(new GyroTransferCost(&tr, nullptr), nullptr, gp.data(), gb.data());
    } else {
      problem.AddResidualBlock(new GyroTransferCost(&tr, &gyro0.bias), nullptr, gp.data());
    }
  }
  ceres::Solver::Options so = solver_options(50);
  so.function_tolerance = 1e-10;
  so.parameter_tolerance = 1e-10;
  ceres::Solver::Summary summary;
  // Two passes: the directions at the ends of the static intervals depend (weakly) on the gyro
  // model through the rotation inside the intervals; the second pass uses the first estimate.
  TedaldiTriad gyro_current = gyro0;
  for (int pass = 0; pass < 2; ++pass) {
    const auto dirs = pose_directions(best->intervals, accel, gyro, samples, res.model.accel, gyro_current);
    for (auto& tr : transfers) {
      tr.u0 = dirs[tr.pose0].u_end;
      tr.u1 = dirs[tr.pose0 + 1].u_start;
    }
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable() || !gp.allFinite()) {
      return make_error(Errc::kSolverFailed, "the gyroscope solve failed: " + summary.message);
    }
    res.gyro_iterations += static_cast<int>(summary.iterations.size());
    gyro_current.T = gyro_misalignment(gp.head<6>());
    gyro_current.scale = gp.tail<3>();
    gyro_current.bias = opt.estimate_gyro_bias ? gb : gyro0.bias;
  }
  const double m_res = 3.0 * static_cast<double>(transfers.size());
  const int n_par = opt.estimate_gyro_bias ? 12 : 9;
  res.gyro_residual_rms = std::sqrt(2.0 * summary.final_cost / m_res);
  res.model.gyro.T = gyro_misalignment(gp.head<6>());
  res.model.gyro.scale = gp.tail<3>();
  res.model.gyro.bias = opt.estimate_gyro_bias ? gb : gyro0.bias;
  {
    // One Jacobian evaluation at the solution serves both the covariance and the propagation of
    // the accelerometer uncertainty below. The covariance is (J^T J)^+ from the SVD of J, singular
    // values below sqrt(1e-14) of the largest being dropped (what ceres::Covariance does with
    // DENSE_SVD and automatic null-space truncation).
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = {gp.data()};
    if (opt.estimate_gyro_bias) eo.parameter_blocks.push_back(gb.data());
    eo.num_threads = 1;
    ceres::CRSMatrix crs;
    if (!problem.Evaluate(eo, nullptr, nullptr, nullptr, &crs) || crs.num_cols != n_par) {
      return make_error(Errc::kSolverFailed,
                        "the gyroscope covariance could not be computed: the motions between poses do not "
                        "constrain all gyro parameters; turn the rig about all three axes between poses");
    }
    Eigen::MatrixXd Jg = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
    for (int r = 0; r < crs.num_rows; ++r) {
      for (int idx = crs.rows[r]; idx < crs.rows[r + 1]; ++idx) Jg(r, crs.cols[idx]) = crs.values[idx];
    }
    {
      const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Jg, Eigen::ComputeThinV);
      const Eigen::VectorXd sv = svd.singularValues();
      Eigen::VectorXd inv_sq = Eigen::VectorXd::Zero(sv.size());
      const double min_ratio = std::sqrt(1e-14);
      for (Eigen::Index i = 0; i < sv.size(); ++i) {
        if (!(sv[i] / sv[0] >= min_ratio)) break;
        inv_sq[i] = 1.0 / (sv[i] * sv[i]);
      }
      res.gyro_covariance = svd.matrixV() * inv_sq.asDiagonal() * svd.matrixV().transpose();
    }
    res.gyro_covariance *= 2.0 * summary.final_cost / std::max(1.0, m_res - n_par);
    // The reference directions come from the calibrated accelerometer, whose errors are common
    // to all transfers: add their effect, D Sigma_a D^T with D = -(J_g^T J_g)^-1 J_g^T dr/dtheta_a
    // (Gauss-Newton sensitivity of the gyro solution; the small rotation inside the static
    // intervals is neglected in dr/dtheta_a).
    {
      const Vec9 pa = accel_params(res.model.accel);
      std::vector<Eigen::Matrix<double, 3, 9>> du(best->means.size());
      for (std::size_t k = 0; k < best->means.size(); ++k) {
        for (int i = 0; i < 9; ++i) {
          const double h = 1e-6 * std::max(1.0, std::abs(pa[i]));
          Vec9 pp = pa, pm = pa;
          pp[i] += h;
          pm[i] -= h;
          du[k].col(i) = (accel_triad(pp).apply(best->means[k]).normalized() -
                          accel_triad(pm).apply(best->means[k]).normalized()) /
                         (2 * h);
        }
      }
      const std::size_t m_rows = 3 * transfers.size();
      Eigen::MatrixXd Ja(m_rows, 9);
      const Eigen::Matrix3d A = res.model.gyro.TK();
      std::vector<Eigen::Vector3d> w;
      for (std::size_t t = 0; t < transfers.size(); ++t) {
        const auto& tr = transfers[t];
        w.resize(tr.gyro_raw.size());
        for (std::size_t i = 0; i < w.size(); ++i) w[i] = A * (tr.gyro_raw[i] + res.model.gyro.bias);
        const Eigen::Matrix3d R = quat_to_matrix(integrate_rk4n(w, tr.t_s));
        Ja.middleRows(3 * t, 3) = du[tr.pose0 + 1] - R.transpose() * du[tr.pose0];
      }
      {
        const Eigen::MatrixXd D = -(Jg.transpose() * Jg).ldlt().solve(Jg.transpose() * Ja);
        res.gyro_covariance += D * res.accel_covariance * D.transpose();
      }
    }
    const Eigen::VectorXd d = res.gyro_covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    res.gyro_sigma.T(0, 1) = d[0];
    res.gyro_sigma.T(0, 2) = d[1];
    res.gyro_sigma.T(1, 0) = d[2];
    res.gyro_sigma.T(1, 2) = d[3];
    res.gyro_sigma.T(2, 0) = d[4];
    res.gyro_sigma.T(2, 1) = d[5];
    res.gyro_sigma.scale = d.segment<3>(6);
    res.gyro_sigma.bias = opt.estimate_gyro_bias ? Eigen::Vector3d(d.tail<3>()) : gyro_bias_sigma;
  }
  res.timings.gyro_s = seconds_since(t0);

  // ---- quality figures (4.1.1) ----
  std::vector<GravityTransfer> checks;
  for (const auto& tr : transfers) checks.push_back({tr.u0, tr.u1, tr.gyro_raw, tr.t_s});
  res.quality.accel_after = gravity_magnitude_error(best->means, res.model.accel, opt.gravity_mps2);
  res.quality.gyro_after = gravity_direction_error(checks, res.model.gyro, opt.gravity_mps2);
  TedaldiTriad gyro_nominal;
  gyro_nominal.scale = gyro_scale0;
  gyro_nominal.bias = opt.gyro_init ? Eigen::Vector3d(-opt.gyro_init->offset) : Eigen::Vector3d::Zero();
  if (opt.accel_init) {
    res.quality.before_available = true;
    const TedaldiTriad accel_nominal = triad_from_conversion(*opt.accel_init);
    res.quality.accel_before = gravity_magnitude_error(best->means, accel_nominal, opt.gravity_mps2);
    // Gravity directions from the nominal accelerometer, rates from the nominal gyro.
    std::vector<GravityTransfer> nominal = checks;
    const auto dirs = pose_directions(best->intervals, accel, gyro, samples, accel_nominal, gyro0);
    for (std::size_t k = 0; k < nominal.size(); ++k) {
      nominal[k].u0 = dirs[transfers[k].pose0].u_end;
      nominal[k].u1 = dirs[transfers[k].pose0 + 1].u_start;
    }
    res.quality.gyro_before = gravity_direction_error(nominal, gyro_nominal, opt.gravity_mps2);
  }
  res.canonical = canonical_from_tedaldi(res.model);
  return res;
}

}  // namespace imucal::calib
