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
// Parameter blocks: N + 2 rotation knots (RightQuaternionManifold), N + 2 position knots (R^3),
// R_ci_c0 (quaternion), t_ci_c0 (R^3), shift (s), intrinsics fu fv pu pv (R^4), distortion (R^4).
// The pose's Jacobians are the spline's analytic ones (calib/spline.hpp); the projection's, in
// the camera point and the 8 camera parameters, come from one Jet evaluation per corner.
//
// Compressed (the default), as the camera-IMU frame residual (calib/camimu_residuals.hpp): every
// parameter moves the corners through the camera frame's rigid motion (w, v) or the 8 camera
// parameters k, so the 2n corner rows r = F G dx (F: 2n x 14 in (w, v, k)) are replaced by 15
// rows with the same cost, gradient and Gauss-Newton matrix: 14 rows R G (R^T R = F^T F), their
// residual R^-T F^T r, and a last row with the rest of |r|^2.

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <vector>

#include "calib/camimu_residuals.hpp"
#include "core/camera_model.hpp"

namespace imucal::calib::chain {

template <int N>
class ChainFrameResidual final : public ceres::CostFunction {
 public:
  static constexpr int kWindow = N + 2;
  static constexpr int kRci = 2 * kWindow, kTci = kRci + 1, kShift = kTci + 1, kIntr = kShift + 1,
                       kDist = kIntr + 1;

  static constexpr int kCompressedRows = 15;

  ChainFrameResidual(DistortionModel model, int width, int height, std::vector<Eigen::Vector3d> points_w,
                     std::vector<Eigen::Vector2d> px, double t_cam_s, int first_window_knot,
                     const SplineTiming<N>& timing, double sigma_px, double loss_scale_px,
                     bool compressed = true)
      : model_(model),
        width_(width),
        height_(height),
        points_(std::move(points_w)),
        px_(std::move(px)),
        t_cam_s_(t_cam_s),
        first_(first_window_knot),
        timing_(timing),
        w_(1.0 / sigma_px),
        c2_(loss_scale_px > 0.0 ? (loss_scale_px / sigma_px) * (loss_scale_px / sigma_px)
                                : std::numeric_limits<double>::infinity()),
        compressed_(compressed && 2 * points_.size() > kCompressedRows) {
    set_num_residuals(compressed_ ? kCompressedRows : 2 * static_cast<int>(points_.size()));
    auto* sizes = mutable_parameter_block_sizes();
    for (int i = 0; i < kWindow; ++i) sizes->push_back(4);
    for (int i = 0; i < kWindow; ++i) sizes->push_back(3);
    for (int s : {4, 3, 1, 4, 4}) sizes->push_back(s);
  }

  /// False when the shift has moved the view out of the knot window it was built with.
  bool in_window(double shift_s) const {
    const int k = timing_.segment(t_cam_s_ + shift_s).first_knot - first_;
    return k >= 0 && k <= 2;
  }
  std::size_t corners() const { return points_.size(); }

  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    return compressed_ ? evaluate_compressed(p, residuals, jac) : evaluate_corners(p, residuals, jac);
  }

