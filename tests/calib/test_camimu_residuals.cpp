// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU residuals' analytic Jacobians (calib/camimu_residuals.hpp) against central
// differences: quaternion blocks through the manifold's right perturbation (tangent columns in
// the first three ambient ones), every other block in its ambient coordinates.

#include <ceres/solver.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "calib/camimu_residuals.hpp"
#include "calib/marginal_covariance.hpp"
#include "sim/camimu.hpp"

namespace imucal::calib::camimu {
namespace {

using Block = std::vector<double>;

Block random_quat(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return {q.x(), q.y(), q.z(), q.w()};
}

Block random_vec(std::mt19937& rng, int size, double mean, double sd) {
  std::normal_distribution<double> n(mean, sd);
  Block b(static_cast<std::size_t>(size));
  for (auto& v : b) v = n(rng);
  return b;
}

// Compares every Jacobian block of `cost` at `blocks` with central differences.
void check_jacobians(const ceres::CostFunction& cost, std::vector<Block> blocks, double tol) {
  const int m = cost.num_residuals();
  const auto& sizes = cost.parameter_block_sizes();
  std::vector<double*> ptr;
  for (auto& b : blocks) ptr.push_back(b.data());
  std::vector<Block> jac(blocks.size());
  std::vector<double*> jptr;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    jac[i].assign(static_cast<std::size_t>(m * sizes[i]), 0.0);
    jptr.push_back(jac[i].data());
  }
  Eigen::VectorXd r(m), rp(m), rm(m);
  ASSERT_TRUE(cost.Evaluate(ptr.data(), r.data(), jptr.data()));
  RightQuaternionManifold manifold;
  const double h = 1e-6;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const bool quat = sizes[i] == 4;
    const int dims = quat ? 3 : sizes[i];
    for (int c = 0; c < dims; ++c) {
      const Block saved = blocks[i];
      for (double sign : {1.0, -1.0}) {
        if (quat) {
          double delta[3] = {0, 0, 0};
          delta[c] = sign * h;
          manifold.Plus(saved.data(), delta, blocks[i].data());
        } else {
          blocks[i][static_cast<std::size_t>(c)] += sign * h;
        }
        ASSERT_TRUE(cost.Evaluate(ptr.data(), (sign > 0 ? rp : rm).data(), nullptr));
        blocks[i] = saved;
      }
      const Eigen::VectorXd numeric = (rp - rm) / (2 * h);
      for (int row = 0; row < m; ++row) {
        const double analytic = jac[i][static_cast<std::size_t>(row * sizes[i] + c)];
        EXPECT_NEAR(analytic, numeric(row), tol * (1.0 + std::abs(numeric(row))))
            << "block " << i << " column " << c << " row " << row;
      }
    }
  }
}

std::vector<Block> knot_blocks(std::mt19937& rng, int n) {
  std::vector<Block> blocks;
  Eigen::Quaterniond q = Eigen::Quaterniond::UnitRandom();
  for (int i = 0; i < n; ++i) {
    const Block d = random_vec(rng, 3, 0.0, 0.3);
    q = q * Eigen::Quaterniond(so3::exp(Eigen::Vector3d(d[0], d[1], d[2])));
    blocks.push_back({q.x(), q.y(), q.z(), q.w()});
  }
  return blocks;
}

TEST(CamImuResiduals, ImuResidualJacobiansMatchNumericOnes) {
  std::mt19937 rng(4);
  constexpr int N = 4;
  ImuResidual<N>::Sample s{
      0.37, 0.81, 0.05, 1.0, Eigen::Vector3d(0.3, -9.5, 1.2), Eigen::Vector3d(0.2, -0.1, 0.4)};
  const ImuResidual<N> cost(s, 0.05, 0.002);
  std::vector<Block> blocks = knot_blocks(rng, N);
  for (int i = 0; i < 3 * N; ++i) blocks.push_back(random_vec(rng, 3, 0.0, 0.5));
  blocks.push_back({0.3, -0.2, -9.8});              // gravity
  blocks.push_back(random_vec(rng, 3, 1.0, 0.02));  // S_a
  blocks.push_back(random_vec(rng, 3, 0.0, 0.02));  // M_a
  blocks.push_back(random_vec(rng, 3, 1.0, 0.02));  // S_g
  blocks.push_back(random_vec(rng, 3, 0.0, 0.02));  // M_g
  blocks.push_back(random_quat(rng));               // C_bg
  blocks.push_back(random_vec(rng, 9, 0.0, 1e-3));  // B_g
  check_jacobians(cost, blocks, 2e-5);
}

