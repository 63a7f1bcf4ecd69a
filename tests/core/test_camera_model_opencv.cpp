// SPDX-License-Identifier: BSD-3-Clause
// The camera models against OpenCV's implementations of the same models, and their use with
// Ceres Jets.

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <random>
#include <vector>

#include "core/camera_model.hpp"
#include "tests/support/test_helpers.hpp"

namespace imucal {
namespace {

std::vector<cv::Point3d> random_points(int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> lateral(-0.9, 0.9);
  std::uniform_real_distribution<double> depth(0.3, 4.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < n; ++i) {
    const double z = depth(rng);
    points.emplace_back(lateral(rng) * z, lateral(rng) * z * 0.7, z);
  }
  return points;
}

cv::Matx33d camera_matrix(const CameraModel& c) {
  return cv::Matx33d(c.intrinsics[0], 0, c.intrinsics[2], 0, c.intrinsics[1], c.intrinsics[3], 0, 0, 1);
}

TEST(CameraModelOpenCv, RadtanMatchesProjectPoints) {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics << 458.654, 457.296, 367.215, 248.375;
  c.distortion_coeffs << -0.28340811, 0.07395907, 0.00019359, 1.76187114e-05;
  c.width = 752;
  c.height = 480;
  const auto points = random_points(3000, 1);
  std::vector<cv::Point2d> cv_px;
  const cv::Vec4d dist(c.distortion_coeffs[0], c.distortion_coeffs[1], c.distortion_coeffs[2],
                       c.distortion_coeffs[3]);
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera_matrix(c), dist, cv_px);
  double max_err = 0.0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto p = c.project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z));
    max_err = std::max(max_err, std::hypot(p.px.x() - cv_px[i].x, p.px.y() - cv_px[i].y));
  }
  EXPECT_LT(max_err, 1e-9);
}

TEST(CameraModelOpenCv, EquidistantMatchesFisheyeProjectPoints) {
  CameraModel c;
  c.distortion_model = DistortionModel::kEquidistant;
  c.intrinsics << 190.978, 190.973, 254.932, 256.897;
  c.distortion_coeffs << 0.0034823, 0.000715, -0.0020532, 0.000202935;
  c.width = 512;
  c.height = 512;
  auto points = random_points(3000, 2);
  points.emplace_back(0.0, 0.0, 1.0);    // on the axis (the r -> 0 branch)
  points.emplace_back(1e-10, 0.0, 1.0);  // just off it
  std::vector<cv::Point2d> cv_px;
  const cv::Vec4d dist(c.distortion_coeffs[0], c.distortion_coeffs[1], c.distortion_coeffs[2],
                       c.distortion_coeffs[3]);
  cv::fisheye::projectPoints(points, cv_px, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera_matrix(c), dist);
  double max_err = 0.0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto p = c.project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z));
    max_err = std::max(max_err, std::hypot(p.px.x() - cv_px[i].x, p.px.y() - cv_px[i].y));
  }
  EXPECT_LT(max_err, 1e-9);
}

TEST(CameraModelOpenCv, RadtanUnprojectMatchesUndistortPoints) {
  const CameraModel c = test::radtan_camera();
  std::vector<cv::Point2d> px;
  for (int v = 0; v < c.height; v += 17) {
    for (int u = 0; u < c.width; u += 13) px.emplace_back(u, v);
  }
  std::vector<cv::Point2d> undistorted;
  // OpenCV iterates a fixed number of times; ask for many so it converges as far as it can.
  cv::undistortPoints(px, undistorted, camera_matrix(c),
                      cv::Vec4d(c.distortion_coeffs[0], c.distortion_coeffs[1], c.distortion_coeffs[2],
                                c.distortion_coeffs[3]),
                      cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 200, 1e-15));
  for (std::size_t i = 0; i < px.size(); ++i) {
    Eigen::Vector3d ray;
    ASSERT_TRUE(c.unproject(Eigen::Vector2d(px[i].x, px[i].y), &ray));
    EXPECT_NEAR(ray.x() / ray.z(), undistorted[i].x, 1e-7);
    EXPECT_NEAR(ray.y() / ray.z(), undistorted[i].y, 1e-7);
  }
}

// The templated model evaluates on Jets: derivatives with respect to the point and the
// intrinsics agree with central differences.
TEST(CameraModelOpenCv, JetDerivativesMatchNumeric) {
  using Jet = ceres::Jet<double, 11>;  // 3 point coordinates + 4 intrinsics + 4 coefficients
  for (auto model : {DistortionModel::kRadtan, DistortionModel::kEquidistant}) {
    const double intr[4] = {285.0, 286.5, 190.3, 118.6};
    const double dist[4] = {-0.21, 0.045, 4e-4, -2e-4};
    const double point[3] = {0.11, -0.07, 0.9};
    Jet ji[4], jd[4];
    Jet jp[3];
    for (int k = 0; k < 4; ++k) {
      ji[k] = Jet(intr[k], 3 + k);
      jd[k] = Jet(dist[k], 7 + k);
    }
    for (int k = 0; k < 3; ++k) jp[k] = Jet(point[k], k);
    const Jet je[2] = {Jet(0.0), Jet(0.0)};
    const auto cam = CameraModelT<Jet>::from_params({ProjectionModel::kPinhole, model}, ji, je, jd, 376, 240);
    const auto proj = cam.project(Eigen::Matrix<Jet, 3, 1>(jp[0], jp[1], jp[2]));
    ASSERT_TRUE(proj.valid());

    auto eval = [&](int index, double delta) {
      double i2[4], d2[4], p2[3];
      std::copy(intr, intr + 4, i2);
      std::copy(dist, dist + 4, d2);
      std::copy(point, point + 3, p2);
      if (index < 3)
        p2[index] += delta;
      else if (index < 7)
        i2[index - 3] += delta;
      else
        d2[index - 7] += delta;
      const double e2[2] = {0.0, 0.0};
      const auto c = CameraModel::from_params({ProjectionModel::kPinhole, model}, i2, e2, d2, 376, 240);
      return c.project(Eigen::Vector3d(p2[0], p2[1], p2[2])).px;
    };
    for (int k = 0; k < 11; ++k) {
      const double h = 1e-6;
      const Eigen::Vector2d numeric = (eval(k, h) - eval(k, -h)) / (2 * h);
      EXPECT_NEAR(proj.px.x().v[k], numeric.x(), 1e-5 * std::max(1.0, std::abs(numeric.x())))
          << distortion_model_name(model) << " parameter " << k;
      EXPECT_NEAR(proj.px.y().v[k], numeric.y(), 1e-5 * std::max(1.0, std::abs(numeric.y())))
          << distortion_model_name(model) << " parameter " << k;
    }
  }
}

}  // namespace
}  // namespace imucal
