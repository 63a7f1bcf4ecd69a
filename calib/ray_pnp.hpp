// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The pose of a planar target from the rays of its corners, for any camera model: the rays are
// turned so that their mean is the optical axis, solved there as a pinhole view (IPPE, exact for
// planar targets) and turned back, so that a view far off the axis (beyond 90 degrees at a
// fisheye's border) is solved as well as a central one.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <vector>

namespace imucal::calib {

struct RayPose {
  Eigen::Matrix3d R_cam_target = Eigen::Matrix3d::Identity();  // p_cam = R p_target + t
  Eigen::Vector3d t_cam_target = Eigen::Vector3d::Zero();
};

/// The pose from target points and their unit rays (same order); `refine`: Levenberg-Marquardt
/// on the turned view after IPPE. nullopt with fewer than 4 rays within 87 degrees of their mean
/// direction or when OpenCV fails.
std::optional<RayPose> pose_from_rays(const std::vector<Eigen::Vector3d>& target_points,
                                      const std::vector<Eigen::Vector3d>& rays, bool refine);

}  // namespace imucal::calib
