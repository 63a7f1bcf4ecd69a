#include "calib/static_calibration.hpp"

#include <ceres/ceres.h>
#include <time.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <limits>
#include <memory>
#include <string>

#include "calib/allan.hpp"
#include "calib/ellipsoid.hpp"
#include "calib/gravity.hpp"
#include "calib/gsens_calibration.hpp"
#include "calib/rk4.hpp"
#include "calib/static_detector.hpp"
#include "calib/static_faces.hpp"
#include "calib/static_steps.hpp"
#include "core/threads.hpp"

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

/// Magnitude form (eq. 3.4) from `init`; with fix_misalignment the three angles stay as given
/// (the scale-bias form: 6 parameters).
AccelSolve solve_accel(std::span<const Eigen::Vector3d> means, double g, const TedaldiTriad& init,
                       Eigen::MatrixXd* covariance, bool fix_misalignment = false) {
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
  if (fix_misalignment) problem.SetManifold(pn.data(), new ceres::SubsetManifold(9, {0, 1, 2}));
  const double fitted = fix_misalignment ? 6.0 : 9.0;
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
      // With no degrees of freedom left the residual variance, and so every sigma, is unknown.
      const double scale =
          n > fitted ? 2.0 * out.cost / (n - fitted) : std::numeric_limits<double>::quiet_NaN();
      *covariance = c.asDiagonal() * Eigen::Matrix<double, 9, 9>(cn) * c.asDiagonal() * scale;
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
  // Set before every solve; initialised so that copies of a fresh transfer read defined values.
  Eigen::Vector3d u0 = Eigen::Vector3d::Zero(), u1 = Eigen::Vector3d::Zero();
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
/// is exact: reverse-mode differentiation of the RK4n recursion (calib/rk4.hpp); or, with
/// set_first_order(true), the first-order one (calib/rk4.hpp), several times cheaper.
class GyroTransferCost : public ceres::CostFunction {
 public:
  /// With `on`, the rate derivatives are the first-order ones (rate_gradient_first_order, about
  /// h w from the exact ones: 1.4e-3 relative at 2 rad/s and 100 Hz), several times cheaper.
  /// Good enough to steer the solver near the minimum; never used for its last steps or for the
  /// covariance, so the solution and its sigmas are those of the exact Jacobian.
  void set_first_order(bool on) { first_order_ = on; }

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
    // The covariance asks again for the Jacobian the solver's last accepted step evaluated.
    Eigen::Matrix<double, 18, 1> jac_key;
    jac_key << key, tr_->u0, tr_->u1;
    if (want_jacobian && !first_order_ && jac_valid_ && jac_key == jac_key_)
      return write_saved(residuals, jacobians);
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
    if (want_jacobian && first_order_) {
      rate_gradient_first_order(q_buf_, tr_->t_s, u0, grad_.df_dw);
    } else if (want_jacobian) {
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
    Eigen::Matrix<double, 3, 9>& J = J_saved_;
    J.col(0) = -s[1] * J_A.col(1);  // T(0,1) = -gamma_yz
    J.col(1) = s[2] * J_A.col(2);   // T(0,2) =  gamma_zy
    J.col(2) = s[0] * J_A.col(3);   // T(1,0) =  gamma_xz
    J.col(3) = -s[2] * J_A.col(5);  // T(1,2) = -gamma_zx
    J.col(4) = -s[0] * J_A.col(6);  // T(2,0) = -gamma_xy
    J.col(5) = s[1] * J_A.col(7);   // T(2,1) =  gamma_yx
    for (int c = 0; c < 3; ++c) {
      J.col(6 + c) = Tg(0, c) * J_A.col(c) + Tg(1, c) * J_A.col(3 + c) + Tg(2, c) * J_A.col(6 + c);
    }
    Jb_saved_ = sum_G * A;
    r_saved_ = r;
    jac_key_ = jac_key;
    jac_valid_ = !first_order_;  // only an exact Jacobian is kept for the covariance
    return write_saved(residuals, jacobians);
  }

 private:
  bool write_saved(double* residuals, double** jacobians) const {
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = r_saved_;
    if (jacobians[0]) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jacobians[0]);
      J = J_saved_;
    }
    if (!fixed_bias_ && jacobians[1]) {
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> Jb(jacobians[1]);
      Jb = Jb_saved_;
    }
    return true;
  }

  const Transfer* tr_;
  const Eigen::Vector3d* fixed_bias_;
  bool first_order_ = false;
  // Scratch, reused between evaluations (one thread at a time evaluates a transfer).
  mutable std::vector<Eigen::Vector3d> w_;
  mutable std::vector<Quat4> q_buf_;
  mutable Rk4nGradient grad_;
  mutable Eigen::Matrix<double, 12, 1> cache_key_ = Eigen::Matrix<double, 12, 1>::Zero();
  mutable bool cache_valid_ = false;
  // The last Jacobian, its residual and its point (parameters and the two directions).
  mutable Eigen::Matrix<double, 18, 1> jac_key_ = Eigen::Matrix<double, 18, 1>::Zero();
  mutable bool jac_valid_ = false;
  mutable Eigen::Vector3d r_saved_ = Eigen::Vector3d::Zero();
  mutable Eigen::Matrix<double, 3, 9> J_saved_ = Eigen::Matrix<double, 3, 9>::Zero();
  mutable Eigen::Matrix3d Jb_saved_ = Eigen::Matrix3d::Zero();
};

/// Consecutive runs of items of about equal total work for up to `threads` threads: run r covers
/// items [begin[r], begin[r + 1]). The split depends on the work and the thread count only, so
/// what each item computes does not depend on the threads' timing.
std::vector<std::size_t> equal_work_runs(const std::vector<std::size_t>& work, int threads) {
  std::size_t total = 0;
  for (const std::size_t w : work) total += w;
  const std::size_t runs = std::clamp<std::size_t>(static_cast<std::size_t>(std::max(threads, 1)), 1,
                                                   std::max<std::size_t>(work.size(), 1));
  std::vector<std::size_t> begin{0};
  std::size_t done = 0;
  for (std::size_t k = 0; k < work.size(); ++k) {
    done += work[k];
    if (begin.size() < runs && done * runs >= total * begin.size()) begin.push_back(k + 1);
  }
  begin.push_back(work.size());
  return begin;
}

/// Calls each(k) for every item of the runs, the first run on the calling thread and each other
/// on a thread of its own; false when any call returned false.
template <class Each>
bool for_each_in_runs(const std::vector<std::size_t>& begin, const Each& each) {
  const auto run = [&](std::size_t r) {
    bool ok = true;
    for (std::size_t k = begin[r]; k < begin[r + 1]; ++k) ok = each(k) && ok;
    return ok;
  };
  std::vector<std::future<bool>> others;
  for (std::size_t r = 1; r + 1 < begin.size(); ++r) others.push_back(std::async(std::launch::async, run, r));
  bool ok = run(0);
  for (auto& f : others) ok = f.get() && ok;
  return ok;
}

/// Every transfer's residuals as one block, evaluated on up to `threads` threads, each over a
/// fixed run of consecutive transfers and writing only their rows. The residuals, Jacobian and
/// so the whole solve are the same whatever the number of threads or their timing (the solver's
/// own parallel evaluation sums the cost in the order the threads finish).
class GyroTransfersCost : public ceres::CostFunction {
 public:
  GyroTransfersCost(const std::vector<Transfer>& transfers, const Eigen::Vector3d* fixed_bias, int threads)
      : with_bias_(fixed_bias == nullptr) {
    std::vector<std::size_t> samples;  // the work: one integration step per sample
    for (const auto& tr : transfers) {
      parts_.push_back(std::make_unique<GyroTransferCost>(&tr, fixed_bias));
      samples.push_back(tr.gyro_raw.size());
    }
    set_num_residuals(3 * static_cast<int>(transfers.size()));
    mutable_parameter_block_sizes()->push_back(9);
    if (with_bias_) mutable_parameter_block_sizes()->push_back(3);
    run_begin_ = equal_work_runs(samples, threads);
  }

  void set_first_order(bool on) {
    for (auto& part : parts_) part->set_first_order(on);
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    return for_each_in_runs(run_begin_, [&](std::size_t t) {
      double* jac[2] = {nullptr, nullptr};
      if (jacobians) {
        if (jacobians[0]) jac[0] = jacobians[0] + 27 * t;
        if (with_bias_ && jacobians[1]) jac[1] = jacobians[1] + 9 * t;
      }
      return parts_[t]->Evaluate(parameters, residuals + 3 * t, jacobians ? jac : nullptr);
    });
  }

 private:
  bool with_bias_;
  std::vector<std::unique_ptr<GyroTransferCost>> parts_;
  std::vector<std::size_t> run_begin_;  // run r covers transfers [run_begin_[r], run_begin_[r + 1])
};

// ---- helpers ---------------------------------------------------------------------------------

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

/// Square roots of a covariance's diagonal; NaN (undetermined) stays NaN.
Eigen::VectorXd sigmas_of(const Eigen::MatrixXd& cov) {
  return cov.diagonal().unaryExpr([](double v) { return std::isnan(v) ? v : std::sqrt(std::max(v, 0.0)); });
}

TriadSigma accel_sigma(const Eigen::MatrixXd& cov) {
  TriadSigma s;
  const Eigen::VectorXd d = sigmas_of(cov);
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
                                            const TedaldiTriad& accel_model, const TedaldiTriad& gyro_model,
                                            int threads) {
  std::vector<PoseDirections> out(intervals.size());
  const Eigen::Matrix3d Aa = accel_model.TK(), Ag = gyro_model.TK();
  // Each interval is independent of the others: runs of them of about equal sample counts on
  // the threads give the same directions as one thread.
  std::vector<std::size_t> work;
  for (const auto& iv : intervals) work.push_back(iv.size());
  for_each_in_runs(equal_work_runs(work, threads), [&](std::size_t k) {
    const StaticInterval& iv = intervals[k];
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
    out[k] = {sum.normalized(), (R.transpose() * sum).normalized()};
    return true;
  });
  return out;
}

}  // namespace

// ---- steps of calibrate_static, in the order it runs them ------------------------------------