/// The blocks of a frame residual: `window` rotation knots turning by `turn` per knot, as many
/// position knots moving by `step` (and a quadratic z), R_cam_imu as the rotation vector
/// `r_ci`, t_cam_imu and the timeshift.
std::vector<Block> frame_blocks(int window, const Eigen::Vector3d& turn, const Eigen::Vector3d& step,
                                const Eigen::Vector3d& r_ci, const Block& t_ci, double shift) {
  std::vector<Block> blocks;
  for (int i = 0; i < window; ++i) {
    const Eigen::Quaterniond q(so3::exp(turn * i));
    blocks.push_back({q.x(), q.y(), q.z(), q.w()});
  }
  for (int i = 0; i < window; ++i) blocks.push_back({step.x() * i, step.y() * i, step.z() * i * i});
  const Eigen::Quaterniond qci(so3::exp(r_ci));
  blocks.push_back({qci.x(), qci.y(), qci.z(), qci.w()});
  blocks.push_back(t_ci);
  blocks.push_back({shift});
  return blocks;
}

TEST(CamImuResiduals, FrameResidualJacobiansMatchNumericOnesIncludingTheTimeshiftAndTheRobustLoss) {
  constexpr int N = 5;
  const CameraModel camera = sim::CamImuSimOptions::default_sim_camera();
  const SplineTiming<N> timing{0.0, 0.05, 20};
  // Knots near a pose that looks at points 1 m in front of the camera.
  std::vector<Block> blocks =
      frame_blocks(N + 2, Eigen::Vector3d(0.02, -0.01, 0.015), Eigen::Vector3d(0.01, -0.02, 0.005),
                   Eigen::Vector3d::Zero(), {0.02, -0.01, 0.03}, 0.004);
  std::vector<Eigen::Vector3d> pts;
  std::vector<Eigen::Vector2d> px;
  for (int k = 0; k < 6; ++k) {
    pts.emplace_back(-0.1 + 0.05 * k, 0.04 * (k % 3) - 0.04, 1.0 + 0.02 * k);
    // Observed pixels: some near the prediction, two far away (in the robust loss's tail).
    px.emplace_back(150.0 + 9.0 * k + (k == 2 ? 6.0 : 0.0), 110.0 + (k == 4 ? -4.0 : 0.5));
  }
  const int first = 3;
  const FrameResidual<N> cost(camera, pts, px, 0.2, first, timing, 0.3, 0.9, /*compressed=*/false);
  check_jacobians(cost, blocks, 2e-5);
}

// A rolling shutter: every corner at its own row's time, the line delay one more block. The
// frame is placed near a knot so that its corners straddle two segments of the spline.
TEST(CamImuResiduals, RollingShutterFrameResidualJacobiansMatchNumericOnesAcrossAKnot) {
  constexpr int N = 4;
  CameraModel camera = sim::CamImuSimOptions::default_sim_camera();
  camera.shutter.kind = Shutter::Kind::kRolling;
  camera.shutter.line_delay_s = 40e-6;  // 240 rows: 9.6 ms of readout
  camera.shutter.stamp_row = Shutter::StampRow::kMiddle;
  const SplineTiming<N> timing{0.0, 0.01, 40};
  std::vector<Block> blocks =
      frame_blocks(N + 2, Eigen::Vector3d(0.02, -0.01, 0.015), Eigen::Vector3d(0.01, -0.02, 0.005),
                   Eigen::Vector3d::Zero(), {0.02, -0.01, 0.03}, 0.002);
  blocks.push_back({40e-6});
  std::vector<Eigen::Vector3d> pts;
  std::vector<Eigen::Vector2d> px;
  for (int k = 0; k < 8; ++k) {
    pts.emplace_back(-0.1 + 0.03 * k, 0.06 * (k % 4) - 0.09, 1.0 + 0.02 * k);
    px.emplace_back(140.0 + 9.0 * k, 20.0 + 28.0 * k + (k == 5 ? 5.0 : 0.3));  // rows 20 .. 216
  }
  // t_cam 0.1 + shift 0.002: the middle row at 0.102 s, the corners from 0.0977 s to 0.1056 s,
  // across a knot.
  const int first = timing.segment(0.102).first_knot - 1;
  ASSERT_NE(timing.segment(0.1 + 0.002 + (20.0 - 119.5) * 40e-6).first_knot,
            timing.segment(0.1 + 0.002 + (216.0 - 119.5) * 40e-6).first_knot);
  const FrameResidual<N> cost(camera, pts, px, 0.1, first, timing, 0.3, 0.9, /*compressed=*/true,
                              /*rolling=*/true);
  ASSERT_EQ(cost.num_residuals(), 16);  // not compressed
  ASSERT_EQ(static_cast<int>(cost.parameter_block_sizes().size()), 2 * (N + 2) + 4);
  EXPECT_TRUE(cost.in_window(0.002, 40e-6));
  check_jacobians(cost, blocks, 2e-5);
  // With a line delay of 0 it is the global-shutter residual.
  const FrameResidual<N> global(camera, pts, px, 0.1, first, timing, 0.3, 0.9, /*compressed=*/false);
  blocks.back() = {0.0};
  std::vector<double*> ptr;
  for (auto& b : blocks) ptr.push_back(b.data());
  Eigen::VectorXd r_rolling(16), r_global(16);
  ASSERT_TRUE(cost.Evaluate(ptr.data(), r_rolling.data(), nullptr));
  ASSERT_TRUE(global.Evaluate(ptr.data(), r_global.data(), nullptr));
  EXPECT_LT((r_rolling - r_global).norm(), 1e-12);
}

