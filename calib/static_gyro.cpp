// SPDX-License-Identifier: BSD-3-Clause
#include "calib/static_gyro.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <future>
#include <limits>
#include <memory>

#include "calib/rk4.hpp"
#include "calib/static_steps.hpp"
#include "core/threads.hpp"

namespace imucal::calib {

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

namespace {

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

}  // namespace

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

/// The motions between consecutive static poses that can be integrated: none crossing a gap, a
/// reset or a saturated gyro sample. Refuses when fewer than min_attitudes - 1 remain.
Result<std::vector<Transfer>> collect_transfers(const std::vector<StaticInterval>& intervals,
                                                const ScannedRecording& scan,
                                                std::span<const ImuSample> samples,
                                                const StaticCalibrationOptions& opt,
                                                std::vector<std::string>* warnings) {
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
    warnings->push_back(std::to_string(dropped) + " motion(s) between static poses were not used for the " +
                        "gyroscope: " + std::to_string(dropped_gap) + " contain a gap or a device reset, " +
                        std::to_string(dropped_sat) + " contain saturated gyro samples");
  }
  const int usable = static_cast<int>(transfers.size());
  // Each motion gives two independent equations (a direction): more than the gyro's 9 parameters
  // (12 with its bias) take 5 (7). Six faces in turn give exactly 5.
  const int min_transfers = opt.estimate_gyro_bias ? 7 : 5;
  if (usable < min_transfers) {
    return make_error(Errc::kInsufficientData,
                      "only " + std::to_string(usable) + " of " + std::to_string(usable + dropped) +
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

namespace {

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
                                          const AccelForGyro& accel, const TedaldiTriad& gyro) {
  const Vec9 pa = accel_params(accel.triad);
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
  const Eigen::Matrix3d A = gyro.TK();
  std::vector<Eigen::Vector3d> w;
  for (std::size_t t = 0; t < transfers.size(); ++t) {
    const auto& tr = transfers[t];
    w.resize(tr.gyro_raw.size());
    for (std::size_t i = 0; i < w.size(); ++i) w[i] = A * (tr.gyro_raw[i] + gyro.bias);
    const Eigen::Matrix3d R = quat_to_matrix(integrate_rk4n(w, tr.t_s));
    Ja.middleRows(3 * t, 3) = du[tr.pose0 + 1] - R.transpose() * du[tr.pose0];
  }
  const Eigen::MatrixXd D = -normal_pseudo_inverse(Jg) * (Jg.transpose() * Ja);
  return D * accel.covariance * D.transpose();
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

}  // namespace

/// The gyro model before the solve: the nominal scale, the given bias (input units, canonical sign).
TedaldiTriad initial_gyro(const Eigen::Vector3d& bias_raw, const StaticCalibrationOptions& opt) {
  TedaldiTriad gyro0;
  gyro0.scale = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  gyro0.bias = -bias_raw;
  return gyro0;
}

namespace {

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
Status gyro_solve(std::vector<Transfer>* transfers, const GyroSolveInput& best, const ScannedRecording& scan,
                  std::span<const ImuSample> samples, const StaticCalibrationOptions& opt,
                  const AccelForGyro& accel, const std::vector<int>& held, GyroPiece* g,
                  std::vector<int>* weak) {
  const TedaldiTriad gyro0 = initial_gyro(best.bias, opt);
  const int threads = threads_or_cores(opt.threads);
  GyroFit fit(*transfers, gyro0, opt.estimate_gyro_bias, threads, held);
  TedaldiTriad gyro_current = gyro0;
  for (int pass = 0; pass < 2; ++pass) {
    set_transfer_directions(transfers, best.intervals, scan, samples, accel.triad, gyro_current, threads);
    IMUCAL_TRY(fit.solve(&g->iterations, pass == 0));
    gyro_current = fit.triad();
  }
  const double m_res = 3.0 * static_cast<double>(transfers->size());
  g->residual_rms = std::sqrt(2.0 * fit.final_cost() / m_res);
  g->triad = fit.triad();
  // One Jacobian evaluation at the solution serves both the covariance and the propagation of
  // the accelerometer uncertainty.
  Result<Eigen::MatrixXd> Jg = fit.jacobian();
  if (!Jg.ok()) return Jg.error();
  g->dof = {static_cast<int>(m_res), fit.fitted()};
  const double s2 =
      g->dof.determined() ? 2.0 * fit.final_cost() / g->dof.dof() : std::numeric_limits<double>::quiet_NaN();
  if (held.empty()) {
    g->covariance = normal_pseudo_inverse(*Jg) * s2;
  } else {
    g->covariance = held_covariance(*Jg, held, s2, g->triad.scale, opt);
  }
  g->covariance += accel_uncertainty_in_gyro(*Jg, *transfers, best.means, accel, g->triad);
  g->sigma = gyro_sigma(g->covariance, opt.estimate_gyro_bias, best.bias_sigma);
  if (weak) *weak = undetermined_gyro_parameters(*Jg, held, s2, g->triad.scale, opt);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  static const int row[] = {0, 0, 1, 1, 2, 2}, col[] = {1, 2, 0, 2, 0, 1};
  for (int i : held) {
    if (i < 6)
      g->sigma.T(row[i], col[i]) = nan;
    else
      g->sigma.scale[i - 6] = nan;
  }
  return {};
}

/// The gyro at its nominal scale without misalignment, the bias from the static poses: what is
/// left when the motions determine none of its scales and misalignments.
void nominal_gyro(const std::vector<Transfer>& transfers, const GyroSolveInput& best,
                  const StaticCalibrationOptions& opt, GyroPiece* g) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  g->triad = initial_gyro(best.bias, opt);
  const int n = opt.estimate_gyro_bias ? 12 : 9;
  g->dof = {3 * static_cast<int>(transfers.size()), 0};
  g->covariance = Eigen::MatrixXd::Zero(n, n);
  g->sigma = gyro_sigma(g->covariance, false, best.bias_sigma);
  g->sigma.T.setConstant(nan);
  g->sigma.T.diagonal().setZero();
  g->sigma.scale.setConstant(nan);
}

}  // namespace

/// Eqs. 3.5-3.16: the gyro solve. Parameters the motions leave undetermined (a few motions about
/// one or two axes, as six faces turned in sequence give) are held at their nominal values (no
/// misalignment, the nominal scale), named, and the rest solved again.
Result<GyroPiece> solve_gyroscope(std::vector<Transfer>* transfers, const GyroSolveInput& best,
                                  const AccelForGyro& accel, const ScannedRecording& scan,
                                  std::span<const ImuSample> samples, const StaticCalibrationOptions& opt) {
  GyroPiece g;
  std::vector<int> held;
  for (int round = 0; round < 3; ++round) {
    std::vector<int> weak;
    IMUCAL_TRY(gyro_solve(transfers, best, scan, samples, opt, accel, held, &g, &weak));
    if (weak.empty()) break;
    held.insert(held.end(), weak.begin(), weak.end());
    std::sort(held.begin(), held.end());
    if (held.size() == 9) {
      nominal_gyro(*transfers, best, opt, &g);
      break;
    }
  }
  g.fixed.clear();
  for (int i : held) g.fixed.emplace_back(gyro_parameter_name(i));
  if (!held.empty()) {
    std::string names;
    for (const auto& n : g.fixed) names += (names.empty() ? "" : ", ") + n;
    g.warnings.push_back("the " + std::to_string(transfers->size()) +
                         " motions between the static poses do not determine the gyroscope's " + names +
                         " (sigma above " + format_number("%.3f", opt.gyro_max_misalignment_sigma_rad) +
                         " rad or " + format_number("%.1f", 100.0 * opt.gyro_max_scale_rel_sigma) +
                         " %): held at nominal (no misalignment, the nominal scale). Turn the rig about each "
                         "of its three axes between holds, both ways");
  }
  return g;
}

}  // namespace imucal::calib
