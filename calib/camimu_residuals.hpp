// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The residuals of the camera-IMU problem (calib/camimu_calibration.cpp), with analytic
// Jacobians built on the spline Jacobians of calib/spline.hpp. Internal to the estimator.
//
// Parameter blocks:
//   rotation knots and R_cam_imu, C_bg: unit quaternions (Eigen order x, y, z, w) on the
//     RightQuaternionManifold below, whose tangent is a right perturbation q <- q Exp(delta); the
//     cost functions write the 3 tangent columns into the first 3 of the 4 ambient ones;
//   position, bias knots: R^3;  gravity: R^3 on a sphere;  S_a, M_a, S_g, M_g: R^3;
//   B_g: R^9 row-major;  t_cam_imu: R^3;  timeshift: R^1 (s).

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "calib/so3.hpp"
#include "calib/spline.hpp"
#include "core/camera_model.hpp"

namespace imucal::calib::camimu {

/// q <- q Exp(delta); the Jacobian trick of PlusJacobian = [I; 0] lets cost functions return
/// tangent-space Jacobians directly in the first three ambient columns.
class RightQuaternionManifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 4; }
  int TangentSize() const override { return 3; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    const Eigen::Map<const Eigen::Quaterniond> q(x);
    const Eigen::Quaterniond dq(so3::exp(Eigen::Map<const Eigen::Vector3d>(delta)));
    Eigen::Map<Eigen::Quaterniond> out(x_plus_delta);
    out = (q * dq).normalized();
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 4, 3, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.topRows<3>().setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    const Eigen::Map<const Eigen::Quaterniond> qy(y), qx(x);
    Eigen::Map<Eigen::Vector3d> out(y_minus_x);
    out = so3::log((qx.conjugate() * qy).toRotationMatrix());
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 3, 4, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.leftCols<3>().setIdentity();
    return true;
  }
};

inline Eigen::Matrix3d quat_matrix(const double* q) {
  return Eigen::Map<const Eigen::Quaterniond>(q).normalized().toRotationMatrix();
}

/// Writes a rows x 3 tangent Jacobian into a rows x ambient (row-major) block.
template <int Rows>
inline void put(double* jac, int ambient, int row0, int rows_total, const Eigen::Matrix<double, Rows, 3>& J,
                int col0 = 0) {
  (void)rows_total;
  for (int r = 0; r < Rows; ++r)
    for (int c = 0; c < 3; ++c) jac[(row0 + r) * ambient + col0 + c] = J(r, c);
}

/// The lower unit-triangular M of the Krebs model applied to v, and its Jacobian in [m0 m1 m2].
inline Eigen::Vector3d apply_m(const double* m, const Eigen::Vector3d& v) {
  return {v.x(), m[0] * v.x() + v.y(), m[1] * v.x() + m[2] * v.y() + v.z()};
}
inline Eigen::Matrix3d m_matrix(const double* m) {
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  M(1, 0) = m[0];
  M(2, 0) = m[1];
  M(2, 1) = m[2];
  return M;
}
inline Eigen::Matrix3d dm_jacobian(const Eigen::Vector3d& s, const Eigen::Vector3d& v) {
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();  // d (s .* (M v)) / d [m0 m1 m2]
  J(1, 0) = s.y() * v.x();
  J(2, 1) = s.z() * v.x();
  J(2, 2) = s.z() * v.y();
  return J;
}

/// One IMU sample: gyroscope and accelerometer residuals of the Krebs model, whitened.
/// Blocks: N rotation knots, N position knots, N accel-bias knots, N gyro-bias knots, gravity,
/// S_a, M_a, S_g, M_g, C_bg, B_g.
template <int N>
class ImuResidual final : public ceres::CostFunction {
 public:
  struct Sample {
    double u = 0.0;       // in the pose segment
    double u_bias = 0.0;  // in the bias segment
    double dt_s = 0.0, bias_dt_s = 0.0;
    Eigen::Vector3d accel, gyro;
  };
  ImuResidual(const Sample& sample, double sigma_a, double sigma_g)
      : s_(sample), wa_(1 / sigma_a), wg_(1 / sigma_g) {
    set_num_residuals(6);
    auto* sizes = mutable_parameter_block_sizes();
    for (int i = 0; i < N; ++i) sizes->push_back(4);
    for (int i = 0; i < 3 * N; ++i) sizes->push_back(3);
    for (int s : {3, 3, 3, 3, 3, 4, 9}) sizes->push_back(s);
  }
  static constexpr int kGravity = 4 * N, kSa = kGravity + 1, kMa = kSa + 1, kSg = kMa + 1, kMg = kSg + 1,
                       kC = kMg + 1, kB = kC + 1;

  /// Residuals: (predicted - measured) / sigma, accel then gyro.
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override;

 private:
  Sample s_;
  double wa_, wg_;
};

