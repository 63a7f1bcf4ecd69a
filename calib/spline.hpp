// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Uniform B-splines for continuous-time estimation: R^d splines (position, biases) and
// cumulative SO(3) splines (orientation), of order N (degree N - 1), with analytic time
// derivatives and analytic Jacobians with respect to the knots.
//
// The SO(3) derivatives use the recursive scheme of Sommer, Usenko, Schubert, Demmel and Cremers
// ("Efficient derivative computation for cumulative B-splines on Lie groups", CVPR 2020): the
// body angular velocity and acceleration are accumulated segment by segment, and their Jacobians
// by one backward pass, so no term is computed twice. Notation:
//   u = (t - t0) / dt - s, with s the segment (knots s .. s + N - 1),
//   R(t) = R_s  prod_{j=1}^{N-1} Exp(lambda_j(u) d_j),   d_j = Log(R_{s+j-1}^T R_{s+j}),
//   lambda_j the cumulative basis functions.
// Knot perturbations are on the right, R_i <- R_i Exp(delta_i), and so is the perturbation of the
// value, R <- R Exp(epsilon); angular velocity and acceleration are in the body frame
// (omega^ = R^T dR/dt). A spline with K knots covers [t0, t0 + (K - N + 1) dt).
//
// Tests compare every Jacobian with a numeric one (tests/calib/test_spline.cpp); the design
// follows basalt-headers' include/basalt/spline/ (API and tests), written here from the paper.

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <vector>

#include "calib/so3.hpp"

namespace imucal::calib {

/// Blending matrices of the uniform B-spline of order N: B(u) = M [1, u, ..., u^(N-1)]^T gives
/// the N basis values, C the cumulative ones (C(j, .) = sum over i >= j of M(i, .)).
template <int N>
struct BlendingMatrices {
  Eigen::Matrix<double, N, N> M, C;
  BlendingMatrices() {
    const auto binomial = [](int n, int k) {
      double r = 1.0;
      for (int i = 1; i <= k; ++i) r = r * (n - k + i) / i;
      return r;
    };
    double factorial = 1.0;
    for (int i = 2; i < N; ++i) factorial *= i;
    for (int s = 0; s < N; ++s) {
      for (int n = 0; n < N; ++n) {
        double sum = 0.0;
        for (int l = s; l < N; ++l) {
          const double sign = ((l - s) % 2 == 0) ? 1.0 : -1.0;
          sum += sign * binomial(N, l - s) * std::pow(static_cast<double>(N - 1 - l), N - 1 - n);
        }
        M(s, n) = binomial(N - 1, n) * sum / factorial;
      }
    }
    for (int j = 0; j < N; ++j) C.row(j) = M.bottomRows(N - j).colwise().sum();
  }
  static const BlendingMatrices& get() {
    static const BlendingMatrices instance;
    return instance;
  }
};

/// The basis (or cumulative basis) values at u and their first and second derivatives in u.
template <int N>
struct SplineWeights {
  Eigen::Matrix<double, N, 1> w, dw, ddw;
};
template <int N>
SplineWeights<N> spline_weights(double u, bool cumulative) {
  Eigen::Matrix<double, N, 1> p, dp, ddp;
  p.setZero();
  dp.setZero();
  ddp.setZero();
  double un = 1.0;
  for (int n = 0; n < N; ++n) {
    p(n) = un;
    if (n + 1 < N) dp(n + 1) = (n + 1) * un;
    if (n + 2 < N) ddp(n + 2) = (n + 2) * (n + 1) * un;
    un *= u;
  }
  const auto& B = BlendingMatrices<N>::get();
  const auto& A = cumulative ? B.C : B.M;
  return {A * p, A * dp, A * ddp};
}

/// Where a time falls: the first knot of its segment and u in [0, 1).
struct SplineSegment {
  int first_knot = 0;
  double u = 0.0;
};

/// Uniform knot timing shared by the splines; time in seconds from an origin of the caller.
template <int N>
struct SplineTiming {
  double t0_s = 0.0;
  double dt_s = 0.1;
  int knots = 0;

  double end_s() const { return t0_s + (knots - N + 1) * dt_s; }
  bool covers(double t_s) const { return t_s >= t0_s && t_s < end_s(); }
  /// The segment of t_s; times outside the spline are clamped to its first or last segment
  /// (u then leaves [0, 1): the polynomial of the end segment is extended).
  SplineSegment segment(double t_s) const {
    const double x = (t_s - t0_s) / dt_s;
    int s = static_cast<int>(std::floor(x));
    s = std::max(0, std::min(s, knots - N));
    return {s, x - s};
  }
};

/// An R^D spline: value and derivatives are weighted sums of N consecutive knots, so the
/// Jacobian with respect to knot first_knot + i is weight(i) times the identity.
template <int N, int D = 3>
class RdSpline {
 public:
  using Vec = Eigen::Matrix<double, D, 1>;