// The solver's form of a frame (7 rows) against the corners' own rows: the same cost, gradient
// J^T r and Gauss-Newton matrix J^T J over all blocks, with corners in the robust loss's tail.
/// The knot window of a frame whose twelve corners (twelve_corners) lie ahead of the camera.
std::vector<Block> twelve_corner_frame_blocks(int n) {
  return frame_blocks(n + 2, Eigen::Vector3d(0.03, -0.02, 0.01), Eigen::Vector3d(0.02, -0.01, 0.004),
                      Eigen::Vector3d(0.1, -0.2, 3.0), {0.03, -0.02, 0.01}, 0.006);
}

/// Twelve board points and their detections: 0.4 px of noise, corner 3 an 8 px outlier.
std::pair<std::vector<Eigen::Vector3d>, std::vector<Eigen::Vector2d>> twelve_corners() {
  std::vector<Eigen::Vector3d> pts;
  std::vector<Eigen::Vector2d> px;
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.4);
  for (int k = 0; k < 12; ++k) {
    pts.emplace_back(-0.15 + 0.03 * k, 0.05 * (k % 4) - 0.07, 1.1 + 0.01 * k);
    px.emplace_back(120.0 + 11.0 * k + noise(rng) + (k == 3 ? 8.0 : 0.0), 100.0 + 6.0 * (k % 4) + noise(rng));
  }
  return {pts, px};
}

/// The Jacobian of `cost` at `blocks` in tangent coordinates (quaternion blocks: their first three
/// ambient columns), stacked over the blocks, and its residuals into *r.
Eigen::MatrixXd stacked_tangent_jacobian(const ceres::CostFunction& cost, std::vector<Block>& blocks,
                                         Eigen::VectorXd* r) {
  const int m = cost.num_residuals();
  const auto& sizes = cost.parameter_block_sizes();
  std::vector<double*> ptr;
  for (auto& b : blocks) ptr.push_back(b.data());
  std::vector<Block> jac(blocks.size());
  std::vector<double*> jptr;
  int cols = 0;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    jac[i].assign(static_cast<std::size_t>(m * sizes[i]), 0.0);
    jptr.push_back(jac[i].data());
    cols += sizes[i] == 4 ? 3 : sizes[i];
  }
  r->resize(m);
  EXPECT_TRUE(cost.Evaluate(ptr.data(), r->data(), jptr.data()));
  Eigen::MatrixXd J(m, cols);
  int c0 = 0;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const int dims = sizes[i] == 4 ? 3 : sizes[i];
    for (int row = 0; row < m; ++row)
      for (int c = 0; c < dims; ++c) J(row, c0 + c) = jac[i][static_cast<std::size_t>(row * sizes[i] + c)];
    c0 += dims;
  }
  return J;
}