template <int N>
bool ImuResidual<N>::Evaluate(double const* const* p, double* residuals, double** jac) const {
  std::array<Eigen::Matrix3d, N> Rk;
  std::array<const Eigen::Matrix3d*, N> ptr;
  for (int i = 0; i < N; ++i) {
    Rk[i] = quat_matrix(p[i]);
    ptr[i] = &Rk[i];
  }
  So3SegmentEval<N> e;
  So3Segment<N>::evaluate(ptr.data(), s_.u, s_.dt_s, So3Derivs::kVelocity, jac != nullptr, &e);
  const auto w2 = RdSpline<N>::weights_at(s_.u, 2, s_.dt_s);
  const auto wb = RdSpline<N>::weights_at(s_.u_bias, 0, s_.bias_dt_s);
  Eigen::Vector3d pdd = Eigen::Vector3d::Zero(), ba = Eigen::Vector3d::Zero(), bg = Eigen::Vector3d::Zero();
  for (int i = 0; i < N; ++i) {
    pdd += w2(i) * Eigen::Map<const Eigen::Vector3d>(p[N + i]);
    ba += wb(i) * Eigen::Map<const Eigen::Vector3d>(p[2 * N + i]);
    bg += wb(i) * Eigen::Map<const Eigen::Vector3d>(p[3 * N + i]);
  }
  const Eigen::Map<const Eigen::Vector3d> g(p[kGravity]), Sa(p[kSa]), Sg(p[kSg]);
  const Eigen::Matrix3d Ct = quat_matrix(p[kC]).transpose();
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> B(p[kB]);
  const Eigen::Matrix3d Rt = e.R.transpose();
  const Eigen::Vector3d f = Rt * (pdd - g);  // specific force, body
  const Eigen::Vector3d Mf = apply_m(p[kMa], f);
  const Eigen::Vector3d cw = Ct * e.omega, cf = Ct * f;
  const Eigen::Vector3d Mw = apply_m(p[kMg], cw);
  const Eigen::Vector3d a_pred = Sa.cwiseProduct(Mf) + ba;
  const Eigen::Vector3d g_pred = Sg.cwiseProduct(Mw) + B * cf + bg;
  Eigen::Map<Eigen::Matrix<double, 6, 1>> r(residuals);
  r.head<3>() = wa_ * (a_pred - s_.accel);
  r.tail<3>() = wg_ * (g_pred - s_.gyro);
  if (!jac) return true;

  const Eigen::Matrix3d dA_df = wa_ * Sa.asDiagonal() * m_matrix(p[kMa]);
  const Eigen::Matrix3d dG_dw = wg_ * Sg.asDiagonal() * m_matrix(p[kMg]) * Ct;
  const Eigen::Matrix3d dG_df = wg_ * B * Ct;
  const Eigen::Matrix3d df_deps = so3::hat(f);
  for (int i = 0; i < N; ++i) {
    if (jac[i]) {
      Eigen::Map<Eigen::Matrix<double, 6, 4, Eigen::RowMajor>> J(jac[i]);
      J.setZero();
      J.template block<3, 3>(0, 0) = dA_df * df_deps * e.dR_dknot[i];
      J.template block<3, 3>(3, 0) = dG_dw * e.domega_dknot[i] + dG_df * df_deps * e.dR_dknot[i];
    }
    if (jac[N + i]) {
      Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[N + i]);
      J.template topRows<3>() = dA_df * Rt * w2(i);
      J.template bottomRows<3>() = dG_df * Rt * w2(i);
    }
    if (jac[2 * N + i]) {
      Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[2 * N + i]);
      J.setZero();
      J.template topRows<3>() = wa_ * wb(i) * Eigen::Matrix3d::Identity();
    }
    if (jac[3 * N + i]) {
      Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[3 * N + i]);
      J.setZero();
      J.template bottomRows<3>() = wg_ * wb(i) * Eigen::Matrix3d::Identity();
    }
  }
  if (jac[kGravity]) {
    Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[kGravity]);
    J.template topRows<3>() = -dA_df * Rt;
    J.template bottomRows<3>() = -dG_df * Rt;
  }
  if (jac[kSa]) {
    Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[kSa]);
    J.setZero();
    J.template topRows<3>() = wa_ * Mf.asDiagonal();
  }
  if (jac[kMa]) {
    Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[kMa]);
    J.setZero();
    J.template topRows<3>() = wa_ * dm_jacobian(Sa, f);
  }
  if (jac[kSg]) {
    Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[kSg]);
    J.setZero();
    J.template bottomRows<3>() = wg_ * Mw.asDiagonal();
  }
  if (jac[kMg]) {
    Eigen::Map<Eigen::Matrix<double, 6, 3, Eigen::RowMajor>> J(jac[kMg]);
    J.setZero();
    J.template bottomRows<3>() = wg_ * dm_jacobian(Sg, cw);
  }
  if (jac[kC]) {
    // C^T -> Exp(-delta) C^T: d(C^T v)/d delta = [C^T v]x.
    Eigen::Map<Eigen::Matrix<double, 6, 4, Eigen::RowMajor>> J(jac[kC]);
    J.setZero();
    J.template block<3, 3>(3, 0) =
        wg_ * (Sg.asDiagonal() * m_matrix(p[kMg]) * so3::hat(cw) + B * so3::hat(cf));
  }
  if (jac[kB]) {
    Eigen::Map<Eigen::Matrix<double, 6, 9, Eigen::RowMajor>> J(jac[kB]);
    J.setZero();
    for (int row = 0; row < 3; ++row)
      for (int c = 0; c < 3; ++c) J(3 + row, 3 * row + c) = wg_ * cf(c);
  }
  return true;
}