namespace {

double seconds_from_start(std::span<const ImuSample> samples, std::size_t i) {
  return ns_to_s(samples[i].t_ns - samples[0].t_ns);
}

/// Samples of the given initial still period, refused when the rig moves in it (by the same
/// absolute criterion as the automatic still start, StaticDetection::moving).
Result<std::size_t> given_still_start(std::span<const ImuSample> samples, const ScannedRecording& scan,
                                      const StaticDetection& det, double init_still_s,
                                      double min_init_still_s) {
  const std::size_t n = samples.size();
  if (init_still_s < min_init_still_s) {
    return make_error(Errc::kInvalidArgument,
                      "the initial still period " + fmt("%.1f", init_still_s) + " s is too short: at least " +
                          fmt("%.0f", min_init_still_s) +
                          " s are needed for the bias and the noise level (the protocol asks for about 50 s)")
        .with_remedy("init_still_s");
  }
  std::size_t n_init = 0;
  while (n_init < n && seconds_from_start(samples, n_init) < init_still_s) ++n_init;
  if (n_init >= n) {
    return make_error(Errc::kInvalidArgument, "the initial still period " + fmt("%.1f", init_still_s) +
                                                  " s is longer than the recording (" +
                                                  fmt("%.1f", seconds_from_start(samples, n - 1)) + " s)");
  }
  for (std::size_t i = 0; i < n_init; ++i) {
    const bool interior = i >= det.half && i + det.half < n_init;
    if ((interior && det.moving(i)) || !scan.accel_ok[i] || !scan.gyro_ok[i] ||
        (i > 0 && scan.reset_before[i])) {
      return make_error(Errc::kInsufficientData,
                        "the given initial still period is not still: the rig moves (or the log has a "
                        "device reset or saturation) at t = " +
                            fmt("%.2f", seconds_from_start(samples, i)) +
                            " s. Give an initial still period (init_still_s) no longer than that, or "
                            "record again starting with the rig at rest for about 50 s")
          .with_remedy("init_still_s");
    }
  }
  return n_init;
}

/// Samples of the still start found by the detector, its length chosen from the gyroscope Allan
/// deviation (section 3.4.3).
Result<std::size_t> automatic_still_start(std::span<const ImuSample> samples, const ScannedRecording& scan,
                                          const StaticDetection& det, double min_init_still_s) {
  const std::size_t n = samples.size();
  std::size_t end = 0;
  // A gap (samples lost while the rig stays still) does not end the still start: the bias mean
  // and the white-noise level do not depend on it. A device reset does.
  while (end < n && scan.accel_ok[end] && scan.gyro_ok[end] && !det.moving(end) &&
         (end == 0 || !scan.reset_before[end]))
    ++end;
  const double still_s = end > 0 ? seconds_from_start(samples, end - 1) : 0.0;
  if (still_s < min_init_still_s) {
    return make_error(Errc::kInsufficientData,
                      "no still period at the start of the recording: the rig is still for only " +
                          fmt("%.1f", still_s) + " s (at least " + fmt("%.0f", min_init_still_s) +
                          " s needed; it moves at t = " + fmt("%.2f", still_s) +
                          " s, where both sensors' variance exceeds 10 times their quietest level). "
                          "Record again starting with the rig at rest for about 50 s")
        .with_remedy("init_still_s");
  }
  auto curve = allan_deviation(std::span<const Eigen::Vector3d>(scan.gyro.data(), end), scan.rate_hz);
  if (!curve.ok()) return curve.error();
  const double t_init = choose_init_period_s(*curve, still_s);
  std::size_t n_init = 0;
  while (n_init < end && seconds_from_start(samples, n_init) <= t_init) ++n_init;
  return n_init;
}

}  // namespace

Result<StillStart> find_still_start(std::span<const ImuSample> samples, const ScannedRecording& scan,
                                    const StaticDetection& detection, const StaticCalibrationOptions& opt,
                                    std::vector<std::string>* warnings) {
  StillStart still;
  still.from_allan = !(opt.init_still_s > 0.0);
  Result<std::size_t> found =
      still.from_allan ? automatic_still_start(samples, scan, detection, opt.min_init_still_s)
                       : given_still_start(samples, scan, detection, opt.init_still_s, opt.min_init_still_s);
  if (!found.ok()) return found.error();
  const std::size_t n_init = *found;
  int init_gaps = 0;
  for (std::size_t i = 1; i < n_init; ++i) init_gaps += scan.break_before[i] ? 1 : 0;
  if (init_gaps > 0) {
    warnings->push_back("the initial still period contains " + std::to_string(init_gaps) +
                        " gap(s): its samples were used as one still period (bias mean and Allan "
                        "deviation); no integration crosses a gap");
  }
  still.samples = n_init;
  still.length_s = seconds_from_start(samples, n_init - 1) + scan.period_s;
  if (still.length_s < 10.0) {
    warnings->push_back("the still start is only " + fmt("%.1f", still.length_s) +
                        " s: the noise level that sets the static threshold and the Allan check of the "
                        "bias rest on few samples; record about 50 s of rest before the first pose");
  }
  still.sigma_init_sq = variance_magnitude_sq_of(std::span<const Eigen::Vector3d>(scan.accel.data(), n_init));
  Eigen::Vector3d gyro_sq = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n_init; ++i) {
    still.gyro_bias_raw += scan.gyro[i];
    still.accel_mean_raw += scan.accel[i] - scan.accel[0];
  }
  still.gyro_bias_raw /= static_cast<double>(n_init);
  still.accel_mean_raw = still.accel_mean_raw / static_cast<double>(n_init) + scan.accel[0];
  for (std::size_t i = 0; i < n_init; ++i) gyro_sq += (scan.gyro[i] - still.gyro_bias_raw).cwiseAbs2();
  still.gyro_bias_sigma =
      (gyro_sq / static_cast<double>(n_init - 1)).cwiseSqrt() / std::sqrt(static_cast<double>(n_init));
  // The mean stands for the bias over the whole session, which wanders (random walk, bias
  // instability): its uncertainty is at least the Allan deviation at the longest averaging time
  // the still start supports, not only the white noise over sqrt(n).
  auto curve = allan_deviation(std::span<const Eigen::Vector3d>(scan.gyro.data(), n_init), scan.rate_hz);
  if (curve.ok() && !curve->adev.empty())
    still.gyro_bias_sigma = still.gyro_bias_sigma.cwiseMax(curve->adev.back());
  return still;
}

Eigen::MatrixXd normal_pseudo_inverse(const Eigen::MatrixXd& J) {
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  Eigen::VectorXd inv_sq = Eigen::VectorXd::Zero(sv.size());
  const double min_ratio = std::sqrt(1e-14);
  for (Eigen::Index i = 0; i < sv.size(); ++i) {
    if (!(sv[i] / sv[0] >= min_ratio)) break;
    inv_sq[i] = 1.0 / (sv[i] * sv[i]);
  }
  return svd.matrixV() * inv_sq.asDiagonal() * svd.matrixV().transpose();
}