TEST(CamImuResiduals, CompressedFrameResidualHasTheCornersCostGradientAndNormalMatrix) {
  constexpr int N = 4;
  const CameraModel camera = sim::CamImuSimOptions::default_sim_camera();
  const SplineTiming<N> timing{0.0, 0.05, 20};
  std::vector<Block> blocks = twelve_corner_frame_blocks(N);
  const auto corners = twelve_corners();
  const auto& pts = corners.first;
  const auto& px = corners.second;
  const FrameResidual<N> full(camera, pts, px, 0.21, 1, timing, 0.3, 0.9, false);
  const FrameResidual<N> compact(camera, pts, px, 0.21, 1, timing, 0.3, 0.9, true);
  ASSERT_EQ(compact.num_residuals(), 7);
  ASSERT_EQ(full.num_residuals(), 24);
  Eigen::VectorXd rf, rc;
  const Eigen::MatrixXd Jf = stacked_tangent_jacobian(full, blocks, &rf);
  const Eigen::MatrixXd Jc = stacked_tangent_jacobian(compact, blocks, &rc);
  EXPECT_NEAR(rc.squaredNorm(), rf.squaredNorm(), 1e-9 * rf.squaredNorm());
  const Eigen::VectorXd gf = Jf.transpose() * rf, gc = Jc.transpose() * rc;
  EXPECT_LT((gc - gf).norm(), 1e-7 * gf.norm()) << gf.transpose() << "\n" << gc.transpose();
  const Eigen::MatrixXd Hf = Jf.transpose() * Jf, Hc = Jc.transpose() * Jc;
  EXPECT_LT((Hc - Hf).norm(), 1e-8 * Hf.norm());
  EXPECT_GT(gf.norm(), 1.0);  // the frame is off its prediction: the comparison is not of zeros
  // The cost alone (no Jacobians) has the same norm.
  Eigen::VectorXd r_only(7);
  std::vector<double*> ptr;
  for (auto& b : blocks) ptr.push_back(b.data());
  ASSERT_TRUE(compact.Evaluate(ptr.data(), r_only.data(), nullptr));
  EXPECT_NEAR(r_only.squaredNorm(), rf.squaredNorm(), 1e-9 * rf.squaredNorm());
}

TEST(CamImuResiduals, BiasWalkResidualIsTheWeightedBiasDerivative) {
  constexpr int N = 4;
  const BiasWalkResidual<N> cost(0.3, 2.0, 5.0);
  std::mt19937 rng(2);
  std::vector<Block> blocks;
  for (int i = 0; i < N; ++i) blocks.push_back(random_vec(rng, 3, 0.0, 1.0));
  check_jacobians(cost, blocks, 1e-6);
  // Constant knots: no derivative, no cost.
  std::vector<Block> flat(N, Block{0.1, 0.2, 0.3});
  std::vector<const double*> ptr;
  for (auto& b : flat) ptr.push_back(b.data());
  Eigen::Vector3d r;
  ASSERT_TRUE(cost.Evaluate(ptr.data(), r.data(), nullptr));
  EXPECT_LT(r.norm(), 1e-12);
}

TEST(CamImuResiduals, PriorJacobiansMatchNumericOnes) {
  std::mt19937 rng(7);
  Eigen::VectorXd x0(9), sigma(9);
  for (int i = 0; i < 9; ++i) {
    x0(i) = 0.1 * i - 0.3;
    sigma(i) = 0.01 * (i + 1);
  }
  check_jacobians(VectorPrior(x0, sigma), {random_vec(rng, 9, 0.0, 0.2)}, 1e-6);
  const Eigen::Matrix3d R0 = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  check_jacobians(RotationPrior(R0, 0.02), {random_quat(rng)}, 1e-5);
  // At the prior's centre the rotation prior is zero.
  const Eigen::Quaterniond q0(R0);
  const double centre[4] = {q0.x(), q0.y(), q0.z(), q0.w()};
  const double* p[] = {centre};
  Eigen::Vector3d r;
  RotationPrior(R0, 0.02).Evaluate(p, r.data(), nullptr);
  EXPECT_LT(r.norm(), 1e-12);
}

/// r = [x + y, z] / 0.1: x - y has no data.
class SumAndZ final : public ceres::SizedCostFunction<2, 1, 1, 1> {
 public:
  bool Evaluate(double const* const* p, double* r, double** jac) const override {
    r[0] = (p[0][0] + p[1][0] - 1.0) / 0.1;
    r[1] = (p[2][0] - 2.0) / 0.1;
    if (jac) {
      for (int b = 0; b < 3; ++b) {
        if (!jac[b]) continue;
        jac[b][0] = b < 2 ? 10.0 : 0.0;
        jac[b][1] = b == 2 ? 10.0 : 0.0;
      }
    }
    return true;
  }
};