/// The bias random walk: the bias derivative at Gauss-Legendre points of one bias segment,
/// weighted so that the sum of squares is the integral of |db/dt|^2 / sigma_rw^2.
/// Blocks: the segment's N bias knots.
template <int N>
class BiasWalkResidual final : public ceres::CostFunction {
 public:
  /// `weight` = sqrt(quadrature weight * segment length) / sigma_rw.
  BiasWalkResidual(double u, double dt_s, double weight) : w1_(weight * RdSpline<N>::weights_at(u, 1, dt_s)) {
    set_num_residuals(3);
    for (int i = 0; i < N; ++i) mutable_parameter_block_sizes()->push_back(3);
  }
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r.setZero();
    for (int i = 0; i < N; ++i) {
      r += w1_(i) * Eigen::Map<const Eigen::Vector3d>(p[i]);
      if (jac && jac[i]) {
        Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> J(jac[i]);
        J = w1_(i) * Eigen::Matrix3d::Identity();
      }
    }
    return true;
  }

 private:
  Eigen::Matrix<double, N, 1> w1_;
};

/// The pose of the spline (world from body) at time t_s, from the knots of a window of
/// N + 2 rotation knots (p[q0] ...) and N + 2 position knots (p[p0] ...) starting at knot
/// `first`: the rotation with its derivatives (So3SegmentEval), the segment's first knot in the
/// window (k0, clamped to 0..2), position, velocity and the position weights.
template <int N>
struct SplinePose {
  So3SegmentEval<N> e;
  int k0 = 0;
  Eigen::Vector3d pos, vel;
  Eigen::Matrix<double, N, 1> w0;
};
template <int N>
SplinePose<N> spline_pose(double const* const* p, int q0, int p0, double t_s, int first,
                          const SplineTiming<N>& timing, bool jacobians) {
  SplinePose<N> out;
  const SplineSegment seg = timing.segment(t_s);
  out.k0 = std::max(0, std::min(2, seg.first_knot - first));
  const double u = (t_s - timing.t0_s) / timing.dt_s - (first + out.k0);
  std::array<Eigen::Matrix3d, N> Rk;
  std::array<const Eigen::Matrix3d*, N> ptr;
  for (int i = 0; i < N; ++i) {
    Rk[i] = quat_matrix(p[q0 + out.k0 + i]);
    ptr[i] = &Rk[i];
  }
  So3Segment<N>::evaluate(ptr.data(), u, timing.dt_s, So3Derivs::kVelocity, jacobians, &out.e);
  out.w0 = RdSpline<N>::weights_at(u, 0, timing.dt_s);
  const auto w1 = RdSpline<N>::weights_at(u, 1, timing.dt_s);
  out.pos.setZero();
  out.vel.setZero();
  for (int i = 0; i < N; ++i) {
    const Eigen::Map<const Eigen::Vector3d> P(p[p0 + out.k0 + i]);
    out.pos += out.w0(i) * P;
    out.vel += w1(i) * P;
  }
  return out;
}

/// A corner's rows (row, row + 1) of the Jacobians in the time offset and a rolling shutter's line
/// delay (either may be null): `d` is d r / d t at the corner's time, and its time moves by
/// `row_offset` per unit of line delay.
inline void put_time_jacobians(double* j_shift, double* j_line_delay, int row, const Eigen::Vector2d& d,
                               double row_offset) {
  if (j_shift) {
    j_shift[row] = d(0);
    j_shift[row + 1] = d(1);
  }
  if (j_line_delay) {
    j_line_delay[row] = row_offset * d(0);
    j_line_delay[row + 1] = row_offset * d(1);
  }
}

