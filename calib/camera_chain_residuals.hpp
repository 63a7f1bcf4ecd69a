// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The residual of the camera chain solve (calib/camera_chain.cpp): one view of one camera
// against the continuous-time trajectory of the reference camera (cam0) relative to the target,
// with that camera's intrinsics free. Internal to the chain estimator.
//
// Model (docs/camera-calibration.md, "Several cameras"): the target frame is the world; the
// spline gives T_target_cam0(t) = (R(t), p(t)); camera i sees target point P at its frame's
// stamp t_i, which is cam0's time t_i + shift_i, as
//   p_cam0 = R(t_i + shift_i)^T (P - p(t_i + shift_i)),
//   p_cami = R_ci_c0 p_cam0 + t_ci_c0,
//   r      = (pi(K_i, d_i; p_cami) - u) / sigma_i,   with the Cauchy loss folded in,
// and for cam0 itself R_c0_c0 = I, t = 0, shift = 0 held constant.
//
// ChainPoseResidual is the same view against one pose of cam0 per stamp (cameras triggered
// together, offsets held at 0; Kalibr's model): blocks R_target_cam0 (quaternion), p (R^3),
// R_ci_c0, t_ci_c0, intrinsics, projection, distortion.
//
// Parameter blocks: N + 2 rotation knots (RightQuaternionManifold), N + 2 position knots (R^3),
// R_ci_c0 (quaternion), t_ci_c0 (R^3), shift (s), intrinsics fu fv pu pv (R^4), the projection's
// parameters (R^2: omni xi, eucm alpha beta, ds xi alpha), distortion (R^4); the entries a model
// does not use are held by the solve. The pose's Jacobians are the spline's analytic ones
// (calib/spline.hpp); the projection's, in the camera point and the 10 camera parameters, come
// from one Jet evaluation per corner.
//
// Compressed (the default), as the camera-IMU frame residual (calib/camimu_residuals.hpp): every
// parameter moves the corners through the camera frame's rigid motion (w, v) or the 10 camera
// parameters k, so the 2n corner rows r = F G dx (F: 2n x 16 in (w, v, k)) are replaced by 17
// rows with the same cost, gradient and Gauss-Newton matrix: 16 rows R G (R^T R = F^T F), their
// residual R^-T F^T r, and a last row with the rest of |r|^2.

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <array>
#include <limits>
#include <vector>

#include "calib/camimu_residuals.hpp"
#include "core/camera_model.hpp"

namespace imucal::calib::chain {

/// The camera frame's motion (w, v) and the camera's 10 parameters (4 intrinsics, 2 of the
/// projection, 4 of the distortion).
inline constexpr int kFactorCols = 16;
using Mat16 = Eigen::Matrix<double, kFactorCols, kFactorCols>;
using Vec16 = Eigen::Matrix<double, kFactorCols, 1>;
inline constexpr int kCompressedRows = kFactorCols + 1;

/// The corners of one view, their weight and loss: what the residual is, whatever models the
/// pose of cam0 relative to the target (world) at the view's time, (R_wb, p_wb).
class ViewCorners {
 public:
  ViewCorners(CameraModelKind model, int width, int height, std::vector<Eigen::Vector3d> points_w,
              std::vector<Eigen::Vector2d> px, double sigma_px, double loss_scale_px)
      : model_(model),
        width_(width),
        height_(height),
        points_(std::move(points_w)),
        px_(std::move(px)),
        w_(1.0 / sigma_px),
        c2_(loss_scale_px > 0.0 ? (loss_scale_px / sigma_px) * (loss_scale_px / sigma_px)
                                : std::numeric_limits<double>::infinity()) {}

  std::size_t size() const { return points_.size(); }
  const Eigen::Vector3d& point(std::size_t k) const { return points_[k]; }
  const Eigen::Vector2d& observed(std::size_t k) const { return px_[k]; }
  int height() const { return height_; }

