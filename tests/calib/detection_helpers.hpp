// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Helpers the target detection tests share (test_target_detection.cpp, checkerboards;
// test_aprilgrid_detection.cpp, AprilGrids): in a named namespace, so that unity builds of the
// test files do not meet two definitions.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "calib/target_detection.hpp"

namespace imucal::calib::detection_test {

inline GrayView view_of(const cv::Mat& image) {
  return GrayView{image.data, image.cols, image.rows, image.step[0]};
}

inline std::unique_ptr<TargetDetector> make_detector(const TargetDescription& t,
                                                     const DetectionOptions& opt = {}) {
  auto d = TargetDetector::create(t, opt);
  EXPECT_TRUE(d.ok()) << d.error().message;
  return d.ok() ? std::move(*d) : nullptr;
}

struct Errors {
  double mean_px = 0.0;
  double max_px = 0.0;
};

/// Distances between detected points and the truth of the same id.
inline Errors errors(const TargetObservation& obs, const std::vector<Eigen::Vector2d>& truth) {
  Errors e;
  for (std::size_t i = 0; i < obs.ids.size(); ++i) {
    const double d = (obs.px[i] - truth[static_cast<std::size_t>(obs.ids[i])]).norm();
    e.mean_px += d;
    e.max_px = std::max(e.max_px, d);
  }
  if (!obs.ids.empty()) e.mean_px /= static_cast<double>(obs.ids.size());
  return e;
}

}  // namespace imucal::calib::detection_test