/// A weighted 2-vector residual e with the Cauchy loss rho(s) = c2 log(1 + s / c2) folded in:
/// r = g(s) e with g = sqrt(rho(s) / s), so that |r|^2 = rho(s); `L` (may be null) receives its
/// exact Jacobian in e, g I + 2 g'(s) e e^T. c2 = infinity leaves e unchanged.
inline void fold_cauchy(const Eigen::Vector2d& e, double c2, Eigen::Vector2d* r, Eigen::Matrix2d* L) {
  const double s = e.squaredNorm();
  double g = 1.0, dg = std::isinf(c2) ? 0.0 : -0.25 / c2;  // limits at s -> 0
  if (!std::isinf(c2) && s > 1e-12 * c2) {
    const double rho = c2 * std::log1p(s / c2), rho1 = 1.0 / (1.0 + s / c2);
    g = std::sqrt(rho / s);
    dg = (rho1 * s - rho) / (2.0 * s * s * g);
  }
  *r = g * e;
  if (L) *L = g * Eigen::Matrix2d::Identity() + 2.0 * dg * e * e.transpose();
}

/// All target corners of one frame: reprojection at t_cam + timeshift with a Cauchy loss per
/// corner applied inside (so the pose is evaluated once per frame). Blocks: N + 2 rotation knots,
/// N + 2 position knots (the window the timeshift may move the frame in), R_cam_imu, t_cam_imu,
/// timeshift, and for a rolling shutter the line delay.
///
/// Rolling shutter: corner k, observed in image row v_k, is seen at t_cam + timeshift +
/// row_offset(v_k) line_delay (core/camera_model.hpp Shutter; the observed row stands for the
/// row the corner was read out in, which differs from it by the pixel noise only), so each corner
/// has its own pose on the spline; d r / d line_delay = row_offset(v_k) d r / d timeshift. The
/// corners then do not share one pose and are not compressed.
///
/// Compressed (the default): every parameter moves the corners only through the camera's pose,
/// dp_cam = -[p_cam]x w + v for a rigid motion (w, v) of the camera frame, so the 2n corner rows
/// r = F G dx (F: 2n x 6, G: 6 x parameters) are replaced by 7 rows with the same cost, gradient
/// and Gauss-Newton matrix: R G with R^T R = F^T F, the residual R^-T F^T r, and a seventh
/// residual that carries the rest of |r|^2 (zero Jacobian; its gradient is already in the first
/// six). The solver then forms J^T J from 7 rows a frame instead of 2n (docs/camimu-calibration.md,
/// "Speed"). Uncompressed, the 2n weighted corner residuals themselves.
template <int N>
class FrameResidual final : public ceres::CostFunction {
 public:
  static constexpr int kWindow = N + 2;
  static constexpr int kCompressedRows = 7;
  FrameResidual(const CameraModel& camera, std::vector<Eigen::Vector3d> points_w,
                std::vector<Eigen::Vector2d> px, double t_cam_s, int first_window_knot,
                const SplineTiming<N>& timing, double sigma_px, double loss_scale_px, bool compressed = true,
                bool rolling = false)
      : camera_(camera),
        camera_jet_(camera.cast<ceres::Jet<double, 3>>()),
        points_(std::move(points_w)),
        px_(std::move(px)),
        t_cam_s_(t_cam_s),
        first_(first_window_knot),
        timing_(timing),
        w_(1.0 / sigma_px),
        c2_((loss_scale_px / sigma_px) * (loss_scale_px / sigma_px)),
        compressed_(compressed && !rolling),
        rolling_(rolling) {
    set_num_residuals(compressed_ ? kCompressedRows : 2 * static_cast<int>(points_.size()));
    auto* sizes = mutable_parameter_block_sizes();
    for (int i = 0; i < kWindow; ++i) sizes->push_back(4);
    for (int i = 0; i < kWindow; ++i) sizes->push_back(3);
    for (int s : {4, 3, 1}) sizes->push_back(s);
    if (rolling_) {
      sizes->push_back(1);
      off_min_ = std::numeric_limits<double>::infinity();
      off_max_ = -off_min_;
      // The camera's readout direction and stamped row, whatever kind its file says (a camera
      // whose shutter is being tested is still global there).
      Shutter shutter = camera_.shutter;
      shutter.kind = Shutter::Kind::kRolling;
      for (const auto& q : px_) {
        const double off = shutter.row_offset(q.y(), camera_.height);
        row_offset_.push_back(off);
        off_min_ = std::min(off_min_, off);
        off_max_ = std::max(off_max_, off);
      }
      if (row_offset_.empty()) off_min_ = off_max_ = 0.0;  // a frame without corners
    }
  }
  static constexpr int kRci = 2 * kWindow, kTci = kRci + 1, kShift = kTci + 1, kLineDelay = kShift + 1;