  /// The unweighted pixel residuals (projected - detected), without the loss.
  void pixel_residuals(const Eigen::Matrix3d& R_wb, const Eigen::Vector3d& p_wb, const double* q_ci,
                       const double* t_ci, const double* intr, const double* proj, const double* dist,
                       std::vector<Eigen::Vector2d>* out) const {
    const Eigen::Matrix3d Rt = R_wb.transpose(), Rci = camimu::quat_matrix(q_ci);
    const Eigen::Map<const Eigen::Vector3d> tci(t_ci);
    const auto camera = CameraModel::from_params(model_, intr, proj, dist, width_, height_);
    out->clear();
    for (std::size_t k = 0; k < points_.size(); ++k)
      out->push_back(camera.project(Rci * (Rt * (points_[k] - p_wb)) + tci).px - px_[k]);
  }
  /// Corner k's alone (a rolling shutter's corners each have their own pose).
  Eigen::Vector2d pixel_residual(std::size_t k, const Eigen::Matrix3d& R_wb, const Eigen::Vector3d& p_wb,
                                 const double* q_ci, const double* t_ci, const double* intr,
                                 const double* proj, const double* dist) const {
    const auto camera = CameraModel::from_params(model_, intr, proj, dist, width_, height_);
    const Eigen::Vector3d pc = camimu::quat_matrix(q_ci) * (R_wb.transpose() * (points_[k] - p_wb)) +
                               Eigen::Map<const Eigen::Vector3d>(t_ci);
    return camera.project(pc).px - px_[k];
  }

  /// Corner k's weighted residual with the loss folded in at the camera point pc and, with `J`,
  /// its Jacobian in pc (columns 0-2) and the 10 camera parameters (3-12).
  Eigen::Vector2d corner(const double* intr, const double* proj, const double* dist,
                         const Eigen::Vector3d& pc, std::size_t k, Eigen::Matrix<double, 2, 13>* J) const {
    Eigen::Vector2d uv;
    Eigen::Matrix<double, 2, 13> Jp = Eigen::Matrix<double, 2, 13>::Zero();
    if (J) {
      using Jet = ceres::Jet<double, 13>;
      std::array<Jet, 4> kj, dj;
      std::array<Jet, 2> ej;
      for (int i = 0; i < 4; ++i) {
        kj[i] = Jet(intr[i], 3 + i);
        dj[i] = Jet(dist[i], 9 + i);
      }
      for (int i = 0; i < 2; ++i) ej[i] = Jet(proj[i], 7 + i);
      const auto camera =
          CameraModelT<Jet>::from_params(model_, kj.data(), ej.data(), dj.data(), width_, height_);
      Eigen::Matrix<Jet, 3, 1> x;
      for (int i = 0; i < 3; ++i) x(i) = Jet(pc(i), i);
      const auto pr = camera.project(x);
      for (int r = 0; r < 2; ++r) {
        uv(r) = pr.px(r).a;
        Jp.row(r) = pr.px(r).v.transpose();
      }
    } else {
      uv = CameraModel::from_params(model_, intr, proj, dist, width_, height_).project(pc).px;
    }
    Eigen::Vector2d r;
    Eigen::Matrix2d L;
    camimu::fold_cauchy(w_ * (uv - px_[k]), c2_, &r, J ? &L : nullptr);
    if (J) *J = w_ * L * Jp;
    return r;
  }