  /// The unweighted pixel residuals (projected - detected) at `p`, without the loss.
  void pixel_residuals(double const* const* p, std::vector<Eigen::Vector2d>* out) const {
    const camimu::SplinePose<N> ps =
        camimu::spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0], first_, timing_, false);
    const Eigen::Matrix3d Rt = ps.e.R.transpose(), Rci = camimu::quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
    const auto camera = CameraModel::from_params(model_, p[kIntr], p[kDist], width_, height_);
    out->clear();
    for (std::size_t k = 0; k < points_.size(); ++k)
      out->push_back(camera.project(Rci * (Rt * (points_[k] - ps.pos)) + tci).px - px_[k]);
  }

 private:
  using Jet = ceres::Jet<double, 11>;

  /// One corner's weighted residual with the loss folded in and, with `J`, its Jacobian in the
  /// camera point (columns 0-2) and the 8 camera parameters (3-10).
  Eigen::Vector2d corner(const CameraModelT<Jet>& camera_jet, const CameraModel& camera,
                         const Eigen::Vector3d& pc, std::size_t k, Eigen::Matrix<double, 2, 11>* J) const {
    Eigen::Vector2d uv;
    Eigen::Matrix<double, 2, 11> Jp = Eigen::Matrix<double, 2, 11>::Zero();
    if (J) {
      Eigen::Matrix<Jet, 3, 1> x;
      for (int i = 0; i < 3; ++i) x(i) = Jet(pc(i), i);
      const auto pr = camera_jet.project(x);
      for (int r = 0; r < 2; ++r) {
        uv(r) = pr.px(r).a;
        Jp.row(r) = pr.px(r).v.transpose();
      }
    } else {
      uv = camera.project(pc).px;
    }
    Eigen::Vector2d r;
    Eigen::Matrix2d L;
    camimu::fold_cauchy(w_ * (uv - px_[k]), c2_, &r, J ? &L : nullptr);
    if (J) *J = w_ * L * Jp;
    return r;
  }

  CameraModelT<Jet> camera_jet(double const* const* p) const {
    std::array<Jet, 4> kj, dj;
    for (int i = 0; i < 4; ++i) {
      kj[i] = Jet(p[kIntr][i], 3 + i);
      dj[i] = Jet(p[kDist][i], 7 + i);
    }
    return CameraModelT<Jet>::from_params(model_, kj.data(), dj.data(), width_, height_);
  }

  bool evaluate_compressed(double const* const* p, double* residuals, double** jac) const {
    const camimu::SplinePose<N> ps =
        camimu::spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0], first_, timing_, jac != nullptr);
    const Eigen::Matrix3d Rt = ps.e.R.transpose(), Rci = camimu::quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
    const auto cj = camera_jet(p);
    const auto camera = CameraModel::from_params(model_, p[kIntr], p[kDist], width_, height_);
    using Mat14 = Eigen::Matrix<double, 14, 14>;
    using Vec14 = Eigen::Matrix<double, 14, 1>;
    Eigen::Map<Eigen::Matrix<double, kCompressedRows, 1>> out(residuals);
    double sum = 0.0;
    Mat14 A = Mat14::Zero();
    Vec14 b = Vec14::Zero();
    for (std::size_t k = 0; k < points_.size(); ++k) {
      const Eigen::Vector3d pc = Rci * (Rt * (points_[k] - ps.pos)) + tci;
      Eigen::Matrix<double, 2, 11> J;
      const Eigen::Vector2d r = corner(cj, camera, pc, k, jac ? &J : nullptr);
      sum += r.squaredNorm();
      if (!jac) continue;
      Eigen::Matrix<double, 2, 14> F;  // d r / d (w, v, k) of the camera frame and camera
      F.leftCols<3>() = -J.leftCols<3>() * so3::hat(pc);
      F.middleCols<3>(3) = J.leftCols<3>();
      F.rightCols<8>() = J.rightCols<8>();
      A.noalias() += F.transpose() * F;
      b.noalias() += F.transpose() * r;
    }
    if (!jac) {
      out.setZero();
      out(kCompressedRows - 1) = std::sqrt(sum);
      return true;
    }
    const Eigen::SelfAdjointEigenSolver<Mat14> es(A);
    const Vec14 l = es.eigenvalues();
    const double floor = 1e-12 * std::max(l.maxCoeff(), 0.0);
    Mat14 R;
    const Vec14 Vb = es.eigenvectors().transpose() * b;
    for (int i = 0; i < 14; ++i) {
      const bool empty = !(l(i) > floor);
      const double sq = empty ? 0.0 : std::sqrt(l(i));
      R.row(i) = sq * es.eigenvectors().col(i).transpose();
      out(i) = empty ? 0.0 : Vb(i) / sq;
    }
    out(kCompressedRows - 1) = std::sqrt(std::max(0.0, sum - out.head<14>().squaredNorm()));
    constexpr int rows = kCompressedRows;
    for (int blk = 0; blk <= kDist; ++blk)
      if (jac[blk]) std::fill(jac[blk], jac[blk] + rows * parameter_block_sizes()[blk], 0.0);
    const Eigen::Matrix3d tx = so3::hat(tci);
    // A block that moves the camera frame by (w, v) = G dx: its 14 rows are R[:, 0:6] G.
    const auto write = [&](double* J, int ambient, const Eigen::Matrix<double, 6, 3>& G) {
      const Eigen::Matrix<double, 14, 3> RG = R.leftCols<6>() * G;
      for (int r = 0; r < 14; ++r)
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
      const Eigen::Matrix<double, 14, 1> Rg = R.leftCols<6>() * g;
      for (int r = 0; r < 14; ++r) J[r] = Rg(r);
    }
    for (int c = 0; c < 4; ++c) {
      for (int r = 0; r < 14; ++r) {
        if (jac[kIntr]) jac[kIntr][r * 4 + c] = R(r, 6 + c);
        if (jac[kDist]) jac[kDist][r * 4 + c] = R(r, 10 + c);
      }
    }
    return true;
  }

  bool evaluate_corners(double const* const* p, double* residuals, double** jac) const {
    const camimu::SplinePose<N> ps =
        camimu::spline_pose<N>(p, 0, kWindow, t_cam_s_ + p[kShift][0], first_, timing_, jac != nullptr);
    const Eigen::Matrix3d Rt = ps.e.R.transpose(), Rci = camimu::quat_matrix(p[kRci]);
    const Eigen::Map<const Eigen::Vector3d> tci(p[kTci]);
    const int rows = num_residuals();
    if (jac) {
      for (int b = 0; b < kDist + 1; ++b)
        if (jac[b]) std::fill(jac[b], jac[b] + rows * parameter_block_sizes()[b], 0.0);
    }
    const auto cj = camera_jet(p);
    const auto camera = CameraModel::from_params(model_, p[kIntr], p[kDist], width_, height_);
    for (std::size_t k = 0; k < points_.size(); ++k) {
      const Eigen::Vector3d pb = Rt * (points_[k] - ps.pos);
      const Eigen::Vector3d pc = Rci * pb + tci;
      Eigen::Matrix<double, 2, 11> Jw;
      Eigen::Map<Eigen::Vector2d>(residuals + 2 * k) = corner(cj, camera, pc, k, jac ? &Jw : nullptr);
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
      if (jac[kShift]) {
        const Eigen::Vector2d d = Jb * (so3::hat(pb) * ps.e.omega - Rt * ps.vel);
        jac[kShift][row] = d(0);
        jac[kShift][row + 1] = d(1);
      }
      for (int c = 0; c < 4; ++c) {
        if (jac[kIntr]) {
          jac[kIntr][row * 4 + c] = Jw(0, 3 + c);
          jac[kIntr][(row + 1) * 4 + c] = Jw(1, 3 + c);
        }
        if (jac[kDist]) {
          jac[kDist][row * 4 + c] = Jw(0, 7 + c);
          jac[kDist][(row + 1) * 4 + c] = Jw(1, 7 + c);
        }
      }
    }
    return true;
  }

  DistortionModel model_;
  int width_, height_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<Eigen::Vector2d> px_;
  double t_cam_s_;
  int first_;
  SplineTiming<N> timing_;
  double w_;
  double c2_;
  bool compressed_;
};

}  // namespace imucal::calib::chain