  /// Whether every corner's time (for a timeshift and a line delay) lies in a segment of the
  /// window; false when they have moved the frame out of it (the problem is then rebuilt).
  bool in_window(double shift_s, double line_delay_s = 0.0) const {
    for (double off : {off_min_, off_max_}) {
      const int k = timing_.segment(t_cam_s_ + shift_s + off * line_delay_s).first_knot - first_;
      if (k < 0 || k > 2) return false;
    }
    return true;
  }
  bool rolling() const { return rolling_; }
  /// Weighted residuals with the loss folded in (compressed or per corner, see above).
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    return compressed_ ? evaluate_compressed(p, residuals, jac) : evaluate_corners(p, residuals, jac);
  }
  /// The same without the robust loss, in pixels.
  void pixel_residuals(double const* const* p, std::vector<Eigen::Vector2d>* out) const;
  /// The Gauss-Newton change of the gradient, J^T dr, when the camera's intrinsics move along
  /// each of `moves` (the camera moved by +-h along the direction, the corners' change taken as
  /// (plus(p_cam) - minus(p_cam)) * scale, scale = 1 / (2 h)): per move, one tangent-space vector
  /// per parameter block (quaternion blocks: 3). J and dr are the corners' own (uncompressed)
  /// ones, so the result does not depend on the compressed rows' basis. For MarginalCovariance's
  /// held inputs.
  std::vector<std::vector<Eigen::VectorXd>> intrinsics_scores(
      double const* const* p, const std::vector<std::pair<CameraModel, CameraModel>>& moves,
      double scale) const;
  std::size_t corners() const { return points_.size(); }
  /// The variance of the corners' image rows, px^2 (0 without corners).
  double row_variance() const {
    if (px_.empty()) return 0.0;
    double mean = 0.0, sq = 0.0;
    for (const auto& q : px_) mean += q.y();
    mean /= static_cast<double>(px_.size());
    for (const auto& q : px_) sq += (q.y() - mean) * (q.y() - mean);
    return sq / static_cast<double>(px_.size());
  }

 private:
  using Pose = SplinePose<N>;
  Pose pose(double const* const* p, bool jacobians) const {
    return spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0], first_, timing_, jacobians);
  }
  /// The pose at corner k's time (a rolling shutter's row).
  Pose corner_pose(double const* const* p, std::size_t k, bool jacobians) const {
    return spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0] + row_offset_[k] * p[kLineDelay][0], first_,
                          timing_, jacobians);
  }
  bool evaluate_corners(double const* const* p, double* residuals, double** jac) const;
  bool evaluate_compressed(double const* const* p, double* residuals, double** jac) const;
  /// The weighted residual of one corner with the Cauchy loss folded in (fold_cauchy).
  void fold(const Eigen::Vector2d& e, Eigen::Vector2d* r, Eigen::Matrix2d* L) const {
    fold_cauchy(e, c2_, r, L);
  }
  /// Projection and its Jacobian in p_cam.
  Eigen::Vector2d project(const Eigen::Vector3d& pc, Eigen::Matrix<double, 2, 3>* J) const;

  CameraModel camera_;
  CameraModelT<ceres::Jet<double, 3>> camera_jet_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<Eigen::Vector2d> px_;
  double t_cam_s_;
  int first_;
  SplineTiming<N> timing_;
  double w_;
  double c2_;
  bool compressed_;
  bool rolling_;
  std::vector<double> row_offset_;  // rolling: each corner's row_offset(v)
  double off_min_ = 0.0, off_max_ = 0.0;
};

template <int N>
Eigen::Vector2d FrameResidual<N>::project(const Eigen::Vector3d& pc, Eigen::Matrix<double, 2, 3>* J) const {
  if (!J) return camera_.project(pc).px;
  using Jet = ceres::Jet<double, 3>;
  Eigen::Matrix<Jet, 3, 1> x;
  for (int i = 0; i < 3; ++i) x(i) = Jet(pc(i), i);
  const auto pr = camera_jet_.project(x);
  for (int r = 0; r < 2; ++r) J->row(r) = pr.px(r).v.transpose();
  return {pr.px(0).a, pr.px(1).a};
}

template <int N>
void FrameResidual<N>::pixel_residuals(double const* const* p, std::vector<Eigen::Vector2d>* out) const {
  Pose ps = pose(p, false);
  const Eigen::Matrix3d Rci = quat_matrix(p[kRci]);
  const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
  out->clear();
  for (std::size_t k = 0; k < points_.size(); ++k) {
    if (rolling_) ps = corner_pose(p, k, false);
    out->push_back(project(Rci * (ps.e.R.transpose() * (points_[k] - ps.pos)) + tci, nullptr) - px_[k]);
  }
}