  /// The compressed rows (see the file's comment) at the pose (R_wb, p_wb): `out` (17 values)
  /// and, with `R`, the 16 x 16 factor whose columns are the rows' Jacobian in the camera frame's
  /// motion (w, v: dp_cam = -[p_cam]x w + v) and the 10 camera parameters.
  void compress(const Eigen::Matrix3d& R_wb, const Eigen::Vector3d& p_wb, const Eigen::Matrix3d& Rci,
                const Eigen::Vector3d& tci, const double* intr, const double* proj, const double* dist,
                double* out, Mat16* R) const {
    const Eigen::Matrix3d Rt = R_wb.transpose();
    double sum = 0.0;
    Mat16 A = Mat16::Zero();
    Vec16 b = Vec16::Zero();
    for (std::size_t k = 0; k < points_.size(); ++k) {
      const Eigen::Vector3d pc = Rci * (Rt * (points_[k] - p_wb)) + tci;
      Eigen::Matrix<double, 2, 13> J;
      const Eigen::Vector2d r = corner(intr, proj, dist, pc, k, R ? &J : nullptr);
      sum += r.squaredNorm();
      if (!R) continue;
      Eigen::Matrix<double, 2, kFactorCols> F;
      F.leftCols<3>() = -J.leftCols<3>() * so3::hat(pc);
      F.middleCols<3>(3) = J.leftCols<3>();
      F.rightCols<10>() = J.rightCols<10>();
      A.noalias() += F.transpose() * F;
      b.noalias() += F.transpose() * r;
    }
    Eigen::Map<Eigen::Matrix<double, kCompressedRows, 1>> o(out);
    if (!R) {
      // Only the cost is asked for: the same norm, all of it in the last row.
      o.setZero();
      o(kCompressedRows - 1) = std::sqrt(sum);
      return;
    }
    // A = V diag(l) V^T; R = diag(sqrt l) V^T; the residual R^-T b (directions of A below 1e-12 of
    // its largest eigenvalue are taken as empty).
    const Eigen::SelfAdjointEigenSolver<Mat16> es(A);
    const Vec16 l = es.eigenvalues();
    const double floor = 1e-12 * std::max(l.maxCoeff(), 0.0);
    const Vec16 Vb = es.eigenvectors().transpose() * b;
    for (int i = 0; i < kFactorCols; ++i) {
      const bool empty = !(l(i) > floor);
      const double sq = empty ? 0.0 : std::sqrt(l(i));
      R->row(i) = sq * es.eigenvectors().col(i).transpose();
      o(i) = empty ? 0.0 : Vb(i) / sq;
    }
    o(kCompressedRows - 1) = std::sqrt(std::max(0.0, sum - o.head<kFactorCols>().squaredNorm()));
  }

 private:
  CameraModelKind model_;
  int width_, height_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<Eigen::Vector2d> px_;
  double w_;
  double c2_;
};

/// Writes R[:, 0:6] G, the rows' Jacobian in a block that moves the camera frame by (w, v) = G dx,
/// into a 16-row block of `ambient` columns (the first 3 or `cols` of them).
template <int Cols>
inline void write_motion_block(double* J, int ambient, const Mat16& R,
                               const Eigen::Matrix<double, 6, Cols>& G) {
  const Eigen::Matrix<double, kFactorCols, Cols> RG = R.leftCols<6>() * G;
  for (int r = 0; r < kFactorCols; ++r)
    for (int c = 0; c < Cols; ++c) J[r * ambient + c] = RG(r, c);
}

/// The Jacobians both residuals share: the camera's pose relative to cam0 (R_ci_c0, t_ci_c0) and
/// its 10 parameters.
inline void write_camera_blocks(double* J_rci, double* J_tci, double* J_intr, double* J_proj, double* J_dist,
                                const Mat16& R, const Eigen::Matrix3d& Rci, const Eigen::Vector3d& tci) {
  const Eigen::Matrix3d tx = so3::hat(tci);
  Eigen::Matrix<double, 6, 3> G;
  if (J_rci) {
    G.topRows<3>() = Rci;
    G.bottomRows<3>() = tx * Rci;
    write_motion_block<3>(J_rci, 4, R, G);
  }
  if (J_tci) {
    G.topRows<3>().setZero();
    G.bottomRows<3>().setIdentity();
    write_motion_block<3>(J_tci, 3, R, G);
  }
  for (int r = 0; r < kFactorCols; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (J_intr) J_intr[r * 4 + c] = R(r, 6 + c);
      if (J_dist) J_dist[r * 4 + c] = R(r, 12 + c);
    }
    for (int c = 0; c < 2; ++c)
      if (J_proj) J_proj[r * 2 + c] = R(r, 10 + c);
  }
}