namespace {

// ---- threshold search (Algorithm 1) ----------------------------------------------------------

/// Prefix sums over the whole recording, so that the mean of any interval costs O(1) for every
/// multiplier tried: accelerometer values about the first one (no precision lost on raw counts
/// with large offsets) and gyro rates about the still-period bias (for the rotation check).
struct PrefixSums {
  std::vector<Eigen::Vector3d> accel, gyro;
  Eigen::Vector3d accel_center = Eigen::Vector3d::Zero();
};

PrefixSums prefix_sums(const ScannedRecording& scan, const Eigen::Vector3d& gyro_bias_raw) {
  const std::size_t n = scan.accel.size();
  PrefixSums p;
  p.accel.resize(n + 1);
  p.gyro.resize(n + 1);
  p.accel[0].setZero();
  p.gyro[0].setZero();
  p.accel_center = scan.accel[0];
  for (std::size_t i = 0; i < n; ++i) {
    p.accel[i + 1] = p.accel[i] + (scan.accel[i] - p.accel_center);
    p.gyro[i + 1] = p.gyro[i] + (scan.gyro[i] - gyro_bias_raw);
  }
  return p;
}

/// The gyroscope at rest: the mean of still pose k is b_g + H a_k + noise (the bias, the
/// g-sensitivity H = A_g^-1 G in input units per m/s^2 acting on the calibrated specific force
/// a_k, and whatever rotation or bias drift the pose holds). One linear fit per axis over the
/// still start and every pose, unweighted, its covariance scaled by the residual variance.
struct GyroStaticFit {
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();  // b_g over the session, input units (canonical sign)
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  /// Bias drift over the session: b(t) = bias + drift_at(t), a quadratic in
  /// tau = (t - t_mid_s) / t_half_s that averages to zero over the poses' span (zero when not fitted).
  Eigen::Matrix<double, 3, 2> drift = Eigen::Matrix<double, 3, 2>::Zero();
  double t_mid_s = 0.0, t_half_s = 1.0;
  Eigen::Vector3d drift_offset = Eigen::Vector3d::Zero();  // makes the drift average to 0
  Eigen::Vector3d drift_at(double t_s) const {
    const double tau = (t_s - t_mid_s) / t_half_s;
    return drift.col(0) * tau + drift.col(1) * tau * tau + drift_offset;
  }
  Eigen::Vector3d bias_sigma = Eigen::Vector3d::Zero();
  Eigen::Matrix3d H_sigma = Eigen::Matrix3d::Zero();
  FitDof dof;
  double rms = 0.0;                       // of the residual rates, input units
  std::vector<Eigen::Vector3d> residual;  // per pose: mean - b_g - H a
};

/// The still start's and the poses' means (the still start first) and their mid times.
struct PoseMeans {
  std::vector<Eigen::Vector3d> gyro, accel_si;
  std::vector<double> t_s;
};

/// Bias drift terms fitted with `poses` means: a quadratic in time once there are enough poses
/// to spare the degrees of freedom, then a line, then none.
int drift_terms(std::size_t poses) { return poses >= 20 ? 2 : poses >= 12 ? 1 : 0; }

/// Newey-West covariances of a least-squares fit Y = X beta + R, one per column of R (Bartlett
/// weights, lag 4 (n/100)^(2/9)), with leverage-inflated residuals (HC3: the sandwich is otherwise
/// too small for the few tens of poses a session has) and Stata's degrees-of-freedom factor
/// n / (n - p).
std::vector<Eigen::MatrixXd> newey_west_covariances(const Eigen::MatrixXd& X, const Eigen::MatrixXd& R,
                                                    const Eigen::MatrixXd& XtX_inv, int dof) {
  const auto n = static_cast<std::size_t>(X.rows());
  const Eigen::Index p = X.cols();
  const int lag = static_cast<int>(std::floor(4.0 * std::pow(static_cast<double>(n) / 100.0, 2.0 / 9.0)));
  Eigen::MatrixXd Ra = R;
  for (std::size_t k = 0; k < n; ++k) {
    const double h = X.row(k) * XtX_inv * X.row(k).transpose();
    Ra.row(k) /= std::max(1.0 - h, 0.05);
  }
  std::vector<Eigen::MatrixXd> out;
  for (Eigen::Index col = 0; col < R.cols(); ++col) {
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(p, p);
    for (std::size_t k = 0; k < n; ++k) S += Ra(k, col) * Ra(k, col) * X.row(k).transpose() * X.row(k);
    for (int l = 1; l <= lag; ++l) {
      const double w = 1.0 - static_cast<double>(l) / (lag + 1.0);
      for (std::size_t k = static_cast<std::size_t>(l); k < n; ++k) {
        const Eigen::MatrixXd xx = X.row(k).transpose() * X.row(k - l);
        S += w * Ra(k, col) * Ra(k - l, col) * (xx + xx.transpose());
      }
    }
    out.push_back(XtX_inv * S * XtX_inv * (static_cast<double>(n) / std::max(1, dof)));
  }
  return out;
}

GyroStaticFit fit_gyro_static(const PoseMeans& m, const StillStart& still, GSensitivityMode mode,
                              const Eigen::Matrix3d& H_fixed) {
  GyroStaticFit f;
  const auto& gyro_means = m.gyro;
  const auto& accel_si = m.accel_si;
  const std::size_t n = gyro_means.size();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (mode == GSensitivityMode::kEstimate) {
    // Regressors [1, a, tau, tau^2]: the bias wanders over a session (random walk, warm-up) by as
    // much as the g-sensitivity moves the pose means, so a smooth drift is fitted with them.
    const int nd = drift_terms(n);
    const int p = 4 + nd;
    const auto [t_lo, t_hi] = std::minmax_element(m.t_s.begin(), m.t_s.end());
    f.t_mid_s = 0.5 * (*t_lo + *t_hi);
    f.t_half_s = std::max(0.5 * (*t_hi - *t_lo), 1e-9);
    Eigen::MatrixXd X(n, p), Y(n, 3);
    for (std::size_t k = 0; k < n; ++k) {
      const double tau = (m.t_s[k] - f.t_mid_s) / f.t_half_s;
      X(k, 0) = 1.0;
      X.row(k).segment<3>(1) = accel_si[k].transpose();
      for (int d = 0; d < nd; ++d) X(k, 4 + d) = std::pow(tau, d + 1);
      Y.row(k) = gyro_means[k].transpose();
    }
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(X);
    const Eigen::MatrixXd beta = qr.solve(Y);  // p x 3: [b; H^T; drift]
    f.bias = beta.row(0).transpose();
    f.H = beta.middleRows(1, 3).transpose();
    for (int d = 0; d < nd; ++d) f.drift.col(d) = beta.row(4 + d).transpose();
    // Report the bias averaged over the span (see the sigma below) and keep the drift about it.
    if (nd == 2) {
      f.bias += f.drift.col(1) / 3.0;
      f.drift_offset = -f.drift.col(1) / 3.0;
    }
    f.dof = {static_cast<int>(n), p};
    const Eigen::MatrixXd R = Y - X * beta;
    const bool full_rank = qr.rank() == p;
    const Eigen::MatrixXd XtX_inv =
        full_rank ? Eigen::MatrixXd((X.transpose() * X).inverse()) : Eigen::MatrixXd::Constant(p, p, nan);
    // The pose errors are not independent: the bias wanders (a random walk) and consecutive poses
    // are close in attitude, so errors and regressors are both correlated from pose to pose, and
    // the textbook s^2 (X'X)^-1 is too small (by about 2 on the virtual rig). Newey-West's
    // covariance (Bartlett weights, lag 4 (n/100)^(2/9)) holds with such errors. Undetermined
    // (NaN) without degrees of freedom.
    const std::vector<Eigen::MatrixXd> cov = newey_west_covariances(X, R, XtX_inv, f.dof.dof());
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::MatrixXd& V = cov[static_cast<std::size_t>(axis)];
      const Eigen::VectorXd sd = V.diagonal().unaryExpr([](double v) { return std::sqrt(std::max(v, 0.0)); });
      // The reported bias is b(t) averaged over the span of the poses (tau uniform in [-1, 1]:
      // mean tau 0, mean tau^2 1/3), the bias a user of the whole recording saw.
      Eigen::VectorXd l = Eigen::VectorXd::Zero(p);
      l[0] = 1.0;
      if (nd == 2) l[5] = 1.0 / 3.0;
      f.bias_sigma[axis] = std::sqrt(std::max(l.dot(V * l), 0.0));
      if (!f.dof.determined()) {
        f.bias_sigma[axis] = nan;
        f.H_sigma.row(axis).setConstant(nan);
        continue;
      }
      f.H_sigma.row(axis) = sd.segment<3>(1).transpose();
    }
    if (!full_rank) f.H_sigma.setConstant(nan);
  } else {
    f.H = mode == GSensitivityMode::kFixed ? H_fixed : Eigen::Matrix3d::Zero();
    if (mode == GSensitivityMode::kFixed) {
      for (std::size_t k = 0; k < n; ++k) f.bias += gyro_means[k] - f.H * accel_si[k];
      f.bias /= static_cast<double>(n);
      f.dof = {static_cast<int>(n), 1};
    } else {
      f.bias = still.gyro_bias_raw;
      f.bias_sigma = still.gyro_bias_sigma;
      f.dof = {static_cast<int>(n), 0};
    }
  }
  f.residual.resize(n);
  double sum_sq = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    f.residual[k] = gyro_means[k] - f.bias - f.H * accel_si[k] - f.drift_at(m.t_s[k]);
    sum_sq += f.residual[k].squaredNorm();
  }
  f.rms = std::sqrt(sum_sq / (3.0 * static_cast<double>(std::max<std::size_t>(n, 1))));
  if (mode == GSensitivityMode::kFixed) {
    for (int axis = 0; axis < 3; ++axis) {
      double ss = 0.0;
      for (std::size_t k = 0; k < n; ++k) ss += f.residual[k][axis] * f.residual[k][axis];
      f.bias_sigma[axis] = n > 1 ? std::sqrt(ss / static_cast<double>(n - 1) / static_cast<double>(n)) : nan;
    }
  }
  return f;
}

/// The static poses found with one threshold multiplier and the accelerometer fitted to them.
struct Candidate {
  int multiplier = 0;
  std::vector<StaticInterval> intervals;
  std::vector<Eigen::Vector3d> means;       // accelerometer, input units
  std::vector<Eigen::Vector3d> gyro_means;  // gyroscope, input units
  AccelSolve solve;
  GyroStaticFit gyro;  // with the still start as its first pose
  int distinct = 0;
  std::vector<int> faces;           // the face each pose lies on (-1: none)
  int rotated = 0;                  // intervals dropped for rotation inside them
  double worst_rotation_deg = 0.0;  // of the dropped ones
};

using AccelModel = StaticCalibrationOptions::AccelModel;

/// The static means' directions: through the nominal conversion, else about the centre of the
/// means' bounding box.
std::vector<Eigen::Vector3d> attitude_directions(const std::vector<Eigen::Vector3d>& means,
                                                 const StaticCalibrationOptions& opt) {
  std::vector<Eigen::Vector3d> dirs;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& m : means) {
    lo = lo.cwiseMin(m);
    hi = hi.cwiseMax(m);
  }
  for (const auto& m : means) {
    const Eigen::Vector3d d =
        opt.accel_init ? opt.accel_init->to_si(m) : Eigen::Vector3d(m - 0.5 * (lo + hi));
    dirs.push_back(d.normalized());
  }
  return dirs;
}

/// Sets the candidate's distinct attitudes and faces; true when there are enough for `model`.
bool enough_attitudes(Candidate* c, AccelModel model, const StaticCalibrationOptions& opt) {
  const auto dirs = attitude_directions(c->means, opt);
  c->distinct = count_distinct(dirs, opt.distinct_attitude_deg * M_PI / 180.0);
  c->faces = assign_faces(dirs, opt.face_max_angle_deg * M_PI / 180.0);
  switch (model) {
    case AccelModel::kFaces:
      return missing_faces_in_words(face_counts(c->faces)).empty();
    case AccelModel::kScaleBias:
      return c->distinct >= opt.min_attitudes_scale_bias;
    default:
      return c->distinct >= opt.min_attitudes;
  }
}

/// Known-orientation form: the scales and biases are fitted again to the gravity magnitude (with
/// the faces' misalignment held) when the poses leave that fit at least 3 degrees of freedom; with
/// one pose per face the faces' fit is the whole result.
bool magnitude_after_faces(std::size_t poses) { return poses >= 9; }

/// Accelerometer fit (no covariance) of `model`. The magnitude forms start from the nominal
/// guess, or from the ellipsoid fit when there is no guess or it fits poorly; the known-orientation
/// form is linear. The rms is always that of eq. 3.4, so that multipliers compare alike.
AccelSolve first_accel_solve(const Candidate& c, AccelModel model, const StaticCalibrationOptions& opt) {
  const auto& means = c.means;
  if (model == AccelModel::kFaces) {
    // The faces give the misalignment, which the magnitude cannot see with so few attitudes; the
    // scales and biases come from the magnitude, which does not depend on how flat the faces lay.
    const KnownOrientationFit fit = fit_known_orientation(means, c.faces, opt.gravity_mps2);
    if (!fit.ok) return {};
    if (magnitude_after_faces(means.size()))
      return solve_accel(means, opt.gravity_mps2, fit.triad, nullptr, true);
    AccelSolve solve;  // one pose per face: the faces alone
    solve.p = accel_params(fit.triad);
    double ss = 0.0;
    for (const auto& m : means) {
      const double r = opt.gravity_mps2 * opt.gravity_mps2 - fit.triad.apply(m).squaredNorm();
      ss += r * r;
    }
    solve.cost = 0.5 * ss;
    solve.rms = std::sqrt(ss / static_cast<double>(means.size()));
    solve.ok = std::isfinite(solve.rms);
    return solve;
  }
  const bool fix = model == AccelModel::kScaleBias;
  const auto level = [fix](TedaldiTriad t) {
    if (fix) t.T.setIdentity();
    return t;
  };
  AccelSolve solve;
  std::optional<TedaldiTriad> init;
  if (opt.accel_init) init = triad_from_conversion(*opt.accel_init);
  if (init) solve = solve_accel(means, opt.gravity_mps2, level(*init), nullptr, fix);
  if (!init || !solve.ok || solve.rms > 0.02 * opt.gravity_mps2 * opt.gravity_mps2) {
    auto ell = fit_ellipsoid(means, opt.gravity_mps2);
    if (ell.ok()) {
      AccelSolve s2 = solve_accel(means, opt.gravity_mps2, level(*ell), nullptr, fix);
      if (s2.ok && (!solve.ok || s2.rms < solve.rms)) solve = s2;
    }
  }
  return solve;
}