template <int N>
std::vector<std::vector<Eigen::VectorXd>> FrameResidual<N>::intrinsics_scores(
    double const* const* p, const std::vector<std::pair<CameraModel, CameraModel>>& moves,
    double scale) const {
  // The corners' Jacobian (the uncompressed form of this frame) and each move's corner changes.
  const FrameResidual corners(camera_, points_, px_, t_cam_s_, first_, timing_, 1.0 / w_, std::sqrt(c2_) / w_,
                              /*compressed=*/false, rolling_);
  const int m = corners.num_residuals();
  const auto& sizes = corners.parameter_block_sizes();
  std::vector<std::vector<double>> jac(sizes.size());
  std::vector<double*> jptr;
  for (std::size_t b = 0; b < sizes.size(); ++b) {
    jac[b].assign(static_cast<std::size_t>(m * sizes[b]), 0.0);
    jptr.push_back(jac[b].data());
  }
  Eigen::VectorXd r(m);
  corners.Evaluate(p, r.data(), jptr.data());
  std::vector<std::vector<Eigen::VectorXd>> out;
  for (const auto& [plus, minus] : moves) {
    Eigen::VectorXd dr(m);
    Pose ps = pose(p, false);
    const Eigen::Matrix3d Rci = quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
    for (std::size_t k = 0; k < points_.size(); ++k) {
      if (rolling_) ps = corner_pose(p, k, false);
      const Eigen::Vector3d pc = Rci * (ps.e.R.transpose() * (points_[k] - ps.pos)) + tci;
      Eigen::Vector2d rk;
      Eigen::Matrix2d L;
      fold(w_ * (project(pc, nullptr) - px_[k]), &rk, &L);
      dr.segment<2>(2 * static_cast<Eigen::Index>(k)) =
          L * (w_ * scale * (plus.project(pc).px - minus.project(pc).px));
    }
    std::vector<Eigen::VectorXd> scores;
    for (std::size_t b = 0; b < sizes.size(); ++b) {
      const int cols = sizes[b] == 4 ? 3 : sizes[b];  // quaternions: the tangent columns first
      const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
          jac[b].data(), m, sizes[b]);
      scores.push_back(J.leftCols(cols).transpose() * dr);
    }
    out.push_back(std::move(scores));
  }
  return out;
}

template <int N>
bool FrameResidual<N>::evaluate_corners(double const* const* p, double* residuals, double** jac) const {
  Pose ps = pose(p, jac != nullptr);
  Eigen::Matrix3d Rt = ps.e.R.transpose();
  const Eigen::Matrix3d Rci = quat_matrix(p[kRci]);
  const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
  const int rows = num_residuals();
  const int blocks = static_cast<int>(parameter_block_sizes().size());
  if (jac) {
    for (int b = 0; b < blocks; ++b)
      if (jac[b]) std::fill(jac[b], jac[b] + rows * parameter_block_sizes()[b], 0.0);
  }
  for (std::size_t k = 0; k < points_.size(); ++k) {
    if (rolling_) {
      ps = corner_pose(p, k, jac != nullptr);
      Rt = ps.e.R.transpose();
    }
    const Eigen::Vector3d pb = Rt * (points_[k] - ps.pos);
    const Eigen::Vector3d pc = Rci * pb + tci;
    Eigen::Matrix<double, 2, 3> Jp;
    const Eigen::Vector2d e = w_ * (project(pc, jac ? &Jp : nullptr) - px_[k]);
    Eigen::Vector2d r;
    Eigen::Matrix2d L;
    fold(e, &r, jac ? &L : nullptr);
    Eigen::Map<Eigen::Vector2d>(residuals + 2 * k) = r;
    if (!jac) continue;
    const Eigen::Matrix<double, 2, 3> Jc = L * w_ * Jp;  // d r / d p_cam
    const Eigen::Matrix<double, 2, 3> Jb = Jc * Rci;     // d r / d p_body
    const int row = 2 * static_cast<int>(k);
    for (int i = 0; i < N; ++i) {
      if (jac[ps.k0 + i]) put<2>(jac[ps.k0 + i], 4, row, rows, Jb * so3::hat(pb) * ps.e.dR_dknot[i]);
      if (jac[kWindow + ps.k0 + i]) put<2>(jac[kWindow + ps.k0 + i], 3, row, rows, -Jb * Rt * ps.w0(i));
    }
    if (jac[kRci]) put<2>(jac[kRci], 4, row, rows, -Jc * Rci * so3::hat(pb));
    if (jac[kTci]) put<2>(jac[kTci], 3, row, rows, Jc);
    double* j_line_delay = rolling_ ? jac[kLineDelay] : nullptr;
    if (jac[kShift] || j_line_delay)
      put_time_jacobians(jac[kShift], j_line_delay, row, Jb * (so3::hat(pb) * ps.e.omega - Rt * ps.vel),
                         rolling_ ? row_offset_[k] : 0.0);
  }
  return true;
}