template <int N>
class ChainFrameResidual final : public ceres::CostFunction {
 public:
  static constexpr int kWindow = N + 2;
  static constexpr int kRci = 2 * kWindow, kTci = kRci + 1, kShift = kTci + 1, kIntr = kShift + 1,
                       kProj = kIntr + 1, kDist = kProj + 1;
  static constexpr int kCompressedRows = chain::kCompressedRows;

  static constexpr int kLineDelay = kDist + 1;  // a rolling shutter's

  /// `rolling`: a rolling shutter (the readout direction and stamped row of `shutter`), corner k
  /// seen at t_cam + shift + row_offset(v_k) line_delay with the line delay as one more block;
  /// each corner then has its own pose and the view is not compressed (as camimu::FrameResidual).
  ChainFrameResidual(CameraModelKind model, int width, int height, std::vector<Eigen::Vector3d> points_w,
                     std::vector<Eigen::Vector2d> px, double t_cam_s, int first_window_knot,
                     const SplineTiming<N>& timing, double sigma_px, double loss_scale_px,
                     bool compressed = true, const Shutter* rolling = nullptr)
      : corners_(model, width, height, std::move(points_w), std::move(px), sigma_px, loss_scale_px),
        t_cam_s_(t_cam_s),
        first_(first_window_knot),
        timing_(timing),
        compressed_(compressed && rolling == nullptr && 2 * corners_.size() > kCompressedRows),
        rolling_(rolling != nullptr) {
    set_num_residuals(compressed_ ? kCompressedRows : 2 * static_cast<int>(corners_.size()));
    auto* sizes = mutable_parameter_block_sizes();
    for (int i = 0; i < kWindow; ++i) sizes->push_back(4);
    for (int i = 0; i < kWindow; ++i) sizes->push_back(3);
    for (int s : {4, 3, 1, 4, 2, 4}) sizes->push_back(s);
    if (rolling_) {
      sizes->push_back(1);
      off_min_ = std::numeric_limits<double>::infinity();
      off_max_ = -off_min_;
      Shutter shutter = *rolling;  // its readout and stamped row, whatever kind it says
      shutter.kind = Shutter::Kind::kRolling;
      for (std::size_t k = 0; k < corners_.size(); ++k) {
        const double off = shutter.row_offset(corners_.observed(k).y(), height);
        row_offset_.push_back(off);
        off_min_ = std::min(off_min_, off);
        off_max_ = std::max(off_max_, off);
      }
      if (row_offset_.empty()) off_min_ = off_max_ = 0.0;  // a view left without corners
    }
  }

