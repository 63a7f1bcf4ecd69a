// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The checkerboard's inner corners as a grid of X junctions: the first, cheap search of the
// checkerboard detector (target_detection.cpp), which also tells it when the slower searches
// need not run. Internal to imucal_calib_targets; docs/targets.md has the method and figures.
//
// The junctions are the saddle points of the lightly smoothed image (Hessian determinant
// negative), kept where their strength is that of a corner of at least kMinContrast grey
// levels. A grid starts from a 3 x 3 patch of junctions (neighbours along rows and columns with
// the saddle's axes turned by a quarter, diagonal ones with them alike, every one X-shaped:
// its four squares alike across each diagonal) and grows a row or column at a time by
// extrapolating its rows and columns, as long as every extrapolated point meets such a
// junction. A search that stops short is repeated at half resolution. Costs 2-6 ms on a
// 752 x 480 frame, board or not.

#include <opencv2/core.hpp>
#include <vector>

namespace imucal::calib {

struct CheckerboardGrid {
  enum class Outcome {
    kFound,      // a grid of exactly the board's corners: `corners`
    kNone,       // no 3 x 3 patch of junctions anywhere: nothing a search could take for a board
    kCut,        // only grids smaller than the board that run into the image's border
    kOther,      // a whole board of another size (its every side ends inside the image)
    kUndecided,  // a grid that stopped inside the image short of the board, or outgrew it
  };
  Outcome outcome = Outcome::kNone;
  /// kFound: cols * rows corners, row-major (rows of `cols`), from any corner of the board in
  /// either sense (the caller orders them); the junctions' positions to about 0.3 px.
  /// kUndecided: the largest undecided grid's grid_cols * grid_rows junctions, row-major.
  std::vector<cv::Point2f> corners;
  /// kOther: the inner corners of the whole board seen (grid_cols along the image's grid rows,
  /// which are the board's rows or its columns); kUndecided: the largest undecided grid's;
  /// kFound: the board's.
  int grid_cols = 0;
  int grid_rows = 0;
};

/// Searches an 8-bit grey image for the grid of a board of `cols` x `rows` inner corners.
[[nodiscard]] CheckerboardGrid find_checkerboard_grid(const cv::Mat& gray, int cols, int rows);

/// Where OpenCV's quad search looks for the board after an undecided grid: only where the
/// board can be, the box around the grid's junctions grown on every side by the rows and
/// columns of the board the grid lacks plus two squares (its outer squares and the margin
/// around them), at the grid's longest step, clipped to the image. The whole image for any
/// other outcome.
[[nodiscard]] cv::Rect fallback_region(const CheckerboardGrid& grid, int cols, int rows, cv::Size image);

}  // namespace imucal::calib
