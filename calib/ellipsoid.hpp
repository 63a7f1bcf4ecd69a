// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Closed-form ellipsoid fit of static accelerometer means, the initial guess of the Tedaldi
// accelerometer model when no nominal conversion is known.

#include <Eigen/Core>
#include <span>

#include "core/imu_model.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// Fits x^T Q x + 2 l^T x + c = 0 to the points by linear least squares (points centred and
/// scaled first), then writes the result in Tedaldi's form: |T K (x + b)| = gravity with T unit
/// upper triangular (from the Cholesky factor of the normalised Q). Needs at least 9 points
/// spread over the sphere; fails when the quadric is not an ellipsoid.
[[nodiscard]] Result<TedaldiTriad> fit_ellipsoid(std::span<const Eigen::Vector3d> points, double gravity);

}  // namespace imucal::calib