/// r = (a + b x + c z + d x^2 - y) / sigma with y = 1 + x / 2: a line in x with a term in z whose
/// coefficient c may be held, and a nuisance d.
class LineWithHeldTerm final : public ceres::SizedCostFunction<1, 1, 1, 1, 1> {
 public:
  LineWithHeldTerm(double x, double z, double sigma) : x_(x), z_(z), w_(1.0 / sigma) {}
  bool Evaluate(double const* const* p, double* r, double** jac) const override {
    r[0] = w_ * (p[0][0] + p[1][0] * x_ + p[2][0] * z_ + p[3][0] * x_ * x_ - 1.0 - 0.5 * x_);
    const double d[4] = {1.0, x_, z_, x_ * x_};
    if (jac)
      for (int b = 0; b < 4; ++b)
        if (jac[b]) jac[b][0] = w_ * d[b];
    return true;
  }

 private:
  double x_, z_, w_;
};

// The change of the gradient when the camera's intrinsics move (for the held-input covariance):
// J^T dr with the corners' Jacobian and the corners' numeric change, the same for the compressed
// and the uncompressed form of a frame.
TEST(CamImuResiduals, IntrinsicsScoresAreTheCornersJacobianTimesTheirChange) {
  constexpr int N = 4;
  const CameraModel camera = sim::CamImuSimOptions::default_sim_camera();
  const SplineTiming<N> timing{0.0, 0.05, 20};
  std::vector<Block> blocks = twelve_corner_frame_blocks(N);
  const auto corners = twelve_corners();
  const auto& pts = corners.first;
  const auto& px = corners.second;
  const Eigen::Vector4d dk(0.8, 0.7, -0.3, 0.2), dd(0.01, -0.004, 0.001, 0.0);
  const auto moved = [&](double f) {
    CameraModel c = camera;
    c.intrinsics += f * dk;
    c.distortion_coeffs += f * dd;
    return c;
  };
  std::vector<double*> ptr;
  for (auto& b : blocks) ptr.push_back(b.data());
  const FrameResidual<N> full(camera, pts, px, 0.21, 1, timing, 0.3, 0.9, false);
  const FrameResidual<N> compact(camera, pts, px, 0.21, 1, timing, 0.3, 0.9, true);
  // Numeric: the corners' residuals of cameras moved by +-1e-3 of the direction.
  const auto residuals_of = [&](double f) {
    const FrameResidual<N> r(moved(f), pts, px, 0.21, 1, timing, 0.3, 0.9, false);
    Eigen::VectorXd out(r.num_residuals());
    EXPECT_TRUE(r.Evaluate(ptr.data(), out.data(), nullptr));
    return out;
  };
  const Eigen::VectorXd dr = (residuals_of(1e-3) - residuals_of(-1e-3)) / 2e-3;
  EXPECT_GT(dr.norm(), 0.05);  // not a comparison of zeros
  Eigen::VectorXd rf;
  const Eigen::MatrixXd Jf = stacked_tangent_jacobian(full, blocks, &rf);
  const Eigen::VectorXd expected = Jf.transpose() * dr;
  const std::vector<std::pair<CameraModel, CameraModel>> moves = {{moved(1.0), moved(-1.0)}};
  for (const FrameResidual<N>* cost : {&full, &compact}) {
    const auto scores = cost->intrinsics_scores(ptr.data(), moves, 0.5);
    ASSERT_EQ(scores.size(), 1u);
    ASSERT_EQ(scores[0].size(), blocks.size());
    Eigen::VectorXd stacked(expected.size());
    Eigen::Index at = 0;
    for (const auto& g : scores[0]) {
      stacked.segment(at, g.size()) = g;
      at += g.size();
    }
    ASSERT_EQ(at, expected.size());
    EXPECT_LT((stacked - expected).norm(), 1e-3 * expected.norm()) << stacked.transpose() << "\n"
                                                                   << expected.transpose();
  }
}