template <int N>
bool FrameResidual<N>::evaluate_compressed(double const* const* p, double* residuals, double** jac) const {
  const Pose ps = pose(p, jac != nullptr);
  const Eigen::Matrix3d Rt = ps.e.R.transpose(), Rci = quat_matrix(p[kRci]);
  const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
  Eigen::Map<Eigen::Matrix<double, kCompressedRows, 1>> out(residuals);
  double sum = 0.0;  // |r|^2 over the corners
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  for (std::size_t k = 0; k < points_.size(); ++k) {
    const Eigen::Vector3d pc = Rci * (Rt * (points_[k] - ps.pos)) + tci;
    Eigen::Matrix<double, 2, 3> Jp;
    const Eigen::Vector2d e = w_ * (project(pc, jac ? &Jp : nullptr) - px_[k]);
    Eigen::Vector2d r;
    Eigen::Matrix2d L;
    fold(e, &r, jac ? &L : nullptr);
    sum += r.squaredNorm();
    if (!jac) continue;
    const Eigen::Matrix<double, 2, 3> Jc = L * w_ * Jp;
    Eigen::Matrix<double, 2, 6> F;  // d r / d (w, v) of the camera frame
    F.leftCols<3>() = -Jc * so3::hat(pc);
    F.rightCols<3>() = Jc;
    A.noalias() += F.transpose() * F;
    b.noalias() += F.transpose() * r;
  }
  if (!jac) {
    // Only the cost is asked for: the same norm, all of it in the last row.
    out.setZero();
    out(kCompressedRows - 1) = std::sqrt(sum);
    return true;
  }
  // A = V diag(l) V^T; R = diag(sqrt l) V^T; R^-T b = diag(1 / sqrt l) V^T b (b lies in A's range;
  // directions of A below 1e-12 of its largest eigenvalue are taken as empty).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(A);
  const Eigen::Matrix<double, 6, 1> l = es.eigenvalues();
  const double floor = 1e-12 * std::max(l.maxCoeff(), 0.0);
  Eigen::Matrix<double, 6, 6> R;
  const Eigen::Matrix<double, 6, 1> Vb = es.eigenvectors().transpose() * b;
  for (int i = 0; i < 6; ++i) {
    const bool empty = !(l(i) > floor);
    const double sq = empty ? 0.0 : std::sqrt(l(i));
    R.row(i) = sq * es.eigenvectors().col(i).transpose();
    out(i) = empty ? 0.0 : Vb(i) / sq;
  }
  out(kCompressedRows - 1) = std::sqrt(std::max(0.0, sum - out.head<6>().squaredNorm()));
  const int rows = kCompressedRows;
  for (int blk = 0; blk < 2 * kWindow + 3; ++blk)
    if (jac[blk]) std::fill(jac[blk], jac[blk] + rows * parameter_block_sizes()[blk], 0.0);
  // G: d (w, v) / d block, 6 x 3 (tangent) for each block; written as R G into the first 6 rows.
  const Eigen::Matrix3d tx = so3::hat(tci);
  const auto write = [&](double* J, int ambient, const Eigen::Matrix<double, 6, 3>& G) {
    const Eigen::Matrix<double, 6, 3> RG = R * G;
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 3; ++c) J[r * ambient + c] = RG(r, c);
  };
  Eigen::Matrix<double, 6, 3> G;
  for (int i = 0; i < N; ++i) {
    if (double* J = jac[ps.k0 + i]) {
      const Eigen::Matrix3d RD = Rci * ps.e.dR_dknot[i];
      G.topRows<3>() = -RD;
      G.bottomRows<3>() = -tx * RD;
      write(J, 4, G);
    }
    if (double* J = jac[kWindow + ps.k0 + i]) {
      G.topRows<3>().setZero();
      G.bottomRows<3>() = -ps.w0(i) * Rci * Rt;
      write(J, 3, G);
    }
  }
  if (double* J = jac[kRci]) {
    G.topRows<3>() = Rci;
    G.bottomRows<3>() = tx * Rci;
    write(J, 4, G);
  }
  if (double* J = jac[kTci]) {
    G.topRows<3>().setZero();
    G.bottomRows<3>().setIdentity();
    write(J, 3, G);
  }
  if (double* J = jac[kShift]) {
    const Eigen::Vector3d w = Rci * ps.e.omega;
    Eigen::Matrix<double, 6, 1> g;
    g.head<3>() = -w;
    g.tail<3>() = -tx * w - Rci * (Rt * ps.vel);
    const Eigen::Matrix<double, 6, 1> Rg = R * g;
    for (int r = 0; r < 6; ++r) J[r] = Rg(r);
  }
  return true;
}

