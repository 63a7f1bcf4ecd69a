// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the live view and the console show of a camera during the motion step (docs/service.md,
// "Live view"): where in its image the target has been seen so far, and the frame itself, shrunk.
//
// The coverage's four measures are those of ROS's camera_calibration (calibrator.py,
// get_parameters and compute_goodenough), so that an operator who knows that tool reads them
// the same way: per view, the target's mean position across and down the image (x, y, with the
// target's own size taken off the span it can move in), its size (the square root of the
// quadrilateral of its outer corners over the image's area) and its skew (twice the departure
// from a right angle at the top right corner, at most 1); each bar is the span of that measure
// over the views so far over ROS's range for it (0.7, 0.7, 0.4, 0.5), at most 1.
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/result.hpp"
#include "core/session_messages.hpp"
#include "core/target.hpp"
#include "core/view_frame.hpp"

namespace imucal::app::session {

class ViewCoverage {
 public:
  static constexpr int kCols = 8;
  static constexpr int kRows = 6;
  /// ROS camera_calibration's ranges for x, y, size and skew.
  static constexpr double kRanges[4] = {0.7, 0.7, 0.4, 0.5};

  ViewCoverage() = default;
  ViewCoverage(int width, int height) : width_(width), height_(height), cells_(kCols * kRows, 0) {}

  /// A view's corners, in the full image's pixels, and their ids (TargetDescription::points()).
  /// A view of fewer than 4 corners, or whose outer corners enclose no area, counts in the
  /// grid but not in the measures.
  void add(const std::vector<Eigen::Vector2d>& px, const std::vector<int>& ids,
           const TargetDescription& target);
  session_msg::CameraCoverage figures() const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  int width_ = 0, height_ = 0;
  std::vector<std::int64_t> cells_;
  std::int64_t views_ = 0;
  bool measured_ = false;
  double lo_[4] = {0, 0, 0, 0}, hi_[4] = {0, 0, 0, 0};
};

/// The view's four measures (x, y, size, skew) of one view whose outer corners, in the image's
/// pixels, are `up_left`, `up_right`, `down_right`, `down_left`; false when they enclose no area.
bool view_measures(const Eigen::Vector2d& mean, const Eigen::Vector2d& up_left,
                   const Eigen::Vector2d& up_right, const Eigen::Vector2d& down_right,
                   const Eigen::Vector2d& down_left, int width, int height, double out[4]);

/// The whole factor by which a frame of `width` columns is shrunk to at most `max_width`.
int view_shrink_factor(int width, int max_width);

/// A frame for the live view: the grey image shrunk by view_shrink_factor (the mean of each
/// factor x factor block), the corners moved into the shrunk image's pixels, `board` set when
/// every corner of a checkerboard was found.
ViewFrame make_view_frame(const std::uint8_t* grey, int width, int height, int max_width,
                          const std::vector<Eigen::Vector2d>& px, const std::vector<int>& ids,
                          const TargetDescription& target);

/// The frame's shrunk image as a grey PNG, for the page.
[[nodiscard]] Result<std::vector<std::uint8_t>> view_frame_png(const ViewFrame& frame);

}  // namespace imucal::app::session