  /// False when the shift (and a rolling shutter's line delay) has moved a corner of the view out
  /// of the knot window it was built with.
  bool in_window(double shift_s, double line_delay_s = 0.0) const {
    for (double off : {off_min_, off_max_}) {
      const int k = timing_.segment(t_cam_s_ + shift_s + off * line_delay_s).first_knot - first_;
      if (k < 0 || k > 2) return false;
    }
    return true;
  }
  std::size_t corners() const { return corners_.size(); }
  bool rolling() const { return rolling_; }

  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    return compressed_ ? evaluate_compressed(p, residuals, jac) : evaluate_corners(p, residuals, jac);
  }

  /// The unweighted pixel residuals (projected - detected) at `p`, without the loss.
  void pixel_residuals(double const* const* p, std::vector<Eigen::Vector2d>* out) const {
    const camimu::SplinePose<N> ps = pose(p, false);
    corners_.pixel_residuals(ps.e.R, ps.pos, p[kRci], p[kTci], p[kIntr], p[kProj], p[kDist], out);
    if (!rolling_) return;
    for (std::size_t k = 0; k < corners_.size(); ++k) {
      const camimu::SplinePose<N> pk = corner_pose(p, k, false);
      (*out)[k] = corners_.pixel_residual(k, pk.e.R, pk.pos, p[kRci], p[kTci], p[kIntr], p[kProj], p[kDist]);
    }
  }

 private:
  camimu::SplinePose<N> pose(double const* const* p, bool jacobians) const {
    return camimu::spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0], first_, timing_, jacobians);
  }
  camimu::SplinePose<N> corner_pose(double const* const* p, std::size_t k, bool jacobians) const {
    return camimu::spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0] + row_offset_[k] * p[kLineDelay][0],
                                  first_, timing_, jacobians);
  }

  bool evaluate_compressed(double const* const* p, double* residuals, double** jac) const {
    const camimu::SplinePose<N> ps = pose(p, jac != nullptr);
    const Eigen::Matrix3d Rt = ps.e.R.transpose(), Rci = camimu::quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
    Mat16 R;
    corners_.compress(ps.e.R, ps.pos, Rci, tci, p[kIntr], p[kProj], p[kDist], residuals, jac ? &R : nullptr);
    if (!jac) return true;
    for (int blk = 0; blk <= kDist; ++blk)
      if (jac[blk]) std::fill(jac[blk], jac[blk] + kCompressedRows * parameter_block_sizes()[blk], 0.0);
    const Eigen::Matrix3d tx = so3::hat(tci);
    Eigen::Matrix<double, 6, 3> G;
    for (int i = 0; i < N; ++i) {
      if (double* J = jac[ps.k0 + i]) {
        const Eigen::Matrix3d RD = Rci * ps.e.dR_dknot[i];
        G.topRows<3>() = -RD;
        G.bottomRows<3>() = -tx * RD;
        write_motion_block<3>(J, 4, R, G);
      }
      if (double* J = jac[kWindow + ps.k0 + i]) {
        G.topRows<3>().setZero();
        G.bottomRows<3>() = -ps.w0(i) * Rci * Rt;
        write_motion_block<3>(J, 3, R, G);
      }
    }
    if (double* J = jac[kShift]) {
      const Eigen::Vector3d w = Rci * ps.e.omega;
      Eigen::Matrix<double, 6, 1> g;
      g.head<3>() = -w;
      g.tail<3>() = -tx * w - Rci * (Rt * ps.vel);
      write_motion_block<1>(J, 1, R, g);
    }
    write_camera_blocks(jac[kRci], jac[kTci], jac[kIntr], jac[kProj], jac[kDist], R, Rci, tci);
    return true;
  }

  bool evaluate_corners(double const* const* p, double* residuals, double** jac) const {
    camimu::SplinePose<N> ps = pose(p, jac != nullptr);
    Eigen::Matrix3d Rt = ps.e.R.transpose();
    const Eigen::Matrix3d Rci = camimu::quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
    const int rows = num_residuals();
    const int blocks = static_cast<int>(parameter_block_sizes().size());
    if (jac) {
      for (int b = 0; b < blocks; ++b)
        if (jac[b]) std::fill(jac[b], jac[b] + rows * parameter_block_sizes()[b], 0.0);
    }
    for (std::size_t k = 0; k < corners_.size(); ++k) {
      if (rolling_) {
        ps = corner_pose(p, k, jac != nullptr);
        Rt = ps.e.R.transpose();
      }
      const Eigen::Vector3d pb = Rt * (corners_.point(k) - ps.pos);
      const Eigen::Vector3d pc = Rci * pb + tci;
      Eigen::Matrix<double, 2, 13> Jw;
      Eigen::Map<Eigen::Vector2d>(residuals + 2 * k) =
          corners_.corner(p[kIntr], p[kProj], p[kDist], pc, k, jac ? &Jw : nullptr);
      if (!jac) continue;
      const Eigen::Matrix<double, 2, 3> Jc = Jw.leftCols<3>();  // d r / d p_cam
      const Eigen::Matrix<double, 2, 3> Jb = Jc * Rci;          // d r / d p_body
      const int row = 2 * static_cast<int>(k);
      for (int i = 0; i < N; ++i) {
        if (jac[ps.k0 + i])
          camimu::put<2>(jac[ps.k0 + i], 4, row, rows, Jb * so3::hat(pb) * ps.e.dR_dknot[i]);
        if (jac[kWindow + ps.k0 + i])
          camimu::put<2>(jac[kWindow + ps.k0 + i], 3, row, rows, -Jb * Rt * ps.w0(i));
      }
      if (jac[kRci]) camimu::put<2>(jac[kRci], 4, row, rows, -Jc * Rci * so3::hat(pb));
      if (jac[kTci]) camimu::put<2>(jac[kTci], 3, row, rows, Jc);
      double* j_line_delay = rolling_ ? jac[kLineDelay] : nullptr;
      if (jac[kShift] || j_line_delay)
        camimu::put_time_jacobians(jac[kShift], j_line_delay, row,
                                   Jb * (so3::hat(pb) * ps.e.omega - Rt * ps.vel),
                                   rolling_ ? row_offset_[k] : 0.0);
      for (int c = 0; c < 4; ++c) {
        if (jac[kIntr]) {
          jac[kIntr][row * 4 + c] = Jw(0, 3 + c);
          jac[kIntr][(row + 1) * 4 + c] = Jw(1, 3 + c);
        }
        if (jac[kDist]) {
          jac[kDist][row * 4 + c] = Jw(0, 9 + c);
          jac[kDist][(row + 1) * 4 + c] = Jw(1, 9 + c);
        }
      }
      if (jac[kProj]) {
        for (int c = 0; c < 2; ++c) {
          jac[kProj][row * 2 + c] = Jw(0, 7 + c);
          jac[kProj][(row + 1) * 2 + c] = Jw(1, 7 + c);
        }
      }
    }
    return true;
  }

  ViewCorners corners_;
  double t_cam_s_;
  int first_;
  SplineTiming<N> timing_;
  bool compressed_;
  bool rolling_;
  std::vector<double> row_offset_;  // rolling: each corner's row_offset(v)
  double off_min_ = 0.0, off_max_ = 0.0;
};

