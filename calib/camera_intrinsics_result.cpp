// SPDX-License-Identifier: BSD-3-Clause
// What a camera solve's result says beside its camera (calib/camera_intrinsics.hpp): the sigmas
// from its covariance, the image's coverage by the corners, and the warnings about its quality.

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "calib/camera_intrinsics.hpp"
#include "core/text_format.hpp"

namespace imucal::calib {

void set_camera_covariance(const std::optional<Eigen::Matrix<double, 10, 10>>& covariance,
                           CameraIntrinsicsResult* result) {
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  result->covariance_ok = covariance.has_value();
  result->covariance = covariance.value_or(Eigen::Matrix<double, 10, 10>::Zero());
  const Eigen::Matrix<double, 10, 1> sigma =
      covariance ? Eigen::Matrix<double, 10, 1>(result->covariance.diagonal().cwiseMax(0.0).cwiseSqrt())
                 : Eigen::Matrix<double, 10, 1>::Constant(inf);
  result->intrinsics_sigma = sigma.head<4>();
  result->projection_sigma = sigma.segment<2>(4);
  result->distortion_sigma = sigma.tail<4>();
  // The entries the model does not have are no parameters: NaN, never a sigma of 0.
  for (int i = projection_param_count(result->camera.projection); i < 2; ++i)
    result->projection_sigma[i] = nan;
  for (int i = distortion_coeff_count(result->camera.distortion_model); i < 4; ++i)
    result->distortion_sigma[i] = nan;
}

void set_coverage(int width, int height, int cols, std::span<const Eigen::Vector2d> px,
                  CameraIntrinsicsResult* result) {
  result->coverage_cols = cols;
  result->coverage_rows = std::max(1, static_cast<int>(std::lround(cols * double(height) / double(width))));
  result->coverage_counts.assign(static_cast<std::size_t>(result->coverage_cols * result->coverage_rows), 0);
  for (const auto& p : px) {
    const int cx = std::clamp(static_cast<int>((p.x() + 0.5) / width * result->coverage_cols), 0,
                              result->coverage_cols - 1);
    const int cy = std::clamp(static_cast<int>((p.y() + 0.5) / height * result->coverage_rows), 0,
                              result->coverage_rows - 1);
    ++result->coverage_counts[static_cast<std::size_t>(cy * result->coverage_cols + cx)];
  }
  const auto hit = std::count_if(result->coverage_counts.begin(), result->coverage_counts.end(),
                                 [](int c) { return c > 0; });
  result->coverage = static_cast<double>(hit) / static_cast<double>(result->coverage_counts.size());
}

std::vector<std::string> camera_quality_warnings(const CameraIntrinsicsResult& r,
                                                 const CameraIntrinsicsOptions& options) {
  std::vector<std::string> out;
  const auto& k = r.camera.intrinsics;
  const double rel = std::max(r.intrinsics_sigma[0] / k[0], r.intrinsics_sigma[1] / k[1]);
  if (!(r.covariance_ok && rel <= options.max_focal_relative_sigma)) {
    out.push_back(std::string("the focal length is not determined by these views (") +
                  (r.covariance_ok ? "relative sigma " + format_number("%.2g", rel)
                                   : std::string("rank-deficient covariance")) +
                  "): views all facing the camera cannot tell the focal length from the distance; record the "
                  "target tilted by 30-45 degrees in several directions and at several distances");
  }
  if (r.coverage < 0.5) {
    out.push_back("the corners cover only " + format_number("%.0f", 100.0 * r.coverage) +
                  " % of the image (" + std::to_string(r.coverage_cols) + " x " +
                  std::to_string(r.coverage_rows) +
                  " cells): the distortion is extrapolated elsewhere; show the target near the "
                  "edges and corners of the image too");
  }
  // The outer ring of cells: a wide lens's distortion is largest there, and the share of the
  // whole grid can look fine with the target never near the edges.
  const int cols = r.coverage_cols, rows = r.coverage_rows;
  if (cols >= 3 && rows >= 3 && r.coverage_counts.size() == static_cast<std::size_t>(cols) * rows) {
    int ring = 0, reached = 0;
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) {
        if (y != 0 && y != rows - 1 && x != 0 && x != cols - 1) continue;
        ++ring;
        if (r.coverage_counts[static_cast<std::size_t>(y) * cols + x] > 0) ++reached;
      }
    if (2 * reached < ring) {
      out.push_back("the corners reached only " + std::to_string(reached) + " of the " +
                    std::to_string(ring) +
                    " cells along the image's edges: the distortion there, the largest with a wide lens, "
                    "is extrapolated; show the target near the edges and into the corners of the image too");
    }
  }
  const int rejected = r.views_total - r.views_used;
  if (rejected * 5 > r.views_total) {
    out.push_back(std::to_string(rejected) + " of " + std::to_string(r.views_total) +
                  " views were rejected (see the views' reasons): check the detections");
  }
  return out;
}

}  // namespace imucal::calib