/// Everything the threshold search reads.
struct SearchInput {
  const ScannedRecording& scan;
  const StaticDetection& detection;
  const StillStart& still;
  const PrefixSums& sums;
  std::size_t min_samples = 0;
  double max_rot_rad = 0.0;
  Eigen::Vector3d gyro_scale0 = Eigen::Vector3d::Ones();
  Eigen::Matrix3d H_fixed = Eigen::Matrix3d::Zero();  // input units per m/s^2, when G is given
  AccelModel model = AccelModel::kFull;
};

/// The g-sensitivity treatment used with `poses` static poses: an estimate needs enough of them.
GSensitivityMode effective_gsens(const StaticCalibrationOptions& opt, const Candidate& c) {
  const std::size_t poses = c.means.size();
  // Poses on all six faces determine G with few of them (the six-face experiment of Krebs
  // 5.2.3): each axis is seen at +g and -g.
  const bool six_faces = missing_faces_in_words(face_counts(c.faces)).empty();
  if (opt.gsens == GSensitivityMode::kEstimate && poses < static_cast<std::size_t>(opt.min_poses_for_gsens) &&
      !six_faces) {
    return GSensitivityMode::kOff;
  }
  return opt.gsens;
}

/// The still start's and a candidate's pose means, the accelerometer's calibrated with `accel`.
PoseMeans pose_means(const Candidate& c, const StillStart& still, const TedaldiTriad& accel,
                     const ScannedRecording& scan) {
  PoseMeans m;
  m.gyro.push_back(still.gyro_bias_raw);
  m.accel_si.push_back(accel.apply(still.accel_mean_raw));
  m.t_s.push_back(0.5 * (scan.t_s.front() + scan.t_s[still.samples - 1]));
  for (std::size_t k = 0; k < c.means.size(); ++k) {
    m.gyro.push_back(c.gyro_means[k]);
    m.accel_si.push_back(accel.apply(c.means[k]));
    m.t_s.push_back(0.5 * (scan.t_s[c.intervals[k].begin] + scan.t_s[c.intervals[k].end - 1]));
  }
  return m;
}

/// The gyro's static model fitted to a candidate's poses (through its accelerometer solve).
void fit_candidate_gyro(Candidate* c, const SearchInput& in, const StaticCalibrationOptions& opt) {
  c->gyro = fit_gyro_static(pose_means(*c, in.still, accel_triad(c->solve.p), in.scan), in.still,
                            effective_gsens(opt, *c), in.H_fixed);
}

/// The static intervals at threshold (k varsigma_init)^2 with their means and attitude count, the
/// accelerometer fitted to them when there are enough attitudes, and the gyro's static model.
/// Intervals whose gyro shows rotation beyond what the bias and the g-sensitivity explain are
/// dropped, and the fits repeated without them.
Candidate evaluate_multiplier(int k, const SearchInput& in, const StaticCalibrationOptions& opt) {
  Candidate c;
  c.multiplier = k;
  const double threshold = static_cast<double>(k) * static_cast<double>(k) * in.still.sigma_init_sq;
  const auto raw_intervals = detect_static_intervals(in.detection.sigma_sq, threshold, in.scan.accel_ok,
                                                     in.scan.break_before, in.min_samples);
  for (const auto& iv : raw_intervals) {
    const double m = static_cast<double>(iv.size());
    c.intervals.push_back(iv);
    c.means.push_back((in.sums.accel[iv.end] - in.sums.accel[iv.begin]) / m + in.sums.accel_center);
    c.gyro_means.push_back((in.sums.gyro[iv.end] - in.sums.gyro[iv.begin]) / m + in.still.gyro_bias_raw);
  }
  if (!enough_attitudes(&c, in.model, opt)) return c;
  c.solve = first_accel_solve(c, in.model, opt);
  if (!c.solve.ok) return c;
  fit_candidate_gyro(&c, in, opt);
  // Drop the interval whose gyro shows the most rotation beyond the static model, one at a time
  // with a refit after each: a pose turned about gravity (which the accelerometer cannot see)
  // pulls the fit towards itself, and dropping everything above the limit after one fit would
  // throw out good poses with it.
  bool dropped = false;
  for (;;) {
    std::size_t worst = 0;
    double worst_rot = 0.0;
    for (std::size_t j = 0; j < c.intervals.size(); ++j) {
      const double duration = static_cast<double>(c.intervals[j].size()) * in.scan.period_s;
      const double rot = in.gyro_scale0.cwiseProduct(c.gyro.residual[j + 1]).norm() * duration;
      if (rot > worst_rot) {
        worst_rot = rot;
        worst = j;
      }
    }
    if (worst_rot <= in.max_rot_rad) break;
    ++c.rotated;
    c.worst_rotation_deg = std::max(c.worst_rotation_deg, worst_rot * 180.0 / M_PI);
    const auto at = static_cast<std::ptrdiff_t>(worst);
    c.intervals.erase(c.intervals.begin() + at);
    c.means.erase(c.means.begin() + at);
    c.gyro_means.erase(c.gyro_means.begin() + at);
    dropped = true;
    if (!enough_attitudes(&c, in.model, opt)) {
      c.solve.ok = false;  // too few attitudes left for this model
      return c;
    }
    fit_candidate_gyro(&c, in, opt);  // with the accelerometer of all the poses: close enough here
  }
  if (dropped) {
    c.solve = first_accel_solve(c, in.model, opt);
    if (c.solve.ok) fit_candidate_gyro(&c, in, opt);
  }
  return c;
}

/// The candidates of every multiplier that have enough attitudes for in.model, and the most
/// attitudes and faces any multiplier found (for the refusal).
struct SearchPass {
  std::vector<Candidate> valid;
  int best_distinct = 0;
  std::size_t best_intervals = 0;
  std::array<int, kFaceCount> best_faces{};
};

SearchPass search_pass(const SearchInput& in, const StaticCalibrationOptions& opt) {
  SearchPass pass;
  int best_covered = -1;
  for (int k = opt.multiplier_min; k <= opt.multiplier_max; ++k) {
    Candidate c = evaluate_multiplier(k, in, opt);
    if (c.distinct > pass.best_distinct) {
      pass.best_distinct = c.distinct;
      pass.best_intervals = c.intervals.size();
    }
    const auto counts = face_counts(c.faces);
    const int covered =
        static_cast<int>(std::count_if(counts.begin(), counts.end(), [](int n) { return n > 0; }));
    if (covered > best_covered) {
      best_covered = covered;
      pass.best_faces = counts;
    }
    if (c.solve.ok) pass.valid.push_back(std::move(c));
  }
  return pass;
}

/// The models tried, in order: auto falls back from the full model to the known-orientation form
/// (six faces) and then to scales and biases alone.
std::vector<AccelModel> models_to_try(AccelModel m) {
  if (m == AccelModel::kAuto) return {AccelModel::kFull, AccelModel::kFaces, AccelModel::kScaleBias};
  return {m};
}

std::string refusal(const SearchPass& pass, const StaticCalibrationOptions& opt) {
  const std::string missing = missing_faces_in_words(pass.best_faces);
  std::string msg = "found at most " + std::to_string(pass.best_distinct) + " distinct static attitudes (" +
                    std::to_string(pass.best_intervals) + " static intervals of at least " +
                    fmt("%.1f", opt.min_interval_s) + " s) with any threshold multiplier in [" +
                    std::to_string(opt.multiplier_min) + ", " + std::to_string(opt.multiplier_max) + "]; ";
  switch (opt.accel_model) {
    case AccelModel::kFull:
      msg += "the full accelerometer model needs " + std::to_string(opt.min_attitudes);
      break;
    case AccelModel::kFaces:
      msg += "the known-orientation form needs a pose on each of the six faces";
      break;
    case AccelModel::kScaleBias:
      msg += "scales and biases alone need " + std::to_string(opt.min_attitudes_scale_bias);
      break;
    case AccelModel::kAuto:
      msg += "the full accelerometer model needs " + std::to_string(opt.min_attitudes) +
             ", scales and biases alone " + std::to_string(opt.min_attitudes_scale_bias) +
             " or a pose on each of the six faces";
      break;
  }
  if (std::all_of(pass.best_faces.begin(), pass.best_faces.end(), [](int n) { return n == 0; })) {
    msg += ". None of the poses lies within " + fmt("%.0f", opt.face_max_angle_deg) +
           " deg of a face (gravity along one axis), so the six-face form cannot be used either";
  } else if (!missing.empty()) {
    msg += ". No pose was held with " + missing + ": hold the rig that way too";
  }
  msg += ". " + std::to_string(pass.best_distinct) +
         " attitudes would determine at most the three biases with the scales taken as nominal, which is no "
         "calibration. Record again: after the still start, hold the rig still for 1-4 s on each of its six "
         "faces, better in 36-50 different attitudes (" +
         std::to_string(opt.recommended_attitudes) + " or more distinct), turning it between holds";
  return msg;
}

/// Algorithm 1: the multiplier whose static poses give the lowest accelerometer residual, for
/// the first model that some multiplier has enough attitudes for.
Result<Candidate> search_threshold(const ScannedRecording& scan, const StaticDetection& detection,
                                   const StillStart& still, const StaticCalibrationOptions& opt,
                                   std::vector<ThresholdCandidate>* scored, AccelModel* model,
                                   std::vector<std::string>* warnings) {
  const PrefixSums sums = prefix_sums(scan, still.gyro_bias_raw);
  SearchInput in{scan, detection, still, sums};
  in.gyro_scale0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  // A given G (rad/s per m/s^2) in input units through the nominal gyro scale.
  in.H_fixed = in.gyro_scale0.cwiseInverse().asDiagonal() * opt.gsens_fixed;
  in.min_samples =
      std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(opt.min_interval_s * scan.rate_hz)));
  in.max_rot_rad = opt.max_rotation_in_static_deg * M_PI / 180.0;
  SearchPass pass;
  for (AccelModel m : models_to_try(opt.accel_model)) {
    in.model = m;
    pass = search_pass(in, opt);
    if (!pass.valid.empty()) {
      *model = m;
      break;
    }
  }
  std::vector<Candidate>& valid = pass.valid;
  // Score: the accelerometer residual (eq. 3.4, Algorithm 1) and the gyro's residual about its
  // static model (motion let into the intervals shows there first), each relative to its best
  // over the multipliers, summed. A threshold whose intervals had to be dropped for rotation
  // loses to any that did not.
  double min_a = std::numeric_limits<double>::infinity(), min_g = min_a;
  for (const auto& c : valid) {
    min_a = std::min(min_a, c.solve.rms);
    min_g = std::min(min_g, c.gyro.rms);
  }
  const auto key = [&](const Candidate& c) {
    const double score = c.solve.rms / std::max(min_a, 1e-300) + c.gyro.rms / std::max(min_g, 1e-300);
    return std::make_pair(c.rotated > 0, score);
  };
  std::optional<Candidate> best;
  for (auto& c : valid) {
    scored->push_back({c.multiplier, static_cast<int>(c.intervals.size()), c.distinct, c.rotated, c.solve.rms,
                       c.gyro.rms, key(c).second});
    if (!best || key(c) < key(*best)) best = std::move(c);
  }
  if (!best) return make_error(Errc::kInsufficientData, refusal(pass, opt));
  if (*model == AccelModel::kFull && best->distinct < opt.recommended_attitudes) {
    warnings->push_back("only " + std::to_string(best->distinct) + " distinct attitudes were found (" +
                        std::to_string(opt.recommended_attitudes) +
                        " or more recommended, 36-50 ideal): the result is less certain, see the sigmas");
  }
  if (best->rotated > 0) {
    warnings->push_back(
        std::to_string(best->rotated) +
        " static interval(s) were dropped because the rig turned inside them: " + "the gyro shows up to " +
        fmt("%.1f", best->worst_rotation_deg) + " deg beyond its bias" +
        (opt.gsens == GSensitivityMode::kOff ? "" : " and g-sensitivity") + " (more than " +
        fmt("%.1f", opt.max_rotation_in_static_deg) + " deg): hold the poses steadier");
  }
  return std::move(*best);
}