/// One view against one pose of cam0 (R_wb, p_wb as blocks), always compressed (a view has at
/// least 8 corners: 16 rows, and the 17 it compresses to carry the same cost).
class ChainPoseResidual final : public ceres::CostFunction {
 public:
  static constexpr int kQ = 0, kP = 1, kRci = 2, kTci = 3, kIntr = 4, kProj = 5, kDist = 6;

  explicit ChainPoseResidual(ViewCorners corners) : corners_(std::move(corners)) {
    set_num_residuals(kCompressedRows);
    for (int s : {4, 3, 4, 3, 4, 2, 4}) mutable_parameter_block_sizes()->push_back(s);
  }

  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const Eigen::Matrix3d Rb = camimu::quat_matrix(p[kQ]), Rci = camimu::quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> pb(p[kP]), tci(p[kTci]);
    Mat16 R;
    corners_.compress(Rb, pb, Rci, tci, p[kIntr], p[kProj], p[kDist], residuals, jac ? &R : nullptr);
    if (!jac) return true;
    for (int blk = 0; blk <= kDist; ++blk)
      if (jac[blk]) std::fill(jac[blk], jac[blk] + kCompressedRows * parameter_block_sizes()[blk], 0.0);
    const Eigen::Matrix3d tx = so3::hat(tci);
    Eigen::Matrix<double, 6, 3> G;
    if (jac[kQ]) {  // R_wb <- R_wb Exp(d): p_body turns by -d, the camera frame with it
      G.topRows<3>() = -Rci;
      G.bottomRows<3>() = -tx * Rci;
      write_motion_block<3>(jac[kQ], 4, R, G);
    }
    if (jac[kP]) {
      G.topRows<3>().setZero();
      G.bottomRows<3>() = -Rci * Rb.transpose();
      write_motion_block<3>(jac[kP], 3, R, G);
    }
    write_camera_blocks(jac[kRci], jac[kTci], jac[kIntr], jac[kProj], jac[kDist], R, Rci, tci);
    return true;
  }

  void pixel_residuals(double const* const* p, std::vector<Eigen::Vector2d>* out) const {
    corners_.pixel_residuals(camimu::quat_matrix(p[kQ]), Eigen::Vector3d(p[kP][0], p[kP][1], p[kP][2]),
                             p[kRci], p[kTci], p[kIntr], p[kProj], p[kDist], out);
  }

 private:
  ViewCorners corners_;
};

}  // namespace imucal::calib::chain