  RdSpline() = default;
  RdSpline(double t0_s, double dt_s, int knots, const Vec& value = Vec::Zero())
      : timing_{t0_s, dt_s, knots}, knots_(knots, value) {}

  const SplineTiming<N>& timing() const { return timing_; }
  std::vector<Vec>& knots() { return knots_; }
  const std::vector<Vec>& knots() const { return knots_; }

  /// The derivative of order `order` (0, 1, 2) at t_s; `weights` (may be null) receives the
  /// weights of knots segment.first_knot .. + N - 1 (d value / d knot_i = weights(i) I).
  Vec evaluate(double t_s, int order = 0, Eigen::Matrix<double, N, 1>* weights = nullptr,
               SplineSegment* segment = nullptr) const {
    const SplineSegment seg = timing_.segment(t_s);
    const Eigen::Matrix<double, N, 1> w = weights_at(seg.u, order, timing_.dt_s);
    Vec v = Vec::Zero();
    for (int i = 0; i < N; ++i) v += w(i) * knots_[seg.first_knot + i];
    if (weights) *weights = w;
    if (segment) *segment = seg;
    return v;
  }

  /// The weights of a derivative at u for knot spacing dt (1/dt^order applied).
  static Eigen::Matrix<double, N, 1> weights_at(double u, int order, double dt_s) {
    const SplineWeights<N> sw = spline_weights<N>(u, false);
    if (order == 0) return sw.w;
    if (order == 1) return sw.dw / dt_s;
    return sw.ddw / (dt_s * dt_s);
  }

 private:
  SplineTiming<N> timing_;
  std::vector<Vec> knots_;
};

/// The value, body angular velocity and acceleration of one segment of a cumulative SO(3) spline
/// and, on request, their Jacobians with respect to the segment's N knots (right perturbations).
template <int N>
struct So3SegmentEval {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();  // rad/s, body
  Eigen::Vector3d alpha = Eigen::Vector3d::Zero();  // rad/s^2, body
  std::array<Eigen::Matrix3d, N> dR_dknot;          // d epsilon / d delta_i
  std::array<Eigen::Matrix3d, N> domega_dknot;
  std::array<Eigen::Matrix3d, N> dalpha_dknot;
};

/// What So3Segment::evaluate computes: each level includes the ones before it.
enum class So3Derivs { kValue, kVelocity, kAcceleration };

template <int N>
class So3Segment {
 public:
  /// `knots` points to N rotations (knot first_knot .. first_knot + N - 1).
  static void evaluate(const Eigen::Matrix3d* const* knots, double u, double dt_s, So3Derivs level,
                       bool jacobians, So3SegmentEval<N>* out) {
    const SplineWeights<N> sw = spline_weights<N>(u, true);
    const Eigen::Matrix<double, N, 1> lam = sw.w, dlam = sw.dw / dt_s, ddlam = sw.ddw / (dt_s * dt_s);
    // Forward pass (j = 1 .. N-1): d_j, A_j = Exp(lambda_j d_j), omega and alpha after step j.
    std::array<Eigen::Vector3d, N> d;
    std::array<Eigen::Matrix3d, N> A;
    std::array<Eigen::Vector3d, N> w, a;  // w[j], a[j]: after step j (w[0] = a[0] = 0)
    w[0].setZero();
    a[0].setZero();
    Eigen::Matrix3d R = *knots[0];
    for (int j = 1; j < N; ++j) {
      d[j] = so3::log(knots[j - 1]->transpose() * *knots[j]);
      A[j] = so3::exp(lam(j) * d[j]);
      R = R * A[j];
      if (level == So3Derivs::kValue) continue;
      const Eigen::Vector3d dd = dlam(j) * d[j];
      w[j] = A[j].transpose() * w[j - 1] + dd;
      if (level == So3Derivs::kAcceleration)
        a[j] = A[j].transpose() * a[j - 1] + ddlam(j) * d[j] + w[j].cross(dd);
    }
    out->R = R;
    out->omega = level == So3Derivs::kValue ? Eigen::Vector3d::Zero() : w[N - 1];
    out->alpha = level == So3Derivs::kAcceleration ? a[N - 1] : Eigen::Vector3d::Zero();
    if (!jacobians) return;
    jacobians_backward(d, A, w, a, lam, dlam, ddlam, level, out);
  }

 private:
  using Lam = Eigen::Matrix<double, N, 1>;

