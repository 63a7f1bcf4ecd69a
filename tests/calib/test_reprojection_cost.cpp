// SPDX-License-Identifier: BSD-3-Clause
// The single-camera solve's residual with staged Jacobians (calib/reprojection_cost.hpp) against
// automatic differentiation of the same residual over all 17 parameters, for every camera model
// imucal calibrates.

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <array>
#include <random>
#include <string>

#include "calib/reprojection_cost.hpp"

namespace imucal::calib {
namespace {

struct Params {
  std::array<double, 4> intr{412.0, 405.0, 321.5, 238.25};
  std::array<double, 2> proj{0.0, 0.0};
  std::array<double, 4> dist{0.0, 0.0, 0.0, 0.0};
  std::array<double, 7> pose{1, 0, 0, 0, 0, 0, 0};
};

Params params_for(CameraModelKind kind) {
  Params p;
  switch (kind.projection) {
    case ProjectionModel::kPinhole:
      break;
    case ProjectionModel::kOmni:
      p.proj = {0.83, 0.0};
      break;
    case ProjectionModel::kEucm:
      p.proj = {0.61, 1.07};
      break;
    case ProjectionModel::kDs:
      p.proj = {-0.21, 0.58};
      break;
  }
  switch (kind.distortion) {
    case DistortionModel::kRadtan:
      p.dist = {-0.28, 0.071, 0.0012, -0.0007};
      break;
    case DistortionModel::kEquidistant:
      p.dist = {-0.039, -0.012, 0.0049, -0.0006};
      break;
    case DistortionModel::kFov:
      p.dist = {0.93, 0.0, 0.0, 0.0};
      break;
    case DistortionModel::kNone:
      break;
  }
  return p;
}

/// Evaluates `cost` at `p`: the residual and the four row-major Jacobians (2 x 4, 2 x 2, 2 x 4, 2 x 7).
bool evaluate(const ceres::CostFunction& cost, Params& p, Eigen::Vector2d* r,
              std::array<std::vector<double>, 4>* J) {
  const double* blocks[4] = {p.intr.data(), p.proj.data(), p.dist.data(), p.pose.data()};
  const std::array<int, 4> sizes{4, 2, 4, 7};
  std::array<double*, 4> jac{};
  for (int b = 0; b < 4; ++b) {
    (*J)[b].assign(static_cast<std::size_t>(2 * sizes[b]), 0.0);
    jac[b] = (*J)[b].data();
  }
  return cost.Evaluate(blocks, r->data(), jac.data());
}

TEST(ReprojectionCost, StagedJacobiansEqualAutomaticDifferentiationForEveryModel) {
  const char* models[] = {"pinhole-radtan", "pinhole-equi", "pinhole-fov", "pinhole-none",
                          "omni-none",      "omni-radtan",  "eucm-none",   "ds-none"};
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_real_distribution<double> spread(-0.35, 0.35);
  for (const char* name : models) {
    SCOPED_TRACE(name);
    const auto kind = parse_camera_model_name(name);
    ASSERT_TRUE(kind.has_value());
    for (int trial = 0; trial < 20; ++trial) {
      SCOPED_TRACE(trial);
      Params p = params_for(*kind);
      // A quaternion that is not of unit norm: both costs normalise it, as Ceres' rotation does.
      const double scale = 0.7 + 0.1 * trial;
      Eigen::Vector4d q(n(rng), n(rng), n(rng), n(rng));
      q = scale * q.normalized();
      const Eigen::Vector3d P(spread(rng), spread(rng), 0.0);
      // The point lands in front of the camera, 0.3-1.2 m away, up to about 40 degrees off axis.
      Eigen::Quaterniond rot(q(0), q(1), q(2), q(3));
      rot.normalize();
      const Eigen::Vector3d in_cam(0.4 * spread(rng), 0.4 * spread(rng), 0.3 + 0.05 * trial);
      const Eigen::Vector3d t = in_cam - rot * P;
      p.pose = {q(0), q(1), q(2), q(3), t.x(), t.y(), t.z()};
      const Eigen::Vector2d px(300.0 + 10.0 * n(rng), 250.0 + 10.0 * n(rng));

      ReprojectionCost staged(P, px, *kind);
      ceres::AutoDiffCostFunction<ReprojectionFunctor, 2, 4, 2, 4, 7> reference(
          new ReprojectionFunctor(P, px, *kind));
      Eigen::Vector2d r_staged, r_reference;
      std::array<std::vector<double>, 4> J_staged, J_reference;
      ASSERT_TRUE(evaluate(staged, p, &r_staged, &J_staged));
      ASSERT_TRUE(evaluate(reference, p, &r_reference, &J_reference));
      EXPECT_NEAR((r_staged - r_reference).norm(), 0.0, 1e-9);
      for (int b = 0; b < 4; ++b) {
        for (std::size_t i = 0; i < J_staged[b].size(); ++i) {
          const double want = J_reference[b][i];
          EXPECT_NEAR(J_staged[b][i], want, 1e-9 * (1.0 + std::abs(want))) << "block " << b << " entry " << i;
        }
      }
      // Without Jacobians the residual is the same.
      const double* blocks[4] = {p.intr.data(), p.proj.data(), p.dist.data(), p.pose.data()};
      Eigen::Vector2d r_plain;
      ASSERT_TRUE(staged.Evaluate(blocks, r_plain.data(), nullptr));
      EXPECT_NEAR((r_plain - r_reference).norm(), 0.0, 1e-9);
    }
  }
}

TEST(ReprojectionCost, APointBehindAPinholeCameraRefusesTheStepAsTheReferenceDoes) {
  const auto kind = parse_camera_model_name("pinhole-radtan");
  ASSERT_TRUE(kind.has_value());
  Params p = params_for(*kind);
  p.pose = {1, 0, 0, 0, 0.0, 0.0, -1.0};  // the target point at z = -1 in the camera
  const Eigen::Vector3d P(0.1, 0.05, 0.0);
  ReprojectionCost staged(P, Eigen::Vector2d(320, 240), *kind);
  ceres::AutoDiffCostFunction<ReprojectionFunctor, 2, 4, 2, 4, 7> reference(
      new ReprojectionFunctor(P, Eigen::Vector2d(320, 240), *kind));
  Eigen::Vector2d r;
  std::array<std::vector<double>, 4> J;
  EXPECT_FALSE(evaluate(reference, p, &r, &J));
  EXPECT_FALSE(evaluate(staged, p, &r, &J));
  const double* blocks[4] = {p.intr.data(), p.proj.data(), p.dist.data(), p.pose.data()};
  EXPECT_FALSE(staged.Evaluate(blocks, r.data(), nullptr));
}

}  // namespace
}  // namespace imucal::calib