/// A Gaussian prior on the pose of camera n relative to camera m (both as T_cam_imu blocks):
/// r = L^-1 [Log(R_obs^T R_n R_m^T); t_n - R_n R_m^T t_m - t_obs], L L^T the covariance.
/// Blocks: R_n (quaternion), t_n, R_m (quaternion), t_m. Its four tangent Jacobians by central
/// differences (a dozen evaluations of a 6-vector; one such residual per camera pair).
class RelativePosePrior final : public ceres::CostFunction {
 public:
  RelativePosePrior(const Eigen::Matrix3d& R_obs, const Eigen::Vector3d& t_obs,
                    const Eigen::Matrix<double, 6, 6>& covariance)
      : R_obs_t_(R_obs.transpose()), t_obs_(t_obs) {
    Linv_ = Eigen::Matrix<double, 6, 6>(covariance.llt().matrixL()).inverse();
    set_num_residuals(6);
    for (int s : {4, 3, 4, 3}) mutable_parameter_block_sizes()->push_back(s);
  }
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    Eigen::Map<Eigen::Matrix<double, 6, 1>> out(residuals);
    out = value(quat_matrix(p[0]), vec3(p[1]), quat_matrix(p[2]), vec3(p[3]));
    if (!jac) return true;
    const double h = 1e-7;
    for (int b = 0; b < 4; ++b) {
      if (!jac[b]) continue;
      const int ambient = b % 2 == 0 ? 4 : 3;
      std::fill(jac[b], jac[b] + 6 * ambient, 0.0);
      for (int k = 0; k < 3; ++k) {
        Eigen::Matrix<double, 6, 1> plus, minus;
        for (int sign : {1, -1}) {
          Eigen::Matrix3d Rn = quat_matrix(p[0]), Rm = quat_matrix(p[2]);
          Eigen::Vector3d tn = vec3(p[1]), tm = vec3(p[3]);
          Eigen::Vector3d d = Eigen::Vector3d::Zero();
          d(k) = sign * h;
          if (b == 0) Rn = Rn * so3::exp(d);
          if (b == 1) tn += d;
          if (b == 2) Rm = Rm * so3::exp(d);
          if (b == 3) tm += d;
          (sign > 0 ? plus : minus) = value(Rn, tn, Rm, tm);
        }
        const Eigen::Matrix<double, 6, 1> col = (plus - minus) / (2.0 * h);
        for (int r = 0; r < 6; ++r) jac[b][r * ambient + k] = col(r);
      }
    }
    return true;
  }

 private:
  static Eigen::Vector3d vec3(const double* v) { return {v[0], v[1], v[2]}; }
  Eigen::Matrix<double, 6, 1> value(const Eigen::Matrix3d& Rn, const Eigen::Vector3d& tn,
                                    const Eigen::Matrix3d& Rm, const Eigen::Vector3d& tm) const {
    const Eigen::Matrix3d R = Rn * Rm.transpose();
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = so3::log(R_obs_t_ * R);
    e.tail<3>() = tn - R * tm - t_obs_;
    return Linv_ * e;
  }

  Eigen::Matrix3d R_obs_t_;
  Eigen::Vector3d t_obs_;
  Eigen::Matrix<double, 6, 6> Linv_;
};

/// A Gaussian prior on an R^n block: (x - x0) ./ sigma. Blocks: the one block.
class VectorPrior final : public ceres::CostFunction {
 public:
  VectorPrior(Eigen::VectorXd x0, Eigen::VectorXd sigma) : x0_(std::move(x0)), sigma_(std::move(sigma)) {
    set_num_residuals(static_cast<int>(x0_.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(x0_.size()));
  }
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const auto n = x0_.size();
    for (Eigen::Index i = 0; i < n; ++i) residuals[i] = (p[0][i] - x0_[i]) / sigma_[i];
    if (jac && jac[0]) {
      Eigen::Map<Eigen::MatrixXd>(jac[0], n, n) = sigma_.cwiseInverse().asDiagonal();
    }
    return true;
  }

 private:
  Eigen::VectorXd x0_, sigma_;
};

/// A Gaussian prior on a rotation block (RightQuaternionManifold): Log(R0^T R) / sigma, with the
/// tangent Jacobian Jr^-1(Log(R0^T R)) / sigma. Blocks: the quaternion.
class RotationPrior final : public ceres::CostFunction {
 public:
  RotationPrior(const Eigen::Matrix3d& R0, double sigma) : R0t_(R0.transpose()), sigma_(sigma) {
    set_num_residuals(3);
    mutable_parameter_block_sizes()->push_back(4);
  }
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const Eigen::Vector3d phi = so3::log(R0t_ * quat_matrix(p[0]));
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = phi / sigma_;
    if (jac && jac[0]) {
      Eigen::Map<Eigen::Matrix<double, 3, 4, Eigen::RowMajor>> J(jac[0]);
      J.setZero();
      J.leftCols<3>() = so3::right_jacobian_inverse(phi) / sigma_;
    }
    return true;
  }

 private:
  Eigen::Matrix3d R0t_;
  double sigma_;
};

}  // namespace imucal::calib::camimu
