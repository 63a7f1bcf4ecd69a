// SPDX-License-Identifier: BSD-3-Clause
#include "app/session/view_coverage.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "log/frame_codec.hpp"

namespace imucal::app::session {

namespace {

double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

/// The angle at b between a and c.
double angle_at(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  const Eigen::Vector2d ab = a - b, cb = c - b;
  const double n = ab.norm() * cb.norm();
  if (n <= 0.0) return M_PI / 2.0;
  return std::acos(std::clamp(ab.dot(cb) / n, -1.0, 1.0));
}

}  // namespace

bool view_measures(const Eigen::Vector2d& mean, const Eigen::Vector2d& up_left,
                   const Eigen::Vector2d& up_right, const Eigen::Vector2d& down_right,
                   const Eigen::Vector2d& down_left, int width, int height, double out[4]) {
  // ROS calibrator.py _calculate_area: half the cross product of the diagonals' halves' sums.
  const Eigen::Vector2d a = up_right - up_left, b = down_right - up_right, c = down_left - down_right;
  const double area = std::abs(cross2(b + c, a + b)) / 2.0;
  if (!(area > 0.0) || width <= 0 || height <= 0) return false;
  const double border = std::sqrt(area);
  const auto along = [border](double m, int extent) {
    const double span = extent - border;
    if (span <= 0.0) return 0.5;  // the target fills the image this way: in the middle
    return std::clamp((m - border / 2.0) / span, 0.0, 1.0);
  };
  out[0] = along(mean.x(), width);
  out[1] = along(mean.y(), height);
  out[2] = std::sqrt(area / (static_cast<double>(width) * height));
  out[3] = std::min(1.0, 2.0 * std::abs(M_PI / 2.0 - angle_at(up_left, up_right, down_right)));
  return true;
}

void ViewCoverage::add(const std::vector<Eigen::Vector2d>& px, const std::vector<int>& ids,
                       const TargetDescription& target) {
  if (px.empty() || width_ <= 0 || height_ <= 0) return;
  ++views_;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : px) {
    mean += p;
    const int c = std::clamp(static_cast<int>(p.x() * kCols / width_), 0, kCols - 1);
    const int r = std::clamp(static_cast<int>(p.y() * kRows / height_), 0, kRows - 1);
    ++cells_[static_cast<std::size_t>(r * kCols + c)];
  }
  mean /= static_cast<double>(px.size());
  if (px.size() < 4 || ids.size() != px.size()) return;
  // The outer corners: the observed ones at the extremes of the target's own plane.
  const std::vector<Eigen::Vector3d> plane = target.points();
  std::size_t ul = 0, ur = 0, dr = 0, dl = 0;
  double best[4] = {1e300, -1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (ids[i] < 0 || static_cast<std::size_t>(ids[i]) >= plane.size()) return;
    const double x = plane[static_cast<std::size_t>(ids[i])].x(),
                 y = plane[static_cast<std::size_t>(ids[i])].y();
    if (x + y < best[0]) best[0] = x + y, ul = i;
    if (x - y > best[1]) best[1] = x - y, ur = i;
    if (x + y > best[2]) best[2] = x + y, dr = i;
    if (y - x > best[3]) best[3] = y - x, dl = i;
  }
  double m[4];
  if (!view_measures(mean, px[ul], px[ur], px[dr], px[dl], width_, height_, m)) return;
  for (int k = 0; k < 4; ++k) {
    lo_[k] = measured_ ? std::min(lo_[k], m[k]) : m[k];
    hi_[k] = measured_ ? std::max(hi_[k], m[k]) : m[k];
  }
  measured_ = true;
}

session_msg::CameraCoverage ViewCoverage::figures() const {
  session_msg::CameraCoverage c;
  c.cols = kCols;
  c.rows = kRows;
  c.cells = cells_;
  if (c.cells.empty()) c.cells.assign(kCols * kRows, 0);
  c.views = views_;
  double bar[4] = {0, 0, 0, 0};
  if (measured_)
    for (int k = 0; k < 4; ++k) bar[k] = std::min(1.0, (hi_[k] - lo_[k]) / kRanges[k]);
  c.x = bar[0];
  c.y = bar[1];
  c.size = bar[2];
  c.skew = bar[3];
  return c;
}

int view_shrink_factor(int width, int max_width) {
  if (width <= 0 || max_width <= 0) return 1;
  return std::max(1, (width + max_width - 1) / max_width);
}

ViewFrame make_view_frame(const std::uint8_t* grey, int width, int height, int max_width,
                          const std::vector<Eigen::Vector2d>& px, const std::vector<int>& ids,
                          const TargetDescription& target) {
  ViewFrame v;
  const int f = view_shrink_factor(width, max_width);
  v.full_width = width;
  v.full_height = height;
  v.width = width / f;
  v.height = height / f;
  v.grey.resize(static_cast<std::size_t>(v.width) * static_cast<std::size_t>(v.height));
  const int n = f * f;
  for (int y = 0; y < v.height; ++y) {
    for (int x = 0; x < v.width; ++x) {
      int sum = 0;
      for (int dy = 0; dy < f; ++dy) {
        const std::uint8_t* row =
            grey + static_cast<std::size_t>(y * f + dy) * static_cast<std::size_t>(width);
        for (int dx = 0; dx < f; ++dx) sum += row[x * f + dx];
      }
      v.grey[static_cast<std::size_t>(y) * static_cast<std::size_t>(v.width) + static_cast<std::size_t>(x)] =
          static_cast<std::uint8_t>((sum + n / 2) / n);
    }
  }
  // A pixel's centre is at an integer: full pixel centre x maps to (x + 0.5) / f - 0.5.
  v.corners.reserve(px.size());
  for (const Eigen::Vector2d& p : px)
    v.corners.emplace_back((p.x() + 0.5) / f - 0.5, (p.y() + 0.5) / f - 0.5);
  v.seen = !px.empty();
  if (target.type == TargetDescription::Type::kCheckerboard && ids.size() == px.size() &&
      static_cast<int>(ids.size()) == target.cols * target.rows)
    v.board = {target.cols, target.rows};
  return v;
}

Result<std::vector<std::uint8_t>> view_frame_png(const ViewFrame& frame) {
  log::Image image;
  image.width = frame.width;
  image.height = frame.height;
  image.data = frame.grey;
  return log::encode_png(image);
}

}  // namespace imucal::app::session
