// SPDX-License-Identifier: BSD-3-Clause
#include "calib/camera_blocks.hpp"

#include <vector>

namespace imucal::calib {
namespace {

/// The manifold that keeps the first `used` of `size` entries free (1 <= used < size).
const ceres::SubsetManifold* held_tail(int used, int size) {
  static const ceres::SubsetManifold projection_1of2(2, {1});
  static const ceres::SubsetManifold distortion_1of4(4, {1, 2, 3});
  if (size == 2 && used == 1) return &projection_1of2;
  if (size == 4 && used == 1) return &distortion_1of4;
  return nullptr;
}

void hold(ceres::Problem* problem, double* block, int used, int size) {
  if (!problem->HasParameterBlock(block)) return;
  if (used == 0) {
    problem->SetParameterBlockConstant(block);
  } else if (used < size) {
    // Ceres takes a non-const manifold but only calls its const methods.
    problem->SetManifold(block, const_cast<ceres::SubsetManifold*>(held_tail(used, size)));
  }
}

}  // namespace

int free_camera_params(CameraModelKind model) {
  return 4 + projection_param_count(model.projection) + distortion_coeff_count(model.distortion);
}

void hold_unused_camera_entries(ceres::Problem* problem, CameraModelKind model, double* projection2,
                                double* distortion4) {
  hold(problem, projection2, projection_param_count(model.projection), 2);
  hold(problem, distortion4, distortion_coeff_count(model.distortion), 4);
}

Eigen::Matrix<double, 10, 10> camera_covariance(CameraModelKind model,
                                                const std::array<const double*, 3>& blocks,
                                                const CovarianceBlockFn& block) {
  const std::array<int, 3> used = {4, projection_param_count(model.projection),
                                   distortion_coeff_count(model.distortion)};
  const std::array<int, 3> offset = {0, 4, 6};
  Eigen::Matrix<double, 10, 10> out = Eigen::Matrix<double, 10, 10>::Zero();
  for (std::size_t a = 0; a < 3; ++a) {
    for (std::size_t b = 0; b < 3; ++b) {
      if (used[a] == 0 || used[b] == 0) continue;
      out.block(offset[a], offset[b], used[a], used[b]) = block(blocks[a], blocks[b], used[a], used[b]);
    }
  }
  return out;
}

}  // namespace imucal::calib