// ---- accelerometer: final solve with covariance ----------------------------------------------

/// Held misalignment angles (at zero in the scale-bias form, at the faces' values in the
/// known-orientation form) are really uncertain by `priors`; the scales and biases they move (to
/// second order on faces, to first order on tilted poses) are widened by the shift a held angle
/// moved by +-prior gives, and the held angles carry the prior's variance so that the gyro's
/// covariance (which takes the accelerometer's) includes it.
void widen_for_held_misalignment(const Candidate& best, const StaticCalibrationOptions& opt, const Vec9& p,
                                 const Eigen::Vector3d& priors, Eigen::MatrixXd* cov) {
  for (int j = 0; j < 3; ++j) {
    const double prior = priors[j];
    Vec9 shift[2];
    for (int side = 0; side < 2; ++side) {
      Vec9 q = p;
      q[j] += side == 0 ? prior : -prior;
      const AccelSolve s = solve_accel(best.means, opt.gravity_mps2, accel_triad(q), nullptr, true);
      shift[side] = s.ok ? Vec9(s.p - q) : Vec9::Zero();
      shift[side][j] = 0.0;
    }
    const Vec9 linear = 0.5 * (shift[0] - shift[1]);
    *cov += 0.5 * (shift[0] * shift[0].transpose() + shift[1] * shift[1].transpose());
    // The held angle and what it moves, correlated through the linear part.
    for (int i = 0; i < 9; ++i) {
      (*cov)(i, j) += linear[i] * prior;
      (*cov)(j, i) += linear[i] * prior;
    }
    (*cov)(j, j) = prior * prior;
  }
}

Status solve_accelerometer(const Candidate& best, AccelModel model, std::span<const ImuSample> samples,
                           const StaticCalibrationOptions& opt, StaticCalibrationResult* res) {
  AccelSolve final;
  if (model == AccelModel::kFaces) {
    const KnownOrientationFit fit = fit_known_orientation(best.means, best.faces, opt.gravity_mps2);
    if (!fit.ok)
      return make_error(Errc::kSolverFailed, "the known-orientation accelerometer fit failed: " + fit.error);
    if (magnitude_after_faces(best.means.size())) {
      // Misalignment from the faces, scales and biases from the magnitude with it held.
      final = solve_accel(best.means, opt.gravity_mps2, fit.triad, &res->accel_covariance, true);
      if (!final.ok) return make_error(Errc::kSolverFailed, "the accelerometer's scale and bias fit failed");
      const Eigen::Vector3d angle_sigma = fit.covariance.diagonal().head<3>().cwiseMax(0.0).cwiseSqrt();
      widen_for_held_misalignment(best, opt, final.p, angle_sigma, &res->accel_covariance);
      res->accel_covariance.topLeftCorner<3, 3>() = fit.covariance.topLeftCorner<3, 3>();
      res->accel_dof = {static_cast<int>(best.means.size()), 6};
    } else {
      final = first_accel_solve(best, model, opt);
      res->accel_covariance = fit.covariance;
      res->accel_dof = {fit.residuals, fit.parameters};
    }
    res->faces_direction_rms_rad = fit.direction_rms_rad;
    res->faces_rotation_rad = fit.q_angle_rad;
    res->poses_off_faces = static_cast<int>(std::count(best.faces.begin(), best.faces.end(), -1));
    res->accel_model = StaticAccelModel::kFaces;
    res->accel_model_reason =
        std::to_string(best.distinct) + " distinct attitudes, fewer than the " +
        std::to_string(opt.min_attitudes) +
        " the magnitude form needs, on all six faces: the misalignment from the poses taken as lying flat on "
        "their faces with gravity along their axes (the form PX4 and ArduPilot use), scales and biases " +
        (magnitude_after_faces(best.means.size()) ? std::string("from the gravity magnitude")
                                                  : std::string("too (one pose per face)"));
    if (opt.accel_model == AccelModel::kFaces) res->accel_model_reason = "chosen with --accel-model faces";
    if (res->poses_off_faces > 0) {
      res->warnings.push_back(
          std::to_string(res->poses_off_faces) + " static pose(s) lie on no face (more than " +
          fmt("%.0f", opt.face_max_angle_deg) +
          " deg from every axis): left out of the accelerometer fit, used for the gyroscope");
    }
    if (fit.direction_rms_rad > 1.0 * M_PI / 180.0) {
      res->warnings.push_back(
          "the poses lie " + fmt("%.2f", fit.direction_rms_rad * 180.0 / M_PI) +
          " deg RMS from their faces' axes: they were not flat on level faces, and the "
          "misalignment is only as good as that (--accel-model scale-bias fits scales and "
          "biases without assuming the faces)");
    }
  } else {
    const bool fix = model == AccelModel::kScaleBias;
    final = solve_accel(best.means, opt.gravity_mps2, accel_triad(best.solve.p), &res->accel_covariance, fix);
    if (!final.ok) {
      return make_error(Errc::kSolverFailed,
                        "the accelerometer covariance could not be computed: the static attitudes do not "
                        "constrain all " +
                            std::string(fix ? "6" : "9") +
                            " parameters; record poses covering more directions");
    }
    res->accel_dof = {static_cast<int>(best.means.size()), fix ? 6 : 9};
    if (fix) {
      widen_for_held_misalignment(best, opt, final.p, Eigen::Vector3d::Constant(opt.misalignment_prior_rad),
                                  &res->accel_covariance);
      res->accel_model = StaticAccelModel::kScaleBias;
      res->accel_fixed = {"misalignment alpha_yz", "misalignment alpha_zy", "misalignment alpha_zx"};
      res->accel_model_reason =
          opt.accel_model == AccelModel::kScaleBias
              ? "chosen with --accel-model scale-bias"
              : std::to_string(best.distinct) + " distinct attitudes, fewer than the " +
                    std::to_string(opt.min_attitudes) +
                    " the full model needs, not on all six faces (missing: " +
                    missing_faces_in_words(face_counts(best.faces)) +
                    "): scales and biases from the gravity magnitude, misalignment held at zero";
      res->warnings.push_back("the accelerometer misalignment was not determined (held at zero; " +
                              res->accel_model_reason +
                              "); the scale and bias sigmas include a misalignment of " +
                              fmt("%.3f", opt.misalignment_prior_rad) + " rad");
    } else {
      res->accel_model = StaticAccelModel::kFull;
      res->accel_model_reason = std::to_string(best.distinct) + " distinct attitudes (" +
                                std::to_string(opt.min_attitudes) + " needed): Tedaldi's magnitude form";
    }
  }
  res->model.accel = accel_triad(final.p);
  if (!res->accel_dof.determined()) {
    res->warnings.push_back("the accelerometer fit is exact: " + std::to_string(res->accel_dof.residuals) +
                            " residuals for its " + std::to_string(res->accel_dof.parameters) +
                            " parameters leave nothing to check it against, and its sigmas are undetermined. "
                            "Record more poses (36-50)");
  }
  res->accel_residual_rms = final.rms;
  res->accel_iterations = best.solve.iterations + final.iterations;
  res->accel_sigma = accel_sigma(res->accel_covariance);
  if (model == AccelModel::kScaleBias) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    res->accel_sigma.T(0, 1) = res->accel_sigma.T(0, 2) = res->accel_sigma.T(1, 2) = nan;
  }
  for (std::size_t k = 0; k < best.intervals.size(); ++k) {
    const auto& iv = best.intervals[k];
    res->intervals.push_back({samples[iv.begin].t_ns, samples[iv.end - 1].t_ns, iv.size(), best.means[k]});
  }
  return {};
}

// ---- gyroscope -------------------------------------------------------------------------------

/// The motions between consecutive static poses that can be integrated: none crossing a gap, a
/// reset or a saturated gyro sample. Refuses when fewer than min_attitudes - 1 remain.
Result<std::vector<Transfer>> collect_transfers(const std::vector<StaticInterval>& intervals,
                                                const ScannedRecording& scan,
                                                std::span<const ImuSample> samples,
                                                const StaticCalibrationOptions& opt,
                                                StaticCalibrationResult* res) {
  std::vector<Transfer> transfers;
  int dropped = 0, dropped_gap = 0, dropped_sat = 0;
  for (std::size_t k = 0; k + 1 < intervals.size(); ++k) {
    const std::size_t a = intervals[k].end - 1;
    const std::size_t b = intervals[k + 1].begin;
    bool has_gap = false, has_sat = false;
    for (std::size_t i = a; i <= b; ++i) {
      has_sat = has_sat || !scan.gyro_ok[i];
      has_gap = has_gap || (i > a && scan.break_before[i]);
    }
    if (has_gap || has_sat) {
      ++dropped;
      dropped_gap += has_gap ? 1 : 0;
      dropped_sat += has_sat ? 1 : 0;
      continue;
    }
    Transfer tr;
    tr.gyro_raw.assign(scan.gyro.begin() + static_cast<std::ptrdiff_t>(a),
                       scan.gyro.begin() + static_cast<std::ptrdiff_t>(b) + 1);
    tr.t_s.resize(tr.gyro_raw.size());
    for (std::size_t i = a; i <= b; ++i) tr.t_s[i - a] = ns_to_s(samples[i].t_ns - samples[a].t_ns);
    tr.pose0 = k;
    transfers.push_back(std::move(tr));
  }
  if (dropped > 0) {
    res->warnings.push_back(
        std::to_string(dropped) + " motion(s) between static poses were not used for the " +
        "gyroscope: " + std::to_string(dropped_gap) + " contain a gap or a device reset, " +
        std::to_string(dropped_sat) + " contain saturated gyro samples");
  }
  res->gyro_transfers = static_cast<int>(transfers.size());
  // Each motion gives two independent equations (a direction): more than the gyro's 9 parameters
  // (12 with its bias) take 5 (7). Six faces in turn give exactly 5.
  const int min_transfers = opt.estimate_gyro_bias ? 7 : 5;
  if (res->gyro_transfers < min_transfers) {
    return make_error(Errc::kInsufficientData,
                      "only " + std::to_string(res->gyro_transfers) + " of " +
                          std::to_string(res->gyro_transfers + dropped) +
                          " motions between consecutive static poses can be integrated (at least " +
                          std::to_string(min_transfers) + " needed for the gyroscope; " +
                          std::to_string(dropped_sat) + " contain saturated gyro samples (" +
                          std::to_string(scan.gyro_saturated) + " saturated in all), " +
                          std::to_string(dropped_gap) +
                          " contain a gap or a device reset): turn the rig more slowly than the gyro "
                          "full-scale range (or raise it), avoid gaps, and record more poses");
  }
  return transfers;
}