  // The derivatives with respect to each d_j by a backward pass over the steps, then the chain
  // to the knots: d_j depends on knot j (Jr^-1(d_j)) and knot j-1 (-Jl^-1(d_j)).
  static void jacobians_backward(const std::array<Eigen::Vector3d, N>& d,
                                 const std::array<Eigen::Matrix3d, N>& A,
                                 const std::array<Eigen::Vector3d, N>& w,
                                 const std::array<Eigen::Vector3d, N>& a, const Lam& lam, const Lam& dlam,
                                 const Lam& ddlam, So3Derivs level, So3SegmentEval<N>* out) {
    std::array<Eigen::Matrix3d, N> dR_dd, dw_dd, da_dd;
    Eigen::Matrix3d S = Eigen::Matrix3d::Identity();   // prod_{i>j} A_i, as R-perturbation map: S^T
    Eigen::Matrix3d Hw = Eigen::Matrix3d::Identity();  // d omega_N / d omega_j
    Eigen::Matrix3d Ga = Eigen::Matrix3d::Identity();  // d alpha_N / d alpha_j
    Eigen::Matrix3d Gw = Eigen::Matrix3d::Zero();      // d alpha_N / d omega_j
    for (int j = N - 1; j >= 1; --j) {
      const Eigen::Matrix3d Jr = so3::right_jacobian(lam(j) * d[j]);
      const Eigen::Matrix3d At = A[j].transpose();
      dR_dd[j] = S.transpose() * Jr * lam(j);
      S = A[j] * S;
      if (level == So3Derivs::kValue) continue;
      const Eigen::Vector3d dd = dlam(j) * d[j];
      const Eigen::Matrix3d W = so3::hat(At * w[j - 1]) * Jr * lam(j) + dlam(j) * Eigen::Matrix3d::Identity();
      dw_dd[j] = Hw * W;
      if (level == So3Derivs::kAcceleration) {
        const Eigen::Matrix3d dadd = so3::hat(At * a[j - 1]) * Jr * lam(j) +
                                     ddlam(j) * Eigen::Matrix3d::Identity() - so3::hat(dd) * W +
                                     so3::hat(w[j]) * dlam(j);
        da_dd[j] = Ga * dadd + Gw * W;
        Gw = Ga * (-so3::hat(dd) * At) + Gw * At;
        Ga = Ga * At;
      }
      Hw = Hw * At;
    }
    // Knot 0 moves the whole product on the right of it.
    out->dR_dknot[0] = S.transpose();
    for (int i = 1; i < N; ++i) out->dR_dknot[i].setZero();
    for (int i = 0; i < N; ++i) {
      out->domega_dknot[i].setZero();
      out->dalpha_dknot[i].setZero();
    }
    for (int j = 1; j < N; ++j) {
      const Eigen::Matrix3d dd_dcur = so3::right_jacobian_inverse(d[j]);
      const Eigen::Matrix3d dd_dprev = -so3::left_jacobian_inverse(d[j]);
      out->dR_dknot[j] += dR_dd[j] * dd_dcur;
      out->dR_dknot[j - 1] += dR_dd[j] * dd_dprev;
      if (level == So3Derivs::kValue) continue;
      out->domega_dknot[j] += dw_dd[j] * dd_dcur;
      out->domega_dknot[j - 1] += dw_dd[j] * dd_dprev;
      if (level == So3Derivs::kAcceleration) {
        out->dalpha_dknot[j] += da_dd[j] * dd_dcur;
        out->dalpha_dknot[j - 1] += da_dd[j] * dd_dprev;
      }
    }
  }
};

/// A cumulative SO(3) spline over its knots.
template <int N>
class So3Spline {
 public:
  So3Spline() = default;
  So3Spline(double t0_s, double dt_s, int knots)
      : timing_{t0_s, dt_s, knots}, knots_(knots, Eigen::Matrix3d::Identity()) {}

  const SplineTiming<N>& timing() const { return timing_; }
  std::vector<Eigen::Matrix3d>& knots() { return knots_; }
  const std::vector<Eigen::Matrix3d>& knots() const { return knots_; }

  /// Evaluates at t_s (clamped to the spline as SplineTiming::segment says); the Jacobians are
  /// with respect to knots segment->first_knot .. + N - 1.
  So3SegmentEval<N> evaluate(double t_s, So3Derivs level, bool jacobians = false,
                             SplineSegment* segment = nullptr) const {
    const SplineSegment seg = timing_.segment(t_s);
    std::array<const Eigen::Matrix3d*, N> ptr;
    for (int i = 0; i < N; ++i) ptr[i] = &knots_[seg.first_knot + i];
    So3SegmentEval<N> out;
    So3Segment<N>::evaluate(ptr.data(), seg.u, timing_.dt_s, level, jacobians, &out);
    if (segment) *segment = seg;
    return out;
  }

 private:
  SplineTiming<N> timing_;
  std::vector<Eigen::Matrix3d> knots_;
};

}  // namespace imucal::calib
