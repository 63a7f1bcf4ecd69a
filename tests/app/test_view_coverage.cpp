// SPDX-License-Identifier: BSD-3-Clause
// What the live view and the console show of a camera (app/session/view_coverage.hpp): the
// coverage's grid and ROS camera_calibration's four measures, and the shrunk frame with its
// corners moved into the shrunk image's pixels.

#include <gtest/gtest.h>

#include <cmath>

#include "app/session/view_coverage.hpp"

namespace imucal::app::session {
namespace {

TargetDescription board(int cols, int rows) {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = cols;
  t.rows = rows;
  t.col_spacing_m = 0.05;
  t.row_spacing_m = 0.05;
  return t;
}

/// A board's corners seen square on: spacing `s` pixels, its first corner at (x0, y0).
void square_view(const TargetDescription& t, double x0, double y0, double s, std::vector<Eigen::Vector2d>& px,
                 std::vector<int>& ids) {
  px.clear();
  ids.clear();
  for (int r = 0; r < t.rows; ++r)
    for (int c = 0; c < t.cols; ++c) {
      px.emplace_back(x0 + c * s, y0 + r * s);
      ids.push_back(r * t.cols + c);
    }
}

TEST(ViewCoverage, MeasuresAViewAsRosCameraCalibrationDoes) {
  // A square seen square on in the middle of a 640 x 480 image: 100 x 100 pixels.
  double m[4];
  ASSERT_TRUE(view_measures({320, 240}, {270, 190}, {370, 190}, {370, 290}, {270, 290}, 640, 480, m));
  EXPECT_NEAR(m[0], (320 - 50) / (640.0 - 100), 1e-12);
  EXPECT_NEAR(m[1], (240 - 50) / (480.0 - 100), 1e-12);
  EXPECT_NEAR(m[2], std::sqrt(100.0 * 100 / (640.0 * 480)), 1e-12);
  EXPECT_NEAR(m[3], 0.0, 1e-12);
  // Sheared so that the angle at the top right corner is 60 degrees: skew 2 x 30 degrees.
  const double dx = 100.0 / std::tan(M_PI / 3);
  ASSERT_TRUE(
      view_measures({320, 240}, {270, 190}, {370, 190}, {370 - dx, 290}, {270 - dx, 290}, 640, 480, m));
  EXPECT_NEAR(m[3], std::min(1.0, 2 * M_PI / 6), 1e-9);
  // Corners on a line enclose nothing.
  EXPECT_FALSE(view_measures({1, 1}, {0, 0}, {1, 1}, {2, 2}, {3, 3}, 640, 480, m));
}

TEST(ViewCoverage, GrowsWithViewsAcrossTheImage) {
  const TargetDescription t = board(7, 6);
  ViewCoverage cov(640, 480);
  session_msg::CameraCoverage f = cov.figures();
  EXPECT_EQ(f.cols * f.rows, static_cast<int>(f.cells.size()));
  EXPECT_EQ(f.views, 0);
  EXPECT_EQ(f.x, 0.0);
  std::vector<Eigen::Vector2d> px;
  std::vector<int> ids;
  square_view(t, 20, 20, 20, px, ids);  // top left, small
  cov.add(px, ids, t);
  f = cov.figures();
  EXPECT_EQ(f.views, 1);
  EXPECT_EQ(f.x, 0.0) << "one view spans nothing";
  std::int64_t corners = 0;
  for (auto n : f.cells) corners += n;
  EXPECT_EQ(corners, 42);
  EXPECT_GT(f.cells[0], 0) << "the top left cell";
  EXPECT_EQ(f.cells.back(), 0) << "the bottom right cell";

  square_view(t, 420, 300, 30, px, ids);  // bottom right, larger
  cov.add(px, ids, t);
  f = cov.figures();
  EXPECT_EQ(f.views, 2);
  EXPECT_GT(f.cells.back(), 0);
  // x: from 0 (at the left edge) to 1 (at the right edge's limit) over ROS's range 0.7.
  const double x1 =
      std::clamp((20 + 60 - std::sqrt(120.0 * 100) / 2) / (640 - std::sqrt(120.0 * 100)), 0.0, 1.0);
  const double x2 =
      std::clamp((420 + 90 - std::sqrt(180.0 * 150) / 2) / (640 - std::sqrt(180.0 * 150)), 0.0, 1.0);
  EXPECT_NEAR(f.x, std::min(1.0, (x2 - x1) / 0.7), 1e-9);
  EXPECT_GT(f.size, 0.0);
  EXPECT_EQ(f.skew, 0.0) << "both square on";
  // A partial view (no 4 corners) counts in the grid, not in the measures.
  cov.add({{630, 10}}, {0}, t);
  EXPECT_EQ(cov.figures().views, 3);
  EXPECT_NEAR(cov.figures().x, f.x, 1e-12);
}

TEST(ViewCoverage, AFrameIsShrunkByAWholeFactorWithItsCornersMovedAlong) {
  EXPECT_EQ(view_shrink_factor(640, 320), 2);
  EXPECT_EQ(view_shrink_factor(641, 320), 3);
  EXPECT_EQ(view_shrink_factor(320, 320), 1);
  EXPECT_EQ(view_shrink_factor(100, 320), 1);
  std::vector<std::uint8_t> grey(8 * 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x)
      grey[static_cast<std::size_t>(y * 8 + x)] = static_cast<std::uint8_t>(x < 4 ? 10 : 200);
  grey[0] = 30;  // the first 2 x 2 block: 30, 10, 10, 10 -> 15
  const TargetDescription t = board(2, 2);
  ViewFrame v = make_view_frame(grey.data(), 8, 4, 4, {{0, 0}, {7, 0}, {0, 3}, {7, 3}}, {0, 1, 2, 3}, t);
  EXPECT_EQ(v.width, 4);
  EXPECT_EQ(v.height, 2);
  EXPECT_EQ(v.full_width, 8);
  ASSERT_EQ(v.grey.size(), 8u);
  EXPECT_EQ(v.grey[0], 15);
  EXPECT_EQ(v.grey[1], 10);
  EXPECT_EQ(v.grey[2], 200);
  // Pixel centres: full (0, 0) is a quarter pixel up and left of shrunk (0, 0)'s centre.
  ASSERT_EQ(v.corners.size(), 4u);
  EXPECT_DOUBLE_EQ(v.corners[0].x(), -0.25);
  EXPECT_DOUBLE_EQ(v.corners[1].x(), 3.25);
  EXPECT_DOUBLE_EQ(v.corners[3].y(), 1.25);
  EXPECT_TRUE(v.seen);
  EXPECT_EQ(v.board[0], 2);
  EXPECT_EQ(v.board[1], 2);
  // Not every corner: no board to join rows along.
  v = make_view_frame(grey.data(), 8, 4, 4, {{0, 0}, {7, 0}}, {0, 1}, t);
  EXPECT_EQ(v.board[0], 0);
  v = make_view_frame(grey.data(), 8, 4, 4, {}, {}, t);
  EXPECT_FALSE(v.seen);
}

}  // namespace
}  // namespace imucal::app::session