/// The least-squares problem of eq. 3.8 over all transfers. The cost functions point at the
/// transfers and at this object's fixed bias, so it is built in place and never moved.
class GyroFit {
 public:
  /// `held`: indices into [6 angles, 3 scales] kept at gyro0's values instead of fitted.
  GyroFit(const std::vector<Transfer>& transfers, const TedaldiTriad& gyro0, bool estimate_bias, int threads,
          std::vector<int> held = {})
      : gyro0_(gyro0), estimate_bias_(estimate_bias), held_(std::move(held)), gb_(gyro0.bias) {
    gp_ << gyro_angles(gyro0_.T), gyro0_.scale;
    if (transfers.empty()) return;
    cost_ = new GyroTransfersCost(transfers, estimate_bias_ ? nullptr : &gyro0_.bias, threads);
    if (estimate_bias_) {
      problem_.AddResidualBlock(cost_, nullptr, gp_.data(), gb_.data());
    } else {
      problem_.AddResidualBlock(cost_, nullptr, gp_.data());
    }
    if (!held_.empty()) problem_.SetManifold(gp_.data(), new ceres::SubsetManifold(9, held_));
  }
  GyroFit(const GyroFit&) = delete;
  GyroFit& operator=(const GyroFit&) = delete;

  /// One solve from the current parameters; the transfers' directions must be set. With
  /// `first_order`, steered by the first-order Jacobian (GyroTransferCost::set_first_order).
  Status solve(int* iterations, bool first_order) {
    if (cost_) cost_->set_first_order(first_order);
    ceres::Solver::Options so = solver_options(50);
    so.function_tolerance = 1e-10;
    so.parameter_tolerance = 1e-10;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem_, &summary);
    if (!summary.IsSolutionUsable() || !gp_.allFinite()) {
      return make_error(Errc::kSolverFailed, "the gyroscope solve failed: " + summary.message);
    }
    *iterations += static_cast<int>(summary.iterations.size());
    final_cost_ = summary.final_cost;
    return {};
  }

  TedaldiTriad triad() const {
    TedaldiTriad t;
    t.T = gyro_misalignment(gp_.head<6>());
    t.scale = gp_.tail<3>();
    t.bias = estimate_bias_ ? gb_ : gyro0_.bias;
    return t;
  }
  int parameters() const { return estimate_bias_ ? 12 : 9; }
  /// The parameters fitted (not held).
  int fitted() const { return parameters() - static_cast<int>(held_.size()); }
  double final_cost() const { return final_cost_; }

  /// The Jacobian of all residuals at the current parameters, dense, with a zero column for each
  /// held parameter.
  Result<Eigen::MatrixXd> jacobian() {
    if (!held_.empty()) {
      // The cost function's own Jacobian: every column, whatever the manifold holds.
      const int rows = cost_ ? cost_->num_residuals() : 0;
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> j9(rows, 9), j3(rows, 3);
      Eigen::VectorXd r(rows);
      const double* params[2] = {gp_.data(), gb_.data()};
      double* jac[2] = {j9.data(), j3.data()};
      if (!cost_ || !cost_->Evaluate(params, r.data(), jac)) {
        return make_error(Errc::kSolverFailed, "the gyroscope Jacobian could not be evaluated");
      }
      Eigen::MatrixXd J = Eigen::MatrixXd::Zero(rows, parameters());
      J.leftCols(9) = j9;
      if (estimate_bias_) J.rightCols(3) = j3;
      for (int i : held_) J.col(i).setZero();
      return J;
    }
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = {gp_.data()};
    if (estimate_bias_) eo.parameter_blocks.push_back(gb_.data());
    eo.num_threads = 1;
    ceres::CRSMatrix crs;
    if (!problem_.Evaluate(eo, nullptr, nullptr, nullptr, &crs) || crs.num_cols != parameters()) {
      return make_error(Errc::kSolverFailed,
                        "the gyroscope covariance could not be computed: the motions between poses do not "
                        "constrain all gyro parameters; turn the rig about all three axes between poses");
    }
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
    for (int r = 0; r < crs.num_rows; ++r) {
      for (int idx = crs.rows[r]; idx < crs.rows[r + 1]; ++idx) J(r, crs.cols[idx]) = crs.values[idx];
    }
    return J;
  }

 private:
  const TedaldiTriad gyro0_;
  const bool estimate_bias_;
  const std::vector<int> held_;
  Eigen::Matrix<double, 9, 1> gp_;
  Eigen::Vector3d gb_;
  ceres::Problem problem_;
  GyroTransfersCost* cost_ = nullptr;  // owned by problem_
  double final_cost_ = 0.0;
};

/// Sets the transfers' gravity directions (u0 at the end of the start pose, u1 at the start of
/// the next) from the given accelerometer and gyro models.
void set_transfer_directions(std::vector<Transfer>* transfers, const std::vector<StaticInterval>& intervals,
                             const ScannedRecording& scan, std::span<const ImuSample> samples,
                             const TedaldiTriad& accel, const TedaldiTriad& gyro, int threads) {
  const auto dirs = pose_directions(intervals, scan.accel, scan.gyro, samples, accel, gyro, threads);
  for (auto& tr : *transfers) {
    tr.u0 = dirs[tr.pose0].u_end;
    tr.u1 = dirs[tr.pose0 + 1].u_start;
  }
}

/// The effect of the accelerometer's uncertainty on the gyro parameters. The reference
/// directions come from the calibrated accelerometer, whose errors are common to all transfers:
/// D Sigma_a D^T with D = -(J_g^T J_g)^-1 J_g^T dr/dtheta_a (Gauss-Newton sensitivity of the gyro
/// solution; the small rotation inside the static intervals is neglected in dr/dtheta_a).
Eigen::MatrixXd accel_uncertainty_in_gyro(const Eigen::MatrixXd& Jg, const std::vector<Transfer>& transfers,
                                          const std::vector<Eigen::Vector3d>& means,
                                          const StaticCalibrationResult& res) {
  const Vec9 pa = accel_params(res.model.accel);
  std::vector<Eigen::Matrix<double, 3, 9>> du(means.size());
  for (std::size_t k = 0; k < means.size(); ++k) {
    for (int i = 0; i < 9; ++i) {
      const double h = 1e-6 * std::max(1.0, std::abs(pa[i]));
      Vec9 pp = pa, pm = pa;
      pp[i] += h;
      pm[i] -= h;
      du[k].col(i) =
          (accel_triad(pp).apply(means[k]).normalized() - accel_triad(pm).apply(means[k]).normalized()) /
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
  const Eigen::MatrixXd D = -normal_pseudo_inverse(Jg) * (Jg.transpose() * Ja);
  return D * res.accel_covariance * D.transpose();
}

TriadSigma gyro_sigma(const Eigen::MatrixXd& cov, bool bias_estimated,
                      const Eigen::Vector3d& still_bias_sigma) {
  const Eigen::VectorXd d = sigmas_of(cov);
  TriadSigma s;
  s.T(0, 1) = d[0];
  s.T(0, 2) = d[1];
  s.T(1, 0) = d[2];
  s.T(1, 2) = d[3];
  s.T(2, 0) = d[4];
  s.T(2, 1) = d[5];
  s.scale = d.segment<3>(6);
  s.bias = bias_estimated ? Eigen::Vector3d(d.tail<3>()) : still_bias_sigma;
  return s;
}

/// The gyro model before the solve: the nominal scale, the given bias (input units, canonical sign).
TedaldiTriad initial_gyro(const Eigen::Vector3d& bias_raw, const StaticCalibrationOptions& opt) {
  TedaldiTriad gyro0;
  gyro0.scale = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  gyro0.bias = -bias_raw;
  return gyro0;
}

/// Names of the gyro parameters in the solve's order (eq. 3.6).
const char* gyro_parameter_name(int i) {
  static const char* names[] = {"misalignment gamma_yz",
                                "misalignment gamma_zy",
                                "misalignment gamma_xz",
                                "misalignment gamma_zx",
                                "misalignment gamma_xy",
                                "misalignment gamma_yx",
                                "scale x",
                                "scale y",
                                "scale z"};
  return names[i];
}

/// Prior sigma of a held gyro parameter (index into [6 angles, 3 scales]): the chip's cross-axis
/// sensitivity for an angle, its sensitivity tolerance for a scale.
double held_prior_sigma(int i, const Eigen::Vector3d& scale, const StaticCalibrationOptions& opt) {
  return i < 6 ? opt.misalignment_prior_rad : opt.scale_prior_rel * std::abs(scale[i - 6]);
}

/// Covariance of the gyro parameters with `held` ones at nominal: the fitted ones' from the
/// residual variance s2 (the plain inverse on the fitted columns, each scaled to unit length, so
/// that a direction the motions do not see gets the size it has and not the truncated
/// pseudo-inverse's zero), plus what the held ones' prior uncertainty moves them by (D P D^T,
/// D = -(Jf'Jf)^-1 Jf'Jh), the held ones carrying their prior. n x n, n = J's columns.
Eigen::MatrixXd held_covariance(const Eigen::MatrixXd& J, const std::vector<int>& held, double s2,
                                const Eigen::Vector3d& scale, const StaticCalibrationOptions& opt) {
  const Eigen::Index n = J.cols();
  std::vector<Eigen::Index> F, H;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (std::find(held.begin(), held.end(), static_cast<int>(i)) == held.end())
      F.push_back(i);
    else
      H.push_back(i);
  }
  const auto nf = static_cast<Eigen::Index>(F.size()), nh = static_cast<Eigen::Index>(H.size());
  Eigen::MatrixXd Jf(J.rows(), nf), Jh(J.rows(), nh);
  Eigen::VectorXd norm(nf);
  for (Eigen::Index c = 0; c < nf; ++c) {
    norm[c] = std::max(J.col(F[static_cast<std::size_t>(c)]).norm(), 1e-300);
    Jf.col(c) = J.col(F[static_cast<std::size_t>(c)]) / norm[c];
  }
  for (Eigen::Index c = 0; c < nh; ++c) Jh.col(c) = J.col(H[static_cast<std::size_t>(c)]);
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Jf, Eigen::ComputeThinV);
  const Eigen::VectorXd inv_sq = svd.singularValues().unaryExpr([](double v) { return 1.0 / (v * v); });
  const Eigen::MatrixXd Ninv = norm.cwiseInverse().asDiagonal();
  const Eigen::MatrixXd JtJ_inv =
      Ninv * svd.matrixV() * inv_sq.asDiagonal() * svd.matrixV().transpose() * Ninv;
  Eigen::MatrixXd cov_f = s2 * JtJ_inv;
  Eigen::VectorXd prior(nh);
  for (Eigen::Index c = 0; c < nh; ++c)
    prior[c] = held_prior_sigma(static_cast<int>(H[static_cast<std::size_t>(c)]), scale, opt);
  const Eigen::MatrixXd P = prior.cwiseAbs2().asDiagonal();
  // Unscaled fitted columns against the held ones: D = -(Jf'Jf)^-1 Jf'Jh.
  const Eigen::MatrixXd D = -JtJ_inv * (Ninv.inverse() * Jf.transpose() * Jh);
  cov_f += D * P * D.transpose();
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index r = 0; r < nf; ++r)
    for (Eigen::Index c = 0; c < nf; ++c)
      cov(F[static_cast<std::size_t>(r)], F[static_cast<std::size_t>(c)]) = cov_f(r, c);
  const Eigen::MatrixXd DP = D * P;
  for (Eigen::Index r = 0; r < nf; ++r)
    for (Eigen::Index c = 0; c < nh; ++c) {
      cov(F[static_cast<std::size_t>(r)], H[static_cast<std::size_t>(c)]) = DP(r, c);
      cov(H[static_cast<std::size_t>(c)], F[static_cast<std::size_t>(r)]) = DP(r, c);
    }
  for (Eigen::Index c = 0; c < nh; ++c)
    cov(H[static_cast<std::size_t>(c)], H[static_cast<std::size_t>(c)]) = P(c, c);
  return cov;
}