// A held input's covariance, propagated, is the spread its own error causes in the wanted
// parameters: y = a + b x + c z + d x^2 with c held (sigma 0.3) and d a nuisance. The problem is
// linear, so solving with c moved by its sigma shifts (a, b) by exactly one column of the share.
TEST(MarginalCovariance, AHeldInputsShareIsTheShiftItsErrorCauses) {
  const double sigma_c = 0.3;
  std::vector<double> xs, zs;
  for (int i = 0; i < 12; ++i) {
    xs.push_back(0.1 * i);
    zs.push_back(std::sin(0.7 * i) + 0.2 * i);
  }
  double a = 0.2, b = -0.4, c = 0.7, d = 3.0;
  ceres::Problem problem;
  for (std::size_t i = 0; i < xs.size(); ++i)
    problem.AddResidualBlock(new LineWithHeldTerm(xs[i], zs[i], 0.1), nullptr, &a, &b, &c, &d);
  problem.SetParameterBlockConstant(&c);
  const auto solve = [&] {
    ceres::Solver::Options so;
    so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-14;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    return Eigen::Vector2d(a, b);
  };
  const Eigen::Vector2d at_c = solve();
  // J^T dr with dr_i = z_i sigma_c / 0.1 and J_i = [1, x_i, x_i^2] / 0.1 for a, b, d.
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < xs.size(); ++i)
    g += Eigen::Vector3d(1.0, xs[i], xs[i] * xs[i]) / 0.1 * (zs[i] * sigma_c / 0.1);
  const MarginalCovariance::HeldScore score = {{&a, Eigen::VectorXd::Constant(1, g(0))},
                                               {&b, Eigen::VectorXd::Constant(1, g(1))},
                                               {&d, Eigen::VectorXd::Constant(1, g(2))}};
  MarginalCovariance held;
  ASSERT_TRUE(held.compute(problem, {&a, &b}, 1, {}, {score}));
  ASSERT_TRUE(held.has_held());
  c += sigma_c;
  const Eigen::Vector2d shift = solve() - at_c;
  Eigen::Matrix2d share;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) share(i, j) = held.held_block(i ? &b : &a, j ? &b : &a)(0, 0);
  EXPECT_LT((share - shift * shift.transpose()).norm(), 1e-6 * share.norm()) << share << "\n" << shift;
  EXPECT_GT(shift.norm(), 0.05);  // not a comparison of zeros
  // The data's own covariance is unchanged by the held input; without one there is no share.
  MarginalCovariance plain;
  ASSERT_TRUE(plain.compute(problem, {&a, &b}, 1));
  EXPECT_FALSE(plain.has_held());
  EXPECT_EQ(plain.held_block(&a, &a)(0, 0), 0.0);
  EXPECT_NEAR(plain.block(&a, &b)(0, 0), held.block(&a, &b)(0, 0), 1e-12);
}

TEST(MarginalCovariance, AnUndeterminedDirectionGivesNanForItsCoordinatesAndNamesThem) {
  double x = 0.4, y = 0.6, z = 2.0, w = 5.0;
  ceres::Problem problem;
  problem.AddResidualBlock(new SumAndZ, nullptr, &x, &y, &z);
  // w: a nuisance parameter observed on its own, marginalised out.
  problem.AddResidualBlock(
      new VectorPrior(Eigen::VectorXd::Constant(1, 4.0), Eigen::VectorXd::Constant(1, 0.2)), nullptr, &w);
  MarginalCovariance cov;
  ASSERT_TRUE(cov.compute(problem, {&x, &y, &z}, 1));
  EXPECT_TRUE(std::isnan(cov.block(&x, &x)(0, 0)));
  EXPECT_TRUE(std::isnan(cov.block(&y, &y)(0, 0)));
  EXPECT_TRUE(std::isnan(cov.block(&x, &z)(0, 0)));
  EXPECT_NEAR(cov.block(&z, &z)(0, 0), 0.01, 1e-12);  // sigma 0.1
  ASSERT_EQ(cov.undetermined().size(), 1u);
  const auto& parts = cov.undetermined()[0].parts;
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_NEAR(std::abs(parts[0].second), std::sqrt(0.5), 1e-9);
  EXPECT_TRUE((parts[0].first.block == &x && parts[1].first.block == &y) ||
              (parts[0].first.block == &y && parts[1].first.block == &x));
  EXPECT_TRUE(std::isnan(sigma_of(cov.block(&x, &x))(0)));
  // Observed on its own as well, x and y are determined again.
  problem.AddResidualBlock(
      new VectorPrior(Eigen::VectorXd::Constant(1, 10.0), Eigen::VectorXd::Constant(1, 0.4)), nullptr, &x);
  ASSERT_TRUE(cov.compute(problem, {&x, &y, &z}, 1));
  EXPECT_TRUE(cov.undetermined().empty());
  // H = [106.25 100; 100 100] (x + y with sigma 0.1, x with 0.4): H^-1 = [0.16 -0.16; -0.16 0.17].
  EXPECT_NEAR(cov.block(&x, &x)(0, 0), 0.16, 1e-9);
  EXPECT_NEAR(cov.block(&y, &y)(0, 0), 0.17, 1e-9);
  EXPECT_NEAR(cov.block(&x, &y)(0, 0), -0.16, 1e-9);
}

}  // namespace
}  // namespace imucal::calib::camimu
