// SPDX-License-Identifier: BSD-3-Clause
// The camera chain solve on synthetic views: a board moving smoothly in front of two or three
// cameras with their own intrinsics, poses and time offsets, projected with pixel noise; the
// estimate must hold the truth within its reported sigmas, find an offset between cameras that
// stamp alike, and chain a camera that overlaps only its neighbour.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "calib/camera_chain.hpp"
#include "calib/camera_chain_residuals.hpp"
#include "calib/marginal_covariance.hpp"
#include "tests/support/chain_views.hpp"

namespace imucal::calib {
namespace {

using test::chain_board;
using test::chain_camera;
using test::synthesize_chain;
using test::TruthCamera;

Eigen::Isometry3d pose(double rx, double ry, double rz, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() =
      (Eigen::AngleAxisd(rz, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(ry, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(rx, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  T.translation() = t;
  return T;
}

/// Errors of the estimate against the truth in units of its sigmas: intrinsics, rotation (about
/// the estimate's axes) and translation of T_cam_cam0, and the offset.
void expect_within_sigmas(const CameraChainCameraResult& r, const TruthCamera& truth, double k,
                          const std::string& what) {
  for (int i = 0; i < 4; ++i) {
    const double e = r.intrinsics.camera.intrinsics(i) - truth.camera.intrinsics(i);
    EXPECT_LT(std::abs(e), k * r.intrinsics.intrinsics_sigma(i))
        << what << " intrinsic " << i << " error " << e;
  }
  const Eigen::Matrix<double, 6, 6>& P = r.T_cam_cam0_covariance;
  const Eigen::AngleAxisd d(r.T_cam_cam0.linear().transpose() * truth.T_cam_cam0.linear());
  const Eigen::Vector3d rot = d.angle() * d.axis();
  const Eigen::Vector3d tra = truth.T_cam_cam0.translation() - r.T_cam_cam0.translation();
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(std::isfinite(P(i, i)) && std::isfinite(P(3 + i, 3 + i))) << what;
    EXPECT_LT(std::abs(rot(i)), k * std::sqrt(P(i, i))) << what << " rotation " << i;
    EXPECT_LT(std::abs(tra(i)), k * std::sqrt(P(3 + i, 3 + i))) << what << " translation " << i;
  }
  ASSERT_TRUE(std::isfinite(r.timeshift_sigma_s)) << what;
  EXPECT_LT(std::abs(r.timeshift_cam0_s - truth.shift_s), k * r.timeshift_sigma_s + 1e-9)
      << what << " offset " << r.timeshift_cam0_s << " against " << truth.shift_s;
}

bool has_warning(const CameraChainResult& r, const std::string& text) {
  for (const auto& w : r.warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

CameraChainOptions test_options() {
  CameraChainOptions o;
  o.threads = 2;
  return o;
}

TEST(CameraChain, AStereoPairStampedAlikeButTenMillisecondsApartIsFoundAndFlagged) {
  TruthCamera c0{chain_camera(480.0, 322.0)};
  TruthCamera c1{chain_camera(455.0, 316.0), pose(0.02, -0.03, 0.01, {-0.11, 0.004, 0.002}), 0.010};
  const std::vector<TruthCamera> truth = {c0, c1};
  const auto inputs = synthesize_chain(truth, 24.0, 0.15, 7);
  auto r = calibrate_camera_chain(chain_board(), inputs, test_options(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->cameras.size(), 2u);
  expect_within_sigmas(r->cameras[1], c1, 3.0, "cam1");
  for (int i = 0; i < 4; ++i)
    EXPECT_LT(std::abs(r->cameras[0].intrinsics.camera.intrinsics(i) - c0.camera.intrinsics(i)),
              3.0 * r->cameras[0].intrinsics.intrinsics_sigma(i));
  // The baseline against the truth, and a sigma on it.
  EXPECT_NEAR(r->cameras[1].baseline_m, c1.T_cam_cam0.translation().norm(),
              3.0 * r->cameras[1].baseline_sigma_m);
  EXPECT_GT(r->cameras[1].baseline_sigma_m, 0.0);
  EXPECT_GT(r->cameras[1].views_stamped_with_cam0, 0.9 * r->cameras[1].views_used);
  EXPECT_TRUE(has_warning(*r, "not synchronized"))
      << "the 10 ms between identically stamped cameras is not said";
  EXPECT_GT(r->cameras[0].shared_views[1], 250);
}

TEST(CameraChain, ASynchronizedPairGetsAnOffsetNearZeroAndNoWarning) {
  TruthCamera c0{chain_camera(480.0, 322.0)};
  TruthCamera c1{chain_camera(470.0, 330.0, DistortionModel::kEquidistant),
                 pose(-0.01, 0.02, 0.0, {0.09, -0.01, 0.003}), 0.0};
  const auto inputs = synthesize_chain({c0, c1}, 20.0, 0.15, 11);
  auto r = calibrate_camera_chain(chain_board(), inputs, test_options(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  expect_within_sigmas(r->cameras[1], c1, 3.0, "cam1");
  EXPECT_FALSE(has_warning(*r, "not synchronized"));
  EXPECT_LT(r->cameras[1].timeshift_sigma_s, 1e-3);
}

TEST(CameraChain, CamerasAtDifferentRatesArePlacedByTheirOffsets) {
  TruthCamera c0{chain_camera(480.0, 322.0)};
  TruthCamera c1{chain_camera(500.0, 318.0), pose(0.0, 0.05, 0.0, {-0.12, 0.0, 0.0}), -0.004};
  c1.rate_hz = 10.0;
  c1.stamp_phase_s = 0.023;
  const auto inputs = synthesize_chain({c0, c1}, 24.0, 0.15, 13);
  auto r = calibrate_camera_chain(chain_board(), inputs, test_options(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  expect_within_sigmas(r->cameras[1], c1, 3.0, "cam1");
  EXPECT_EQ(r->cameras[1].views_stamped_with_cam0, 0);
  EXPECT_FALSE(has_warning(*r, "not synchronized"));
}

// Still pairs seconds apart (a board held in a new place for each pair): no trajectory joins
// them, so with the offsets held every pair gets its own pose, as in Kalibr.
TEST(CameraChain, StillPairsWithOffsetsHeldGetOnePoseEach) {
  TruthCamera c0{chain_camera(480.0, 322.0)};
  TruthCamera c1{chain_camera(455.0, 316.0), pose(0.02, -0.03, 0.01, {-0.11, 0.004, 0.002}), 0.0};
  c0.rate_hz = c1.rate_hz = 0.5;
  const auto inputs = synthesize_chain({c0, c1}, 80.0, 0.15, 23);
  CameraChainOptions o = test_options();
  o.estimate_time_offsets = false;
  auto r = calibrate_camera_chain(chain_board(), inputs, o, {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->knot_spacing_s, 0.0);
  EXPECT_FALSE(r->cameras[1].timeshift_estimated);
  EXPECT_EQ(r->cameras[1].timeshift_sigma_s, 0.0);
  const auto& cam = r->cameras[1];
  for (int i = 0; i < 4; ++i)
    EXPECT_LT(std::abs(cam.intrinsics.camera.intrinsics(i) - c1.camera.intrinsics(i)),
              3.0 * cam.intrinsics.intrinsics_sigma(i));
  const Eigen::Vector3d e = cam.T_cam_cam0.translation() - c1.T_cam_cam0.translation();
  for (int i = 0; i < 3; ++i)
    EXPECT_LT(std::abs(e(i)), 3.0 * std::sqrt(cam.T_cam_cam0_covariance(3 + i, 3 + i)));
  EXPECT_LT(r->rms_px, 0.3);
}

TEST(CameraChain, AThirdCameraThatOverlapsOnlyTheSecondIsChainedThroughIt) {
  TruthCamera c0{chain_camera(480.0, 322.0)};
  TruthCamera c1{chain_camera(460.0, 318.0), pose(0.01, -0.02, 0.0, {-0.10, 0.0, 0.0}), 0.0};
  TruthCamera c2{chain_camera(470.0, 325.0), pose(0.0, 0.03, 0.02, {-0.21, 0.01, 0.0}), 0.006};
  c0.visible_to_s = 12.0;    // cam0 sees the board in the first half only,
  c2.visible_from_s = 13.0;  // cam2 in the second: they never share a view
  const auto inputs = synthesize_chain({c0, c1, c2}, 26.0, 0.15, 17);
  auto r = calibrate_camera_chain(chain_board(), inputs, test_options(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->cameras.size(), 3u);
  EXPECT_EQ(r->cameras[2].linked_to, 1);
  EXPECT_EQ(r->cameras[0].shared_views[2], 0);
  EXPECT_GT(r->cameras[1].shared_views[2], 100);
  expect_within_sigmas(r->cameras[1], c1, 3.0, "cam1");
  expect_within_sigmas(r->cameras[2], c2, 3.0, "cam2");
  // T_cn_cnm1 of cam2 is against cam1.
  const Eigen::Isometry3d T21 = c2.T_cam_cam0 * c1.T_cam_cam0.inverse();
  const Eigen::Vector3d e = r->cameras[2].T_cn_cnm1.translation() - T21.translation();
  for (int i = 0; i < 3; ++i) EXPECT_LT(std::abs(e(i)), 3.0 * r->cameras[2].T_cn_cnm1_translation_sigma_m(i));
}

TEST(CameraChain, ACameraThatNeverSharesAViewIsNamedWithWhatToRecord) {
  TruthCamera c0{chain_camera(480.0, 322.0)};
  TruthCamera c1{chain_camera(460.0, 318.0), pose(0.0, 0.0, 0.0, {-0.10, 0.0, 0.0}), 0.0};
  c0.visible_to_s = 10.0;
  c1.visible_from_s = 11.0;
  const auto inputs = synthesize_chain({c0, c1}, 22.0, 0.15, 19);
  auto r = calibrate_camera_chain(chain_board(), inputs, test_options(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInsufficientData);
  EXPECT_NE(r.error().message.find("cam1 never saw the target at the same time as cam0"), std::string::npos)
      << r.error().message;
  EXPECT_NE(r.error().message.find("record the target where cam1"), std::string::npos);
}

TEST(CameraChain, NoCameraIsRefusedAndOneIsCalibratedOnItsTrajectory) {
  auto none = calibrate_camera_chain(chain_board(), std::span<const CameraChainInput>(), test_options(), {});
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.error().code, Errc::kInvalidArgument);
  TruthCamera c0{chain_camera(480.0, 322.0)};
  const auto inputs = synthesize_chain({c0}, 12.0, 0.15, 3);
  auto r = calibrate_camera_chain(chain_board(), inputs, test_options(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->cameras.size(), 1u);
  const auto& k = r->cameras[0].intrinsics;
  for (int i = 0; i < 4; ++i)
    EXPECT_LT(std::abs(k.camera.intrinsics[i] - c0.camera.intrinsics[i]), 3.0 * k.intrinsics_sigma[i]) << i;
  // A global-shutter camera: the evidence keeps it global.
  EXPECT_FALSE(k.camera.shutter.rolling()) << r->cameras[0].shutter_choice;
  EXPECT_EQ(r->cameras[0].shutter_choice.rfind("global, chosen by the evidence", 0), 0u)
      << r->cameras[0].shutter_choice;
}

// The residual's analytic Jacobians against central differences in every block's tangent space.
TEST(CameraChain, TheResidualsJacobiansMatchNumericOnes) {
  constexpr int N = 4;
  using R = chain::ChainFrameResidual<N>;
  const SplineTiming<N> timing{0.0, 0.05, 12};
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<std::array<double, 4>> q(R::kWindow);
  std::vector<std::array<double, 3>> p(R::kWindow);
  for (int i = 0; i < R::kWindow; ++i) {
    const Eigen::Quaterniond qi(
        Eigen::AngleAxisd(0.1 * u(rng), Eigen::Vector3d(u(rng), u(rng), 1).normalized()));
    q[i] = {qi.x(), qi.y(), qi.z(), qi.w()};
    p[i] = {0.1 + 0.02 * u(rng), 0.1 + 0.02 * u(rng), -0.8 + 0.02 * u(rng)};
  }
  const Eigen::Quaterniond qc(Eigen::AngleAxisd(0.05, Eigen::Vector3d(0.3, 1, 0.2).normalized()));
  std::array<double, 4> qci = {qc.x(), qc.y(), qc.z(), qc.w()};
  std::array<double, 3> tci = {-0.1, 0.01, 0.02};
  double shift = 0.012;
  std::array<double, 4> intr = {480.0, 482.0, 320.0, 240.0};
  std::array<double, 2> proj = {0.0, 0.0};  // pinhole: the projection block is held
  std::array<double, 4> dist = {-0.2, 0.05, 0.001, -0.0005};
  std::vector<Eigen::Vector3d> pts;
  std::vector<Eigen::Vector2d> px;
  for (int i = 0; i < 10; ++i) {
    pts.emplace_back(0.05 * (i % 5), 0.04 * (i / 5), 0.0);
    px.emplace_back(300.0 + 10 * i, 220.0 + 7 * i);
  }
  // A rolling shutter (the third case): 30 us per row over these corners' rows 220 .. 283, so that
  // with the knots 5 ms apart the corners straddle a knot.
  Shutter rs;
  rs.kind = Shutter::Kind::kRolling;
  rs.line_delay_s = 30e-6;
  double line_delay = 30e-6;
  for (const int variant : {0, 1, 2}) {
    const bool robust = variant > 0, rolling = variant == 2;
    const SplineTiming<N> knots = rolling ? SplineTiming<N>{0.0, 0.005, 60} : timing;
    // Rolling: the corners' times t_view + shift + v * 30 us span 54.1-56.0 ms, across the knot at 55.
    const double t_view = rolling ? 0.0355 : 0.21;
    const int first = rolling ? knots.segment(t_view + shift + 250 * 30e-6).first_knot - 1 : 3;
    if (rolling) {
      ASSERT_NE(knots.segment(t_view + shift + 220 * 30e-6).first_knot,
                knots.segment(t_view + shift + 283 * 30e-6).first_knot);
    }
    R cost({ProjectionModel::kPinhole, DistortionModel::kRadtan}, 640, 480, pts, px, t_view, first, knots,
           0.2, robust ? 0.3 : 0.0, false, rolling ? &rs : nullptr);
    if (rolling) {
      ASSERT_TRUE(cost.in_window(shift, line_delay));
    }
    std::vector<double*> blocks;
    for (auto& x : q) blocks.push_back(x.data());
    for (auto& x : p) blocks.push_back(x.data());
    for (double* x : {qci.data(), tci.data(), &shift, intr.data(), proj.data(), dist.data()})
      blocks.push_back(x);
    if (rolling) blocks.push_back(&line_delay);
    const auto& sizes = cost.parameter_block_sizes();
    const int rows = cost.num_residuals();
    std::vector<std::vector<double>> jac(blocks.size());
    std::vector<double*> jp;
    for (std::size_t b = 0; b < blocks.size(); ++b) {
      jac[b].assign(static_cast<std::size_t>(rows * sizes[b]), 0.0);
      jp.push_back(jac[b].data());
    }
    std::vector<double> r0(static_cast<std::size_t>(rows));
    ASSERT_TRUE(cost.Evaluate(blocks.data(), r0.data(), jp.data()));
    camimu::RightQuaternionManifold manifold;
    for (std::size_t b = 0; b < blocks.size(); ++b) {
      const bool quat = sizes[b] == 4 && (b < static_cast<std::size_t>(R::kWindow) || b == R::kRci);
      const int tangent = quat ? 3 : sizes[b];
      for (int k = 0; k < tangent; ++k) {
        // The line delay moves a corner's time by its row (up to 283) times the step.
        const bool delay = rolling && b + 1 == blocks.size();
        const double h = quat ? 1e-6 : delay ? 3e-9 : 1e-6 * std::max(1.0, std::abs(blocks[b][k]));
        std::vector<double> plus(static_cast<std::size_t>(rows)), minus(static_cast<std::size_t>(rows));
        const std::vector<double> saved(blocks[b], blocks[b] + sizes[b]);
        for (int sign : {1, -1}) {
          if (quat) {
            double d[3] = {0, 0, 0};
            d[k] = sign * h;
            manifold.Plus(saved.data(), d, blocks[b]);
          } else {
            blocks[b][k] = saved[static_cast<std::size_t>(k)] + sign * h;
          }
          ASSERT_TRUE(cost.Evaluate(blocks.data(), sign > 0 ? plus.data() : minus.data(), nullptr));
          std::copy(saved.begin(), saved.end(), blocks[b]);
        }
        for (int row = 0; row < rows; ++row) {
          const double numeric = (plus[row] - minus[row]) / (2 * h);
          const double analytic = jac[b][static_cast<std::size_t>(row * sizes[b] + k)];
          EXPECT_NEAR(analytic, numeric, 1e-4 * std::max(1.0, std::abs(numeric)))
              << "block " << b << " column " << k << " row " << row << (robust ? " (robust)" : "")
              << (rolling ? " (rolling)" : "");
        }
      }
    }
    if (rolling) continue;  // a rolling shutter's views are not compressed
    // The compressed form: the same cost, gradient and Gauss-Newton matrix in 15 rows.
    R packed({ProjectionModel::kPinhole, DistortionModel::kRadtan}, 640, 480, pts, px, 0.21, 3, timing, 0.2,
             robust ? 0.3 : 0.0, true);
    ASSERT_EQ(packed.num_residuals(), R::kCompressedRows);
    std::vector<std::vector<double>> pjac(blocks.size());
    std::vector<double*> pjp;
    for (std::size_t b = 0; b < blocks.size(); ++b) {
      pjac[b].assign(static_cast<std::size_t>(R::kCompressedRows * sizes[b]), 0.0);
      pjp.push_back(pjac[b].data());
    }
    std::vector<double> pr(R::kCompressedRows);
    ASSERT_TRUE(packed.Evaluate(blocks.data(), pr.data(), pjp.data()));
    const auto stack = [&](const std::vector<std::vector<double>>& J, int n) {
      Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, 0);
      for (std::size_t b = 0; b < J.size(); ++b) {
        const bool quat = sizes[b] == 4 && (b < static_cast<std::size_t>(R::kWindow) || b == R::kRci);
        const int cols = quat ? 3 : sizes[b];
        Eigen::MatrixXd B(n, cols);
        for (int r = 0; r < n; ++r)
          for (int c = 0; c < cols; ++c) B(r, c) = J[b][static_cast<std::size_t>(r * sizes[b] + c)];
        Eigen::MatrixXd next(n, M.cols() + cols);
        next << M, B;
        M = next;
      }
      return M;
    };
    const Eigen::MatrixXd Jf = stack(jac, rows), Jc = stack(pjac, R::kCompressedRows);
    const Eigen::VectorXd rf = Eigen::Map<const Eigen::VectorXd>(r0.data(), rows);
    const Eigen::VectorXd rc = Eigen::Map<const Eigen::VectorXd>(pr.data(), R::kCompressedRows);
    EXPECT_NEAR(rc.squaredNorm(), rf.squaredNorm(), 1e-9 * rf.squaredNorm());
    const Eigen::MatrixXd Hf = Jf.transpose() * Jf, Hc = Jc.transpose() * Jc;
    EXPECT_LT((Hf - Hc).norm(), 1e-8 * Hf.norm()) << (robust ? "robust" : "plain");
    const Eigen::VectorXd gf = Jf.transpose() * rf, gc = Jc.transpose() * rc;
    EXPECT_LT((gf - gc).norm(), 1e-5 * std::max(1.0, gf.norm())) << (robust ? "robust" : "plain");
  }
}

// The per-stamp pose residual (offsets held): its 15 rows carry the Gauss-Newton matrix and the
// gradient of the corners' pixel residuals, differentiated numerically in every tangent space.
TEST(CameraChain, ThePoseResidualsRowsCarryTheCornersGaussNewtonMatrix) {
  using chain::ChainPoseResidual;
  std::vector<Eigen::Vector3d> pts;
  std::vector<Eigen::Vector2d> px;
  for (int i = 0; i < 12; ++i) {
    pts.emplace_back(0.05 * (i % 4), 0.04 * (i / 4), 0.0);
    px.emplace_back(290.0 + 12 * (i % 4) + 0.3 * i, 230.0 + 9 * (i / 4) - 0.2 * i);
  }
  const Eigen::Quaterniond qb(Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.1, 1, 0.3).normalized()));
  std::array<double, 4> q = {qb.x(), qb.y(), qb.z(), qb.w()};
  std::array<double, 3> p = {0.1, 0.05, -0.7};
  const Eigen::Quaterniond qc(Eigen::AngleAxisd(0.04, Eigen::Vector3d(0.3, 1, 0.2).normalized()));
  std::array<double, 4> qci = {qc.x(), qc.y(), qc.z(), qc.w()};
  std::array<double, 3> tci = {-0.1, 0.01, 0.02};
  std::array<double, 4> intr = {480.0, 482.0, 320.0, 240.0};
  std::array<double, 4> dist = {-0.2, 0.05, 0.001, -0.0005};
  // Mei's model with radtan: every one of the 10 camera parameters moves the corners.
  std::array<double, 2> proj = {0.4, 0.0};
  ChainPoseResidual cost(
      chain::ViewCorners({ProjectionModel::kOmni, DistortionModel::kRadtan}, 640, 480, pts, px, 1.0, 0.0));
  std::vector<double*> blocks = {q.data(),    p.data(),    qci.data(), tci.data(),
                                 intr.data(), proj.data(), dist.data()};
  const auto& sizes = cost.parameter_block_sizes();
  const std::vector<bool> quat = {true, false, true, false, false, false, false};
  std::vector<std::vector<double>> jac(blocks.size());
  std::vector<double*> jp;
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    jac[b].assign(static_cast<std::size_t>(chain::kCompressedRows * sizes[b]), 0.0);
    jp.push_back(jac[b].data());
  }
  std::vector<double> rc(chain::kCompressedRows);
  ASSERT_TRUE(cost.Evaluate(blocks.data(), rc.data(), jp.data()));
  std::vector<Eigen::Vector2d> r0;
  cost.pixel_residuals(blocks.data(), &r0);
  const int n = static_cast<int>(2 * r0.size());
  Eigen::MatrixXd Jn(n, 0), Jc(chain::kCompressedRows, 0);
  camimu::RightQuaternionManifold manifold;
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const int tangent = quat[b] ? 3 : sizes[b];
    Eigen::MatrixXd Bn(n, tangent), Bc(chain::kCompressedRows, tangent);
    for (int k = 0; k < tangent; ++k) {
      const std::vector<double> saved(blocks[b], blocks[b] + sizes[b]);
      std::vector<Eigen::Vector2d> rp, rm;
      const double h = quat[b] ? 1e-6 : 1e-6 * std::max(1.0, std::abs(saved[static_cast<std::size_t>(k)]));
      for (int sign : {1, -1}) {
        if (quat[b]) {
          double d[3] = {0, 0, 0};
          d[k] = sign * h;
          manifold.Plus(saved.data(), d, blocks[b]);
        } else {
          blocks[b][k] = saved[static_cast<std::size_t>(k)] + sign * h;
        }
        cost.pixel_residuals(blocks.data(), sign > 0 ? &rp : &rm);
        std::copy(saved.begin(), saved.end(), blocks[b]);
      }
      for (int i = 0; i < n / 2; ++i) Bn.block<2, 1>(2 * i, k) = (rp[i] - rm[i]) / (2 * h);
      for (int r = 0; r < chain::kCompressedRows; ++r)
        Bc(r, k) = jac[b][static_cast<std::size_t>(r * sizes[b] + k)];
    }
    Eigen::MatrixXd nn(n, Jn.cols() + tangent), nc(chain::kCompressedRows, Jc.cols() + tangent);
    nn << Jn, Bn;
    nc << Jc, Bc;
    Jn = nn;
    Jc = nc;
  }
  Eigen::VectorXd rn(n);
  for (int i = 0; i < n / 2; ++i) rn.segment<2>(2 * i) = r0[static_cast<std::size_t>(i)];
  const Eigen::VectorXd rcv = Eigen::Map<const Eigen::VectorXd>(rc.data(), chain::kCompressedRows);
  EXPECT_NEAR(rcv.squaredNorm(), rn.squaredNorm(), 1e-9 * rn.squaredNorm());
  const Eigen::MatrixXd Hn = Jn.transpose() * Jn, Hc = Jc.transpose() * Jc;
  EXPECT_LT((Hn - Hc).norm(), 1e-5 * Hn.norm());
  const Eigen::VectorXd gn = Jn.transpose() * rn, gc = Jc.transpose() * rcv;
  EXPECT_LT((gn - gc).norm(), 1e-5 * std::max(1.0, gn.norm()));
}

/// y = a + b x + e, a wanted, b a nuisance parameter; whitened with unit sigma.
struct LineCost {
  LineCost(double x, double y) : x_(x), y_(y) {}
  template <class T>
  bool operator()(const T* a, const T* b, T* r) const {
    r[0] = a[0] + b[0] * T(x_) - T(y_);
    return true;
  }
  double x_, y_;
};

/// The variance of `a` (plain and cluster-robust) fitted to clusters of `m` points whose errors
/// are unit white noise plus, with `shared`, a unit error common to the cluster.
std::pair<double, double> line_variances(bool shared, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> ux(-1.0, 1.0);
  double a = 0.0, b = 0.0;
  ceres::Problem problem;
  std::vector<std::vector<ceres::ResidualBlockId>> clusters;
  constexpr int kClusters = 300, kPerCluster = 8;
  for (int c = 0; c < kClusters; ++c) {
    const double u = shared ? n01(rng) : 0.0;
    clusters.emplace_back();
    for (int k = 0; k < kPerCluster; ++k) {
      const double x = ux(rng);
      const double y = 1.0 + 0.5 * x + u + n01(rng);
      clusters.back().push_back(problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<LineCost, 1, 1, 1>(new LineCost(x, y)), nullptr, &a, &b));
    }
  }
  ceres::Solver::Options o;
  o.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(o, &problem, &summary);
  MarginalCovariance cov;
  EXPECT_TRUE(cov.compute(problem, {&a}, 1, clusters));
  EXPECT_TRUE(cov.has_robust());
  EXPECT_EQ(cov.clusters(), kClusters);
  return {cov.block(&a, &a)(0, 0), cov.robust_block(&a, &a)(0, 0)};
}

// The sandwich equals the plain covariance on independent, correctly weighted residuals, and
// grows when a cluster of 8 shares a unit error the plain covariance does not know of: the
// variance of a cluster's sum is 8 + 64 instead of 8, so 9 times.
TEST(MarginalCovariance, TheClusterRobustCovarianceSeesSharedErrors) {
  const auto [plain, robust] = line_variances(false, 3);
  EXPECT_NEAR(plain, 1.0 / 2400.0, 1e-6);  // 1 / n for the mean of n unit-noise points
  EXPECT_NEAR(robust / plain, 1.0, 0.2);
  const auto [plain_s, robust_s] = line_variances(true, 5);
  EXPECT_NEAR(plain_s, 1.0 / 2400.0, 1e-6);  // the plain one does not see the shared error
  EXPECT_GT(robust_s / plain_s, 6.5);
  EXPECT_LT(robust_s / plain_s, 12.0);
}

}  // namespace
}  // namespace imucal::calib
