// SPDX-License-Identifier: BSD-3-Clause
#include "calib/ray_pnp.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

namespace imucal::calib {

std::optional<RayPose> pose_from_rays(const std::vector<Eigen::Vector3d>& target_points,
                                      const std::vector<Eigen::Vector3d>& rays, bool refine) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& r : rays) sum += r.normalized();
  if (rays.size() < 4 || rays.size() != target_points.size() || !(sum.norm() > 0.0)) return std::nullopt;
  const Eigen::Matrix3d R_turn =
      Eigen::Quaterniond::FromTwoVectors(sum.normalized(), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (std::size_t k = 0; k < rays.size(); ++k) {
    const Eigen::Vector3d r = R_turn * rays[k].normalized();
    if (!(r.z() > 0.05)) continue;
    obj.emplace_back(target_points[k].x(), target_points[k].y(), target_points[k].z());
    img.emplace_back(r.x() / r.z(), r.y() / r.z());
  }
  if (obj.size() < 4) return std::nullopt;
  cv::Mat rvec, tvec;
  const cv::Mat K = cv::Mat::eye(3, 3, CV_64F);
  try {
    if (!cv::solvePnP(obj, img, K, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE)) return std::nullopt;
    if (refine) cv::solvePnPRefineLM(obj, img, K, cv::noArray(), rvec, tvec);
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
  const Eigen::Vector3d r(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2));
  const double angle = r.norm();
  const Eigen::Matrix3d R_turned =
      angle > 0.0 ? Eigen::AngleAxisd(angle, r / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
  RayPose out;
  out.R_cam_target = R_turn.transpose() * R_turned;
  out.t_cam_target =
      R_turn.transpose() * Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  if (!out.R_cam_target.allFinite() || !out.t_cam_target.allFinite()) return std::nullopt;
  return out;
}

}  // namespace imucal::calib