/// The fitted gyro parameters the motions leave undetermined: a misalignment angle whose sigma
/// (held_covariance: with the share of the parameters already held) exceeds the limit, or a scale
/// whose relative sigma does. One at a time, the parameter furthest beyond its limit is set
/// aside and the others are looked at again with it held, so that a parameter made uncertain
/// only by its correlation with a worse one is kept unless holding that one moves it as much.
std::vector<int> undetermined_gyro_parameters(const Eigen::MatrixXd& J, const std::vector<int>& held,
                                              double s2, const Eigen::Vector3d& scale,
                                              const StaticCalibrationOptions& opt) {
  std::vector<int> all_held = held, weak;
  for (;;) {
    const Eigen::MatrixXd cov = held_covariance(J, all_held, s2, scale, opt);
    int worst = -1;
    double worst_ratio = 1.0;
    for (int i = 0; i < 9; ++i) {  // biases (with --estimate-gyro-bias) are never held
      if (std::find(all_held.begin(), all_held.end(), i) != all_held.end()) continue;
      const double sd = std::sqrt(std::max(cov(i, i), 0.0));
      const double limit =
          i < 6 ? opt.gyro_max_misalignment_sigma_rad : opt.gyro_max_scale_rel_sigma * std::abs(scale[i - 6]);
      const double ratio = std::isfinite(sd) ? sd / limit : std::numeric_limits<double>::infinity();
      if (ratio > worst_ratio || (!(ratio <= 1.0) && worst < 0)) {
        worst_ratio = ratio;
        worst = i;
      }
    }
    if (worst < 0) break;
    weak.push_back(worst);
    all_held.push_back(worst);
    if (all_held.size() >= 9) break;
  }
  return weak;
}

/// One gyro solve with `held` parameters at their nominal values: two passes (the directions at
/// the ends of the static intervals depend weakly on the gyro model through the rotation inside
/// the intervals; the first pass, from the nominal model, is steered by the first-order Jacobian,
/// the second, which decides the solution, by the exact one), then the covariance with the
/// accelerometer's share. `weak` receives the fitted parameters the motions leave undetermined:
/// a misalignment angle whose sigma exceeds the limit, or a scale whose relative sigma does.
Status gyro_solve(std::vector<Transfer>* transfers, const Candidate& best, const ScannedRecording& scan,
                  std::span<const ImuSample> samples, const GyroStaticFit& gfit,
                  const StaticCalibrationOptions& opt, const std::vector<int>& held,
                  StaticCalibrationResult* res, std::vector<int>* weak) {
  const TedaldiTriad gyro0 = initial_gyro(gfit.bias, opt);
  const int threads = threads_or_cores(opt.threads);
  GyroFit fit(*transfers, gyro0, opt.estimate_gyro_bias, threads, held);
  TedaldiTriad gyro_current = gyro0;
  for (int pass = 0; pass < 2; ++pass) {
    set_transfer_directions(transfers, best.intervals, scan, samples, res->model.accel, gyro_current,
                            threads);
    IMUCAL_TRY(fit.solve(&res->gyro_iterations, pass == 0));
    gyro_current = fit.triad();
  }
  const double m_res = 3.0 * static_cast<double>(transfers->size());
  res->gyro_residual_rms = std::sqrt(2.0 * fit.final_cost() / m_res);
  res->model.gyro = fit.triad();
  // One Jacobian evaluation at the solution serves both the covariance and the propagation of
  // the accelerometer uncertainty.
  Result<Eigen::MatrixXd> Jg = fit.jacobian();
  if (!Jg.ok()) return Jg.error();
  res->gyro_dof = {static_cast<int>(m_res), fit.fitted()};
  const double s2 = res->gyro_dof.determined() ? 2.0 * fit.final_cost() / res->gyro_dof.dof()
                                               : std::numeric_limits<double>::quiet_NaN();
  if (held.empty()) {
    res->gyro_covariance = normal_pseudo_inverse(*Jg) * s2;
  } else {
    res->gyro_covariance = held_covariance(*Jg, held, s2, res->model.gyro.scale, opt);
  }
  res->gyro_covariance += accel_uncertainty_in_gyro(*Jg, *transfers, best.means, *res);
  res->gyro_sigma = gyro_sigma(res->gyro_covariance, opt.estimate_gyro_bias, gfit.bias_sigma);
  if (weak) *weak = undetermined_gyro_parameters(*Jg, held, s2, res->model.gyro.scale, opt);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  static const int row[] = {0, 0, 1, 1, 2, 2}, col[] = {1, 2, 0, 2, 0, 1};
  for (int i : held) {
    if (i < 6)
      res->gyro_sigma.T(row[i], col[i]) = nan;
    else
      res->gyro_sigma.scale[i - 6] = nan;
  }
  return {};
}

/// The gyro at its nominal scale without misalignment, the bias from the static poses: what is
/// left when the motions determine none of its scales and misalignments.
void nominal_gyro(const std::vector<Transfer>& transfers, const GyroStaticFit& gfit,
                  const StaticCalibrationOptions& opt, StaticCalibrationResult* res) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  res->model.gyro = initial_gyro(gfit.bias, opt);
  const int n = opt.estimate_gyro_bias ? 12 : 9;
  res->gyro_dof = {3 * static_cast<int>(transfers.size()), 0};
  res->gyro_covariance = Eigen::MatrixXd::Zero(n, n);
  res->gyro_sigma = gyro_sigma(res->gyro_covariance, false, gfit.bias_sigma);
  res->gyro_sigma.T.setConstant(nan);
  res->gyro_sigma.T.diagonal().setZero();
  res->gyro_sigma.scale.setConstant(nan);
}

/// Eqs. 3.5-3.16: the gyro solve. Parameters the motions leave undetermined (a few motions about
/// one or two axes, as six faces turned in sequence give) are held at their nominal values (no
/// misalignment, the nominal scale), named, and the rest solved again.
Status solve_gyroscope(std::vector<Transfer>* transfers, const Candidate& best, const ScannedRecording& scan,
                       std::span<const ImuSample> samples, const GyroStaticFit& gfit,
                       const StaticCalibrationOptions& opt, StaticCalibrationResult* res) {
  std::vector<int> held;
  for (int round = 0; round < 3; ++round) {
    std::vector<int> weak;
    IMUCAL_TRY(gyro_solve(transfers, best, scan, samples, gfit, opt, held, res, &weak));
    if (weak.empty()) break;
    held.insert(held.end(), weak.begin(), weak.end());
    std::sort(held.begin(), held.end());
    if (held.size() == 9) {
      nominal_gyro(*transfers, gfit, opt, res);
      break;
    }
  }
  res->gyro_fixed.clear();
  for (int i : held) res->gyro_fixed.emplace_back(gyro_parameter_name(i));
  if (!held.empty()) {
    std::string names;
    for (const auto& n : res->gyro_fixed) names += (names.empty() ? "" : ", ") + n;
    res->warnings.push_back(
        "the " + std::to_string(transfers->size()) +
        " motions between the static poses do not determine the gyroscope's " + names + " (sigma above " +
        fmt("%.3f", opt.gyro_max_misalignment_sigma_rad) + " rad or " +
        fmt("%.1f", 100.0 * opt.gyro_max_scale_rel_sigma) +
        " %): held at nominal (no misalignment, the nominal scale). Turn the rig about each "
        "of its three axes between holds, both ways");
  }
  return {};
}

// ---- g-sensitivity ---------------------------------------------------------------------------

/// The 95 % point of the chi-square distribution with 9 degrees of freedom.
constexpr double kChi2_9_95 = 16.919;

