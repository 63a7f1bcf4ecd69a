// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A camera's parameter blocks in a Ceres problem, shared by the single-camera and the chain
// solves: intrinsics fu fv pu pv (4), the projection's parameters (2: omni xi; eucm alpha beta;
// ds xi alpha) and the distortion coefficients (4). A model uses the first
// projection_param_count and distortion_coeff_count entries; the others are held at 0 (a block
// the model does not use at all is constant, one it uses in part has a SubsetManifold).

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <array>
#include <functional>

#include "core/camera_model.hpp"

namespace imucal::calib {

/// The number of camera parameters a model estimates (4 + its projection's + its distortion's).
int free_camera_params(CameraModelKind model);

/// Holds the entries of the projection and distortion blocks that `model` does not use. The
/// blocks must be in `problem`, which must not own manifolds (the ones set here are shared).
void hold_unused_camera_entries(ceres::Problem* problem, CameraModelKind model, double* projection2,
                                double* distortion4);

/// A covariance block of two parameter blocks in their tangent spaces (rows x cols), NaN where
/// not determined.
using CovarianceBlockFn = std::function<Eigen::MatrixXd(const double*, const double*, int, int)>;

/// The 10 x 10 covariance of [intrinsics, projection, distortion] from the tangent-space blocks
/// of `block`, with 0 in the rows and columns of the entries the model does not use.
Eigen::Matrix<double, 10, 10> camera_covariance(CameraModelKind model,
                                                const std::array<const double*, 3>& blocks,
                                                const CovarianceBlockFn& block);

}  // namespace imucal::calib