/// Few poses on all six faces: the fit over the poses has too few degrees of freedom for its
/// residual covariance to mean much, so G and the bias come from the six-face experiment
/// (calib/gsens_calibration.hpp: generalised least squares weighted by the holds' white noise and
/// bias walk) through the final accelerometer; the pose fit stays when that cannot be had (holds
/// shorter than its minimum), with a warning.
void six_face_gsens(std::span<const ImuSample> samples, const StaticCalibrationOptions& opt,
                    const Eigen::Vector3d& s0, StaticCalibrationResult* res, GyroStaticFit* f) {
  GSensitivityOptions g;
  g.gravity_mps2 = opt.gravity_mps2;
  const CanonicalImuModel c = canonical_from_tedaldi(res->model);
  g.A_a = c.A_a;
  g.b_a = c.b_a;
  g.A_g = s0.asDiagonal();
  g.window_s = opt.window_s;
  g.max_face_angle_deg = std::max(opt.face_max_angle_deg, 30.0);
  const Result<GSensitivityResult> r = calibrate_gsens(samples, g);
  if (!r.ok()) {
    res->warnings.push_back("the g-sensitivity comes from the " + std::to_string(f->dof.residuals) +
                            " pose means with " + std::to_string(f->dof.dof()) +
                            " degrees of freedom per axis, too few for trustworthy sigmas; the six-face "
                            "experiment could not be used: " +
                            r.error().message);
    return;
  }
  const Eigen::Vector3d inv = s0.cwiseInverse();
  f->H = inv.asDiagonal() * r->G;
  f->bias = r->b_g;
  f->drift.setZero();
  f->drift_offset.setZero();
  for (int i = 0; i < 3; ++i) {
    f->H_sigma.row(i) = r->G_sigma.row(i) * inv[i];
    f->bias_sigma[i] = r->b_g_sigma[i];
  }
  f->dof = {r->dof.residuals / 3, r->dof.parameters / 3};
  for (const auto& w : r->warnings) res->warnings.push_back("g-sensitivity (six-face holds): " + w);
}

/// The gyro's static model with the final accelerometer calibration.
GyroStaticFit final_gyro_static_fit(const Candidate& best, const ScannedRecording& scan,
                                    std::span<const ImuSample> samples, const StillStart& still,
                                    const StaticCalibrationOptions& opt, StaticCalibrationResult* res) {
  res->gsens_mode = effective_gsens(opt, best);
  if (res->gsens_mode != opt.gsens) {
    res->warnings.push_back(
        "the gyro g-sensitivity was not estimated: " + std::to_string(best.means.size()) +
        " static poses are too few to fit it (" + std::to_string(opt.min_poses_for_gsens) +
        " needed, or a pose on each of the six faces); it is neglected (Tedaldi's model), which "
        "costs gyro accuracy on MEMS gyros. Record more poses, or give a known G");
  }
  // A given G in input units through the nominal gyro scale (the solved scale differs from it by
  // far less than G's own uncertainty).
  const Eigen::Vector3d s0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  const Eigen::Matrix3d H_fixed = s0.cwiseInverse().asDiagonal() * opt.gsens_fixed;
  GyroStaticFit f =
      fit_gyro_static(pose_means(best, still, res->model.accel, scan), still, res->gsens_mode, H_fixed);
  if (res->gsens_mode == GSensitivityMode::kEstimate &&
      best.means.size() < static_cast<std::size_t>(opt.min_poses_for_gsens)) {
    six_face_gsens(samples, opt, s0, res, &f);
  }
  if (res->gsens_mode == GSensitivityMode::kEstimate) {
    // Is G distinguishable from zero at all? The Wald statistic of its nine entries (their
    // correlations neglected) against the chi-square 95 % point; below it, estimating G only
    // adds its noise to every gyro sample (on the real recordings of docs/static-calibration.md
    // whose G this test rejects, neglecting it carried gravity better on every one).
    double w = 0.0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) w += (f.H(i, j) / f.H_sigma(i, j)) * (f.H(i, j) / f.H_sigma(i, j));
    res->gsens_wald = w;
    if (std::isfinite(w) && w < kChi2_9_95) {
      // Not a warning: there is nothing to do about it. The summary and the JSON say so.
      res->gsens_mode = GSensitivityMode::kOff;
      f = fit_gyro_static(pose_means(best, still, res->model.accel, scan), still, res->gsens_mode, H_fixed);
    }
  }
  res->gsens_dof = f.dof;
  return f;
}

/// The recording with every gyro sample's g-sensitivity removed (w_raw - H a(t), a(t) the
/// calibrated accelerometer sample), so that the transfers integrate rates that carry only the
/// bias besides the rotation.
ScannedRecording without_gsens(const ScannedRecording& scan, const GyroStaticFit& f,
                               const TedaldiTriad& accel) {
  ScannedRecording out = scan;
  if (f.H.isZero(0.0) && f.drift.isZero(0.0)) return out;
  for (std::size_t i = 0; i < out.gyro.size(); ++i) {
    out.gyro[i] -= f.H * accel.apply(scan.accel[i]) + f.drift_at(scan.t_s[i]);
  }
  return out;
}

/// Canonical G = A_g H (minus the Earth's vertical rate when the latitude is known) and its sigma.
void set_gsens_result(const GyroStaticFit& f, const StaticCalibrationOptions& opt,
                      StaticCalibrationResult* res) {
  res->gsens_residual_rms = f.rms;
  const Eigen::Matrix3d A = res->model.gyro.TK();
  if (res->gsens_mode == GSensitivityMode::kFixed) {
    res->canonical.G = opt.gsens_fixed;
    res->gsens_residual_rms = (opt.gyro_init ? opt.gyro_init->scale.mean() : 1.0) * f.rms;
    return;
  }
  if (res->gsens_mode == GSensitivityMode::kOff) return;
  res->canonical.G = A * f.H;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double var = 0.0;
      for (int k = 0; k < 3; ++k) var += A(i, k) * A(i, k) * f.H_sigma(k, j) * f.H_sigma(k, j);
      res->gsens_sigma(i, j) = std::sqrt(var);
    }
  }
  if (opt.latitude_deg) {
    res->earth_rate_removed = earth_rate_gsens(*opt.latitude_deg, opt.gravity_mps2);
    res->canonical.G -= res->earth_rate_removed * Eigen::Matrix3d::Identity();
  }
  const Eigen::Vector3d s0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  res->gsens_residual_rms = s0.mean() * f.rms;
}

// ---- quality figures (4.1.1) -----------------------------------------------------------------

StaticQuality quality_figures(const std::vector<Transfer>& transfers, const Candidate& best,
                              const ScannedRecording& scan, std::span<const ImuSample> samples,
                              const StillStart& still, const StaticCalibrationOptions& opt,
                              const TedaldiImuModel& model) {
  StaticQuality q;
  std::vector<GravityTransfer> checks;
  for (const auto& tr : transfers) checks.push_back({tr.u0, tr.u1, tr.gyro_raw, tr.t_s});
  q.accel_after = gravity_magnitude_error(best.means, model.accel, opt.gravity_mps2);
  q.gyro_after = gravity_direction_error(checks, model.gyro, opt.gravity_mps2);
  if (!opt.accel_init) return q;
  TedaldiTriad gyro_nominal;
  gyro_nominal.scale = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  gyro_nominal.bias = opt.gyro_init ? Eigen::Vector3d(-opt.gyro_init->offset) : Eigen::Vector3d::Zero();
  q.before_available = true;
  const TedaldiTriad accel_nominal = triad_from_conversion(*opt.accel_init);
  q.accel_before = gravity_magnitude_error(best.means, accel_nominal, opt.gravity_mps2);
  // Gravity directions from the nominal accelerometer, rates from the nominal gyro.
  std::vector<GravityTransfer> nominal = checks;
  const auto dirs = pose_directions(best.intervals, scan.accel, scan.gyro, samples, accel_nominal,
                                    initial_gyro(still.gyro_bias_raw, opt), threads_or_cores(opt.threads));
  for (std::size_t k = 0; k < nominal.size(); ++k) {
    nominal[k].u0 = dirs[transfers[k].pose0].u_end;
    nominal[k].u1 = dirs[transfers[k].pose0 + 1].u_start;
  }
  q.gyro_before = gravity_direction_error(nominal, gyro_nominal, opt.gravity_mps2);
  return q;
}

}  // namespace

Result<StaticCalibrationResult> calibrate_static(std::span<const ImuSample> samples,
                                                 const StaticCalibrationOptions& opt) {
  IMUCAL_TRY(opt.validate());
  StaticCalibrationResult res;
  res.gravity_mps2 = opt.gravity_mps2;
  if (samples.size() < 1000) {
    return make_error(Errc::kInsufficientData,
                      "the recording has " + std::to_string(samples.size()) +
                          " samples: a static calibration needs a still start (about 50 s) and 36-50 "
                          "held poses; record again");
  }
  Result<ScannedRecording> scan = scan_recording(samples, &res.warnings);
  if (!scan.ok()) return scan.error();

  auto t0 = Clock::now();
  const StaticDetection detection = detect_variance(*scan, opt.window_s);
  Result<StillStart> still = find_still_start(samples, *scan, detection, opt, &res.warnings);
  if (!still.ok()) return still.error();
  res.init_still_s = still->length_s;
  res.init_still_from_allan = still->from_allan;
  res.sigma_init_sq = still->sigma_init_sq;
  res.timings.detector_s = seconds_since(t0);

  t0 = Clock::now();
  AccelModel model = AccelModel::kFull;
  Result<Candidate> best =
      search_threshold(*scan, detection, *still, opt, &res.threshold_candidates, &model, &res.warnings);
  res.timings.threshold_search_s = seconds_since(t0);
  if (!best.ok()) return best.error();
  res.threshold_multiplier = best->multiplier;
  res.threshold = static_cast<double>(best->multiplier) * best->multiplier * res.sigma_init_sq;
  res.distinct_attitudes = best->distinct;

  t0 = Clock::now();
  IMUCAL_TRY(solve_accelerometer(*best, model, samples, opt, &res));
  res.timings.accel_s = seconds_since(t0);

  t0 = Clock::now();
  const GyroStaticFit gfit = final_gyro_static_fit(*best, *scan, samples, *still, opt, &res);
  const ScannedRecording corrected = without_gsens(*scan, gfit, res.model.accel);
  Result<std::vector<Transfer>> transfers = collect_transfers(best->intervals, corrected, samples, opt, &res);
  if (!transfers.ok()) return transfers.error();
  IMUCAL_TRY(solve_gyroscope(&*transfers, *best, corrected, samples, gfit, opt, &res));
  res.timings.gyro_s = seconds_since(t0);

  res.quality = quality_figures(*transfers, *best, *scan, samples, *still, opt, res.model);
  res.canonical = canonical_from_tedaldi(res.model);
  set_gsens_result(gfit, opt, &res);
  return res;
}

}  // namespace imucal::calib
