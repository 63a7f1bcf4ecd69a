// SPDX-License-Identifier: BSD-3-Clause
#include "calib/target_detection.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <utility>

#include "calib/checkerboard_grid.hpp"

namespace imucal::calib {
namespace {

// The caller's pixels as a cv::Mat header (no copy). OpenCV's detectors only read them.
cv::Mat as_mat(const GrayView& image) {
  const std::size_t stride = image.stride == 0 ? static_cast<std::size_t>(image.width) : image.stride;
  return cv::Mat(image.height, image.width, CV_8UC1, const_cast<std::uint8_t*>(image.data), stride);
}

Status check_image(const GrayView& image) {
  if (image.data == nullptr || image.width <= 0 || image.height <= 0) {
    return make_error(Errc::kInvalidArgument, "target detection: empty image (no pixels or a zero size)");
  }
  if (image.stride != 0 && image.stride < static_cast<std::size_t>(image.width)) {
    return make_error(Errc::kInvalidArgument,
                      "target detection: image stride " + std::to_string(image.stride) +
                          " is smaller than its width " + std::to_string(image.width));
  }
  return {};
}

TargetObservation empty_observation(const GrayView& image) {
  TargetObservation obs;
  obs.width = image.width;
  obs.height = image.height;
  return obs;
}

// cornerSubPix's stopping rule for both targets: 0.01 px or 40 iterations (it converges in a
// few on clean corners; the tolerance is well below the detector's own error).
const cv::TermCriteria kSubpixCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 0.01);

// ---------------------------------------------------------------------------------------------
// Checkerboard

/// Mean grey level of a small square around `centre`, or -1 when it is not inside the image.
double mean_around(const cv::Mat& image, const cv::Point2f& centre, int half) {
  const int x0 = static_cast<int>(std::lround(centre.x)) - half;
  const int y0 = static_cast<int>(std::lround(centre.y)) - half;
  const cv::Rect box(x0, y0, 2 * half + 1, 2 * half + 1);
  if ((box & cv::Rect(0, 0, image.cols, image.rows)) != box) return -1.0;
  return cv::mean(image(box))[0];
}

/// OpenCV reports misuse by exceptions; they must not leave the library.
template <class F>
Result<TargetObservation> guarded(F&& f) {
  try {
    return f();
  } catch (const cv::Exception& e) {
    return make_error(Errc::kInternal, std::string("target detection: OpenCV failed: ") + e.what());
  } catch (const std::bad_alloc&) {
    return make_error(Errc::kInternal, "target detection: out of memory");
  }
}

/// The largest second difference along a found board's rows and columns, as a fraction of the
/// side: a corner OpenCV's searches put on the wrong junction, or 3-20 px off, breaks it.
constexpr double kMaxBend = 0.3;
/// The same for a board that the refinement moved by at most kMaxInPlaceMove of its smallest
/// side (its corners were on junctions already): fisheye boards bend by up to 0.44 (the real
/// fisheye frames of docs/benchmarks.md, half of which 0.3 rejected; their refinement moved
/// corners by at most 0.044 of a side). A corner on the wrong junction bends the grid by 1-2.
constexpr double kMaxBendInPlace = 0.6;
constexpr double kMaxInPlaceMove = 0.1;

class CheckerboardDetector final : public TargetDetector {
 public:
  CheckerboardDetector(TargetDescription target, DetectionOptions options)
      : target_(std::move(target)), options_(options) {}

  using TargetDetector::detect;
  Result<TargetObservation> detect(const GrayView& image, const DetectionHistory& history) const override {
    return guarded([&] { return detect_impl(image, history); });
  }
  const TargetDescription& target() const override { return target_; }
  std::string describe_other_target(const GrayView& image) const override;

 private:
  Result<TargetObservation> detect_impl(const GrayView& image, const DetectionHistory& history) const;
  // The board searched for in the whole image (detected order, unmirrored, refined and
  // checked), or nothing.
  std::optional<std::vector<cv::Point2f>> search(const cv::Mat& image) const;
  // Puts OpenCV's mirrored orderings right (see unmirror), refines the corners and checks them.
  bool refine_and_check(const cv::Mat& image, std::vector<cv::Point2f>* corners) const;
  // OpenCV's rows have x -> y turning clockwise in the image (the board's z axis away from the
  // camera), the convention kept here; a mirrored ordering is turned back.
  void unmirror(std::vector<cv::Point2f>* px) const;
  // The corners of the previous frames carried to this one (in id order), or nothing.
  std::optional<std::vector<cv::Point2f>> track(const cv::Mat& image, const DetectionHistory& history) const;
  // Whether corners in detected order look like this board: a smooth grid (second differences
  // along rows and columns at most `max_bend` of a side) whose squares alternate dark and
  // bright.
  bool plausible(const cv::Mat& image, const std::vector<cv::Point2f>& px, double max_bend = kMaxBend) const;
  double max_second_difference(const std::vector<cv::Point2f>& px) const;
  bool squares_alternate(const cv::Mat& image, const std::vector<cv::Point2f>& px) const;
  double smallest_side(const std::vector<cv::Point2f>& px) const;
  // Detected index of target corner (r, c) under candidate ordering `turn` (quarter turns of
  // the index grid; 1 and 3 only for square boards).
  int index(int turn, int r, int c) const;
  // Whether the square diagonally outside target corner 0 is black under ordering `turn`
  // (1 black, 0 white, -1 undecided: out of view or no contrast).
  int outer_square_black(const cv::Mat& image, const std::vector<cv::Point2f>& px, int turn) const;
  // The ordering of the detected corners that matches the target's ids (see the header).
  int resolve_turn(const cv::Mat& image, const std::vector<cv::Point2f>& px) const;
  int subpix_half_window(const std::vector<cv::Point2f>& px) const;

  TargetDescription target_;
  DetectionOptions options_;
};

int CheckerboardDetector::index(int turn, int r, int c) const {
  const int rows = target_.rows;
  const int cols = target_.cols;
  switch (turn) {
    case 0:
      return r * cols + c;
    case 1:  // square boards only: rows == cols
      return c * cols + (cols - 1 - r);
    case 2:
      return (rows - 1 - r) * cols + (cols - 1 - c);
    default:
      return (cols - 1 - c) * cols + r;
  }
}

int CheckerboardDetector::outer_square_black(const cv::Mat& image, const std::vector<cv::Point2f>& px,
                                             int turn) const {
  // Local affine frame at corner 0 from its two neighbours: square (i, j) has its centre at
  // corner 0 + (i + 0.5) dx + (j + 0.5) dy; (-1, -1) is the one in question. The threshold is
  // halfway between two neighbouring inner squares (one black, one white, whatever the
  // ordering).
  auto centre = [&](int t, double i, double j) {
    const cv::Point2f p0 = px[index(t, 0, 0)];
    const cv::Point2f dx = px[index(t, 0, 1)] - p0;
    const cv::Point2f dy = px[index(t, 1, 0)] - p0;
    return p0 + static_cast<float>(i + 0.5) * dx + static_cast<float>(j + 0.5) * dy;
  };
  const cv::Point2f d = px[1] - px[0];
  const int half = std::max(1, static_cast<int>(0.2 * std::hypot(d.x, d.y)));
  const double a = mean_around(image, centre(0, 0, 0), half);
  const double b = mean_around(image, centre(0, 1, 0), half);
  const double outer = mean_around(image, centre(turn, -1, -1), half);
  if (a < 0 || b < 0 || outer < 0 || std::abs(a - b) < 10.0) return -1;
  return outer < 0.5 * (a + b) ? 1 : 0;
}

int CheckerboardDetector::resolve_turn(const cv::Mat& image, const std::vector<cv::Point2f>& px) const {
  // Quarter turns 0..3 for a square board, half turns (0 and 2) otherwise.
  const int turns = 4;
  const int step = target_.rows == target_.cols ? 1 : 2;
  // Orderings the printed pattern allows: the square outside corner 0 is black. An ordering
  // whose outer square is seen black beats one whose outer square is out of view or without
  // contrast (undecided), which beats one whose outer square is seen white: a board cut by the
  // image edge must not turn half round because its corner-0 square fell outside.
  std::array<int, 4> rank{};
  int top = -1;
  for (int turn = 0; turn < turns; turn += step) {
    const int black = outer_square_black(image, px, turn);
    rank[turn] = black == 1 ? 2 : (black < 0 ? 1 : 0);
    top = std::max(top, rank[turn]);
  }
  // Among what the pattern cannot tell apart (boards with 180-degree symmetry), the one whose
  // x axis points most to the right in the image.
  int best = 0;
  double best_right = -2.0;
  for (int turn = 0; turn < turns; turn += step) {
    if (rank[turn] != top) continue;
    const cv::Point2f x_axis = px[index(turn, 0, target_.cols - 1)] - px[index(turn, 0, 0)];
    const double right = x_axis.x / std::max(1e-9, static_cast<double>(std::hypot(x_axis.x, x_axis.y)));
    if (right > best_right) {
      best_right = right;
      best = turn;
    }
  }
  return best;
}

double CheckerboardDetector::smallest_side(const std::vector<cv::Point2f>& px) const {
  double side = 1e9;
  for (int r = 0; r + 1 < target_.rows; ++r) {
    for (int c = 0; c + 1 < target_.cols; ++c) {
      const cv::Point2f p = px[r * target_.cols + c];
      const cv::Point2f a = px[r * target_.cols + c + 1] - p;
      const cv::Point2f b = px[(r + 1) * target_.cols + c] - p;
      side = std::min(
          {side, static_cast<double>(std::hypot(a.x, a.y)), static_cast<double>(std::hypot(b.x, b.y))});
    }
  }
  return side;
}

int CheckerboardDetector::subpix_half_window(const std::vector<cv::Point2f>& px) const {
  // Half the window stays below half the smallest square seen, so that no window reaches a
  // neighbouring corner; capped at 5 (an 11 x 11 window), where the accuracy levels off.
  return std::clamp(static_cast<int>(smallest_side(px) * 0.45), 2, 5);
}

double CheckerboardDetector::max_second_difference(const std::vector<cv::Point2f>& px) const {
  // Along rows and columns, relative to the local side: a corner that slid along an edge or
  // jumped to a neighbour breaks the smoothness of the grid (lens distortion bends it far less:
  // at most 0.14 of a side on strongly distorted frames, docs/targets.md).
  const int cols = target_.cols;
  double worst = 0.0;
  auto second = [&](cv::Point2f a, cv::Point2f p, cv::Point2f b) {
    const double side = 0.5 * (cv::norm(a - p) + cv::norm(b - p));
    worst = std::max(worst, side > 0.0 ? cv::norm(a + b - 2.0f * p) / side : 1e9);
  };
  for (int r = 0; r < target_.rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const cv::Point2f p = px[r * cols + c];
      if (c > 0 && c + 1 < cols) second(px[r * cols + c - 1], p, px[r * cols + c + 1]);
      if (r > 0 && r + 1 < target_.rows) second(px[(r - 1) * cols + c], p, px[(r + 1) * cols + c]);
    }
  }
  return worst;
}

bool CheckerboardDetector::squares_alternate(const cv::Mat& image, const std::vector<cv::Point2f>& px) const {
  // The grey level at the centre of every inner square; side by side squares must differ with
  // the checkerboard's alternating sign, each pair by at least max(10 DN, a tenth of the
  // median difference) (local contrast, so uneven lighting does not matter).
  const int cols = target_.cols;
  const int half = std::max(1, static_cast<int>(0.15 * smallest_side(px)));
  const int sq_cols = cols - 1;
  const int sq_rows = target_.rows - 1;
  std::vector<double> level(static_cast<std::size_t>(sq_cols * sq_rows));
  for (int r = 0; r < sq_rows; ++r) {
    for (int c = 0; c < sq_cols; ++c) {
      const cv::Point2f centre = 0.25f * (px[r * cols + c] + px[r * cols + c + 1] + px[(r + 1) * cols + c] +
                                          px[(r + 1) * cols + c + 1]);
      const double v = mean_around(image, centre, half);
      if (v < 0) return false;
      level[r * sq_cols + c] = v;
    }
  }
  std::vector<double> d;
  for (int r = 0; r < sq_rows; ++r) {
    for (int c = 0; c < sq_cols; ++c) {
      const double sign = (r + c) % 2 == 0 ? 1.0 : -1.0;
      const double a = level[r * sq_cols + c];
      if (c + 1 < sq_cols) d.push_back(sign * (a - level[r * sq_cols + c + 1]));
      if (r + 1 < sq_rows) d.push_back(sign * (a - level[(r + 1) * sq_cols + c]));
    }
  }
  if (d.empty()) return false;
  std::vector<double> magnitude(d.size());
  for (std::size_t k = 0; k < d.size(); ++k) magnitude[k] = std::abs(d[k]);
  std::nth_element(magnitude.begin(), magnitude.begin() + magnitude.size() / 2, magnitude.end());
  const double need = std::max(10.0, 0.1 * magnitude[magnitude.size() / 2]);
  const double sign = d[0] < 0 ? -1.0 : 1.0;
  return std::all_of(d.begin(), d.end(), [&](double v) { return sign * v >= need; });
}

bool CheckerboardDetector::plausible(const cv::Mat& image, const std::vector<cv::Point2f>& px,
                                     double max_bend) const {
  return px.size() == static_cast<std::size_t>(target_.cols * target_.rows) &&
         max_second_difference(px) <= max_bend && squares_alternate(image, px);
}

std::optional<std::vector<cv::Point2f>> CheckerboardDetector::track(const cv::Mat& image,
                                                                    const DetectionHistory& history) const {
  const std::size_t n = static_cast<std::size_t>(target_.cols * target_.rows);
  const TargetObservation* last = history.last;
  if (last == nullptr || last->ids.size() != n || last->width != image.cols || last->height != image.rows) {
    return std::nullopt;
  }
  // Constant velocity from the two frames before, scaled by their spacing when the times are
  // known (at most twice the last step: beyond that the prediction is a guess).
  std::vector<cv::Point2f> predicted(n);
  for (std::size_t k = 0; k < n; ++k) {
    predicted[k] = cv::Point2f(static_cast<float>(last->px[k].x()), static_cast<float>(last->px[k].y()));
  }
  const TargetObservation* before = history.before_last;
  if (before != nullptr && before->ids.size() == n) {
    double scale = 1.0;
    if (history.t_ns > last->t_ns && last->t_ns > before->t_ns) {
      scale = std::min(2.0, static_cast<double>(history.t_ns - last->t_ns) /
                                static_cast<double>(last->t_ns - before->t_ns));
    }
    for (std::size_t k = 0; k < n; ++k) {
      const Eigen::Vector2d p = last->px[k] + scale * (last->px[k] - before->px[k]);
      predicted[k] = cv::Point2f(static_cast<float>(p.x()), static_cast<float>(p.y()));
    }
  }
  // A wide window pulls each predicted corner onto the corner near it, the usual one refines it.
  const double side = smallest_side(predicted);
  const int wide = std::clamp(static_cast<int>(0.45 * side), 3, 12);
  // The ring of squares around the corners must stay in view (a square's side from the edge):
  // with part of it out, a grid slid by whole squares can pass the checks below.
  const double margin = std::max(static_cast<double>(wide + 1), side);
  for (const cv::Point2f& p : predicted) {
    if (p.x < margin || p.y < margin || p.x > image.cols - 1 - margin || p.y > image.rows - 1 - margin) {
      return std::nullopt;  // near or beyond the edge: the board may be leaving the view
    }
  }
  // cornerSubPix puts a corner that wandered further than its window back exactly where it
  // started: a corner left bit for bit where it was is one the refinement did not find (on a
  // small board that moved more than the window, every corner, and the stale grid passes the
  // shape checks below). Such a track is no track; a still board is found again by the search.
  auto refine = [&](std::vector<cv::Point2f>* corners, int window) {
    const std::vector<cv::Point2f> start = *corners;
    cv::cornerSubPix(image, *corners, cv::Size(window, window), cv::Size(-1, -1), kSubpixCriteria);
    for (std::size_t k = 0; k < n; ++k) {
      if ((*corners)[k] == start[k]) return false;
    }
    return true;
  };
  std::vector<cv::Point2f> px = predicted;
  if (!refine(&px, wide)) return std::nullopt;
  if (!refine(&px, subpix_half_window(px))) return std::nullopt;
  // Checks: no corner went far from its prediction or left the image, the grid kept its shape
  // and size, its squares alternate, and the square outside corner 0 is still black (a grid
  // slid by one square fails one of these).
  const double max_move = std::max(2.0, 0.6 * side);
  for (std::size_t k = 0; k < n; ++k) {
    if (cv::norm(px[k] - predicted[k]) > max_move || px[k].x < 0 || px[k].y < 0 || px[k].x > image.cols - 1 ||
        px[k].y > image.rows - 1) {
      return std::nullopt;
    }
  }
  // A tracked grid is held to a smoother shape than a found one (0.15 of a side; lens distortion
  // bends the grid by at most 0.14 on the strongly distorted frames of docs/benchmarks.md): a
  // corner the refinement dragged onto something else is a search, not a track.
  constexpr double kMaxTrackedSecondDifference = 0.15;
  if (smallest_side(px) < 0.5 * side || max_second_difference(px) > kMaxTrackedSecondDifference ||
      !plausible(image, px) || outer_square_black(image, px, 0) == 0) {
    return std::nullopt;
  }
  return px;
}

Result<TargetObservation> CheckerboardDetector::detect_impl(const GrayView& view,
                                                            const DetectionHistory& history) const {
  IMUCAL_TRY(check_image(view));
  TargetObservation obs = empty_observation(view);
  const cv::Mat image = as_mat(view);
  const cv::Size pattern(target_.cols, target_.rows);
  const std::size_t n = static_cast<std::size_t>(target_.cols * target_.rows);
  auto fill = [&](const std::vector<cv::Point2f>& px, int turn) {
    obs.ids.resize(n);
    obs.px.resize(n);
    for (int r = 0; r < target_.rows; ++r) {
      for (int c = 0; c < target_.cols; ++c) {
        const int id = r * target_.cols + c;
        const cv::Point2f& p = px[index(turn, r, c)];
        obs.ids[id] = id;
        obs.px[id] = Eigen::Vector2d(p.x, p.y);
      }
    }
  };
  const bool sector_based = options_.checkerboard_method == CheckerboardMethod::kSectorBased;
  if (!sector_based) {
    // The board of the frames before, carried over: the ids stay those of the first detection.
    if (auto tracked = track(image, history)) {
      fill(*tracked, 0);
      return obs;
    }
  }
  std::vector<cv::Point2f> px;
  if (sector_based) {
    if (!cv::findChessboardCornersSB(image, pattern, px,
                                     cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_ACCURACY) ||
        px.size() != n) {
      return obs;
    }
    unmirror(&px);
  } else {
    std::optional<std::vector<cv::Point2f>> searched = search(image);
    if (!searched) return obs;
    px = std::move(*searched);
  }
  fill(px, resolve_turn(image, px));
  return obs;
}

void CheckerboardDetector::unmirror(std::vector<cv::Point2f>* px) const {
  // OpenCV returns the rows with x -> y turning clockwise in the image (the board's z axis
  // away from the camera), the convention kept here; a mirrored result is turned back.
  const std::size_t n = px->size();
  const cv::Point2f quad[4] = {(*px)[0], (*px)[target_.cols - 1], (*px)[n - 1], (*px)[n - target_.cols]};
  double area = 0.0;
  for (int i = 0; i < 4; ++i) area += quad[i].x * quad[(i + 1) % 4].y - quad[(i + 1) % 4].x * quad[i].y;
  if (area < 0) {
    for (int r = 0; r < target_.rows; ++r) {
      std::reverse(px->begin() + r * target_.cols, px->begin() + (r + 1) * target_.cols);
    }
  }
}

bool CheckerboardDetector::refine_and_check(const cv::Mat& image, std::vector<cv::Point2f>* corners) const {
  if (corners->size() != static_cast<std::size_t>(target_.cols * target_.rows)) return false;
  unmirror(corners);
  const std::vector<cv::Point2f> start = *corners;
  if (options_.subpixel) {
    const int half = subpix_half_window(*corners);
    cv::cornerSubPix(image, *corners, cv::Size(half, half), cv::Size(-1, -1), kSubpixCriteria);
  }
  // Held to kMaxBendInPlace instead of kMaxBend when the refinement moved no corner by more
  // than kMaxInPlaceMove of the smallest side: a fisheye board bends further than OpenCV's
  // wrong results do, and a grid put on the wrong junctions (across the rows of a steeply
  // foreshortened board) is dragged by the refinement by 0.2-0.4 of a side.
  double moved = 0.0;
  for (std::size_t k = 0; k < start.size(); ++k) {
    moved = std::max(moved, static_cast<double>(cv::norm((*corners)[k] - start[k])));
  }
  return plausible(image, *corners,
                   moved <= kMaxInPlaceMove * smallest_side(*corners) ? kMaxBendInPlace : kMaxBend);
}

std::optional<std::vector<cv::Point2f>> CheckerboardDetector::search(const cv::Mat& image) const {
  // Each step only for what the one before missed, every result checked:
  //  1. the grid of X junctions (checkerboard_grid.hpp): a few ms, and it also says when the
  //     step below cannot find the board: no board at all, only part of it in view, or a
  //     whole board of another size;
  //  2. after a grid that stopped short, the quad search on OpenCV's histogram threshold,
  //     without its pre-test (which rejects boards the search finds, and costs more than it
  //     saves), in the region where the rest of the board can be.
  // The quad search's adaptive-threshold passes are not used: on textured, noisy frames they
  // cost up to seconds a frame and found no board the two steps miss; nor is the sector-based
  // search, 150-370 ms on a 1280 x 720 frame, which found no board after the grid's on any
  // frame set measured (docs/targets.md).
  CheckerboardGrid grid = find_checkerboard_grid(image, target_.cols, target_.rows);
  switch (grid.outcome) {
    case CheckerboardGrid::Outcome::kFound:
      // A grid the checks reject is not searched again: the searches below see the same
      // junctions (on the frames of docs/benchmarks.md they never found such a board).
      if (!refine_and_check(image, &grid.corners)) return std::nullopt;
      return std::move(grid.corners);
    case CheckerboardGrid::Outcome::kNone:
    case CheckerboardGrid::Outcome::kCut:
    case CheckerboardGrid::Outcome::kOther:
      return std::nullopt;
    case CheckerboardGrid::Outcome::kUndecided:
      // Only a grid of at least half the board is worth the quad search (a board with a few
      // junctions lost to glare or blur); small grids are where lines cross in clutter.
      if (2 * grid.grid_cols * grid.grid_rows < target_.cols * target_.rows) return std::nullopt;
      break;
  }
  // Only in the region where the rest of the board can be: on the whole of a 1280 x 720
  // image the quad search costs 10-30 ms.
  const cv::Rect region = fallback_region(grid, target_.cols, target_.rows, image.size());
  std::vector<cv::Point2f> px;
  if (!cv::findChessboardCorners(image(region), cv::Size(target_.cols, target_.rows), px, 0))
    return std::nullopt;
  for (cv::Point2f& p : px) p += cv::Point2f(static_cast<float>(region.x), static_cast<float>(region.y));
  if (!refine_and_check(image, &px)) return std::nullopt;
  return px;
}

std::string CheckerboardDetector::describe_other_target(const GrayView& view) const {
  if (!check_image(view).ok()) return {};
  try {
    auto words = [](int cols, int rows) {
      return "a checkerboard of " + std::to_string(std::max(cols, rows)) + " x " +
             std::to_string(std::min(cols, rows)) + " inner corners";
    };
    // A whole board in the junction grid first (a few ms).
    const CheckerboardGrid grid = find_checkerboard_grid(as_mat(view), target_.cols, target_.rows);
    if (grid.outcome == CheckerboardGrid::Outcome::kOther) return words(grid.grid_cols, grid.grid_rows);
    if (grid.outcome == CheckerboardGrid::Outcome::kFound) return {};
    // The sector-based detector with CALIB_CB_LARGER finds a board of any size from the smallest
    // pattern up and says in `meta` how many corners it has (rows x columns).
    std::vector<cv::Point2f> px;
    cv::Mat meta;
    if (!cv::findChessboardCornersSB(as_mat(view), cv::Size(3, 3), px,
                                     cv::CALIB_CB_LARGER | cv::CALIB_CB_NORMALIZE_IMAGE, meta)) {
      return {};
    }
    const int cols = meta.cols;
    const int rows = meta.rows;
    if (cols <= 0 || rows <= 0 || px.size() != static_cast<std::size_t>(cols * rows)) return {};
    // A board cut by the image border shows fewer corners than it has: only a board clear of
    // the border by one and a half squares counts.
    double spacing = 0.0;
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c + 1 < cols; ++c) spacing += cv::norm(px[r * cols + c + 1] - px[r * cols + c]);
    }
    spacing /= std::max(1, rows * (cols - 1));
    for (const cv::Point2f& p : px) {
      const double margin = std::min({static_cast<double>(p.x), static_cast<double>(p.y),
                                      view.width - 1.0 - p.x, view.height - 1.0 - p.y});
      if (margin < 1.5 * spacing) return {};
    }
    if ((cols == target_.cols && rows == target_.rows) || (cols == target_.rows && rows == target_.cols))
      return {};
    return words(cols, rows);
  } catch (const cv::Exception&) {
    return {};
  }
}

// ---------------------------------------------------------------------------------------------
// AprilGrid

// Kalibr's tags have a black border two bits wide (its detector's blackTagBorder = 2, and
// kalibr_create_target_pdf draws borderBits = 2): the black square is 10 bits across, not the
// 8 of libapriltag's tag36h11. The same codes with the bits moved one place inwards and a
// border width of 10 decode them (the quad is still the black square's outline).
constexpr int kKalibrBorderBits = 2;

struct AprilTagDeleter {
  void operator()(apriltag_detector_t* d) const { apriltag_detector_destroy(d); }
  void operator()(apriltag_family_t* f) const { tag36h11_destroy(f); }
};

/// One libapriltag detector with its own family (the family holds the detector's decode
/// table, so it cannot be shared). Not thread-safe: one user at a time.
struct AprilTagContext {
  std::unique_ptr<apriltag_family_t, AprilTagDeleter> family;
  std::unique_ptr<apriltag_detector_t, AprilTagDeleter> detector;
};

/// libapriltag's qtp.min_white_black_diff (see make_apriltag_context).
constexpr int kMinWhiteBlackDiff = 12;

std::unique_ptr<AprilTagContext> make_apriltag_context(double decimate) {
  auto ctx = std::make_unique<AprilTagContext>();
  ctx->family.reset(tag36h11_create());
  apriltag_family_t* f = ctx->family.get();
  const int extra = kKalibrBorderBits - 1;
  f->width_at_border += 2 * extra;
  f->total_width += 2 * extra;
  for (std::uint32_t i = 0; i < f->nbits; ++i) {
    f->bit_x[i] += extra;
    f->bit_y[i] += extra;
  }
  ctx->detector.reset(apriltag_detector_create());
  apriltag_detector_t* d = ctx->detector.get();
  // One thread per detector: callers detect several frames at once instead.
  d->nthreads = 1;
  d->quad_decimate = static_cast<float>(decimate);
  d->quad_sigma = 0.0f;
  d->refine_edges = true;
  d->decode_sharpening = 0.25;
  // libapriltag leaves pixels unthresholded where their tile's brightest and darkest differ
  // by less than kMinWhiteBlackDiff (its default, 5, thresholds every textured or noisy patch:
  // 27-30 ms a 752 x 480 frame of the second generator against 8-9 ms at 12, the same tags).
  // 20 already loses tags of a dim grid whose black and white are 13 grey levels apart.
  d->qtp.min_white_black_diff = kMinWhiteBlackDiff;
  apriltag_detector_add_family_bits(d, f, 2);
  return ctx;
}

/// The grey-level curve applied before libapriltag sees the image: v' = 255 (v / 255)^0.3.
///
/// On Kalibr's grid every tag corner is an X junction with a small black square. The pixels
/// at a junction are partly black from both sides, so libapriltag's thresholded image joins
/// the tag's black square to the corner squares, the tag's outline is no longer a quad, and
/// the tag is lost (on images of known geometry, 29 % of the tags were found over all turns
/// and distances, and almost none near 45 degrees). Brightening the mid-greys moves the
/// threshold towards black: a partly covered pixel turns white and the squares come apart,
/// while edges move by a fraction of a pixel (the corners are refined on the original image
/// afterwards). With 0.3: 90 % of the tags (docs/targets.md).
cv::Mat separation_curve() {
  cv::Mat lut(1, 256, CV_8U);
  for (int i = 0; i < 256; ++i)
    lut.at<std::uint8_t>(i) = cv::saturate_cast<std::uint8_t>(255.0 * std::pow(i / 255.0, 0.3));
  return lut;
}

/// Tags whose median edge in the frame before is at least this are searched for at half
/// resolution first (AprilGridDetector::find_tags).
constexpr double kCoarseTagEdgePx = 28.0;
// The coarse search stands when it decodes at least this share of the frame before's tags.
constexpr double kCoarseKeep = 0.9;
/// With a frame before, only the region around its points is searched (a margin of this many
/// of its median tag edges, plus the motion between the two frames before) when that region is
/// at most kMaxRegionShare of the image; the whole image when it decodes fewer than
/// kCoarseKeep of the tags the frame before had.
constexpr double kRegionMarginTags = 1.5;
/// A tag corner's gaps are brighter than the tag's border and the corner square by at least
/// this many grey levels (printed grids differ by 100-200).
constexpr float kMinTagCornerContrast = 8.0f;
constexpr double kMaxRegionShare = 0.7;

struct TagCorners {
  int id = 0;
  std::array<cv::Point2f, 4> px;  // in the order of TargetDescription::tag_point_ids()
};

class AprilGridDetector final : public TargetDetector {
 public:
  AprilGridDetector(TargetDescription target, DetectionOptions options)
      : target_(std::move(target)),
        options_(options),
        curve_(separation_curve()),
        board_points_(target_.points()) {
    // The four outer corners of the grid's tags, on the board.
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e9);
    Eigen::Vector2d hi = Eigen::Vector2d::Constant(-1e9);
    for (const Eigen::Vector3d& p : board_points_) {
      lo = lo.cwiseMin(p.head<2>());
      hi = hi.cwiseMax(p.head<2>());
    }
    board_outline_ = {cv::Point2f(static_cast<float>(lo.x()), static_cast<float>(lo.y())),
                      cv::Point2f(static_cast<float>(hi.x()), static_cast<float>(lo.y())),
                      cv::Point2f(static_cast<float>(hi.x()), static_cast<float>(hi.y())),
                      cv::Point2f(static_cast<float>(lo.x()), static_cast<float>(hi.y()))};
  }

  using TargetDetector::detect;
  // Tags are found anew in every frame; the history only chooses the scale and the region of
  // the quad search.
  Result<TargetObservation> detect(const GrayView& image, const DetectionHistory& history) const override {
    return guarded([&] { return detect_impl(image, history); });
  }
  const TargetDescription& target() const override { return target_; }
  std::string describe_other_target(const GrayView& image) const override;

 private:
  Result<TargetObservation> detect_impl(const GrayView& image, const DetectionHistory& history) const;
  // The tags libapriltag decodes with quads searched at 1 / decimate of the resolution, ids not
  // checked against the grid.
  std::vector<TagCorners> decode_tags(const GrayView& view, double decimate) const;
  /// The grid's tags in `region` of the image (the whole image when empty), each id once.
  std::vector<TagCorners> find_tags(const GrayView& view, double decimate, cv::Rect region = {}) const;
  /// The part of the image the frame before says the grid is in, or an empty rectangle when
  /// the whole image is to be searched.
  cv::Rect search_region(const GrayView& view, const DetectionHistory& history) const;
  /// The tags of a frame, refined, searched at half resolution when the frame before showed
  /// large tags (see kCoarseTagEdgePx), else at options_.aprilgrid_decimate.
  std::vector<TagCorners> refined_tags(const GrayView& view, const DetectionHistory& history) const;
  /// The median edge of the tags of an observation of this grid, in pixels (0 without one).
  double median_tag_edge_px(const TargetObservation& obs) const;
  void refine(const cv::Mat& image, std::vector<TagCorners>* tags) const;
  /// Whether refined tag corner k of `corners` (one tag's four) sits on an X junction.
  bool tag_corner_shaped(const cv::Mat& image, const std::vector<cv::Point2f>& corners, int k) const;
  int subpix_half_window(const TagCorners& tag) const;
  // A pool of libapriltag detectors: detect() borrows one (creating it when all are busy), so
  // calls on several threads never share one, and none lives beyond this object (no global or
  // thread-local state, which matters in a module that is unloaded).
  std::unique_ptr<AprilTagContext> borrow() const;
  void give_back(std::unique_ptr<AprilTagContext> ctx) const;

  TargetDescription target_;
  DetectionOptions options_;
  cv::Mat curve_;                              // separation_curve(), read-only
  std::vector<Eigen::Vector3d> board_points_;  // by point id
  std::vector<cv::Point2f> board_outline_;     // the grid's outer corners on the board
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<AprilTagContext>> pool_;
};

std::unique_ptr<AprilTagContext> AprilGridDetector::borrow() const {
  {
    std::lock_guard<std::mutex> lock(pool_mutex_);
    if (!pool_.empty()) {
      auto ctx = std::move(pool_.back());
      pool_.pop_back();
      return ctx;
    }
  }
  return make_apriltag_context(options_.aprilgrid_decimate);
}

void AprilGridDetector::give_back(std::unique_ptr<AprilTagContext> ctx) const {
  std::lock_guard<std::mutex> lock(pool_mutex_);
  pool_.push_back(std::move(ctx));
}

std::vector<TagCorners> AprilGridDetector::decode_tags(const GrayView& view, double decimate) const {
  cv::Mat separated;
  cv::LUT(as_mat(view), curve_, separated);
  std::unique_ptr<AprilTagContext> ctx = borrow();
  ctx->detector->quad_decimate = static_cast<float>(decimate);  // the context is this call's alone
  image_u8_t im{separated.cols, separated.rows, static_cast<std::int32_t>(separated.step[0]), separated.data};
  zarray_t* found = apriltag_detector_detect(ctx->detector.get(), &im);
  std::vector<TagCorners> tags;
  for (int i = 0; i < zarray_size(found); ++i) {
    apriltag_detection_t* det = nullptr;
    zarray_get(found, i, &det);
    TagCorners tag;
    tag.id = det->id;
    // libapriltag's corners are p[0] = tag (-1, 1), p[1] = (1, 1), p[2] = (1, -1),
    // p[3] = (-1, -1), with the tag's y axis along its bit rows, down the tag as drawn: the
    // lower left corner of an upright tag first, counter-clockwise, which on Kalibr's grid
    // (y up the page) is the order of tag_point_ids(). Its pixel centres are at +0.5
    // (tests/calib/test_target_detection.cpp checks both on images of known geometry).
    for (int k = 0; k < 4; ++k) {
      tag.px[k] = cv::Point2f(static_cast<float>(det->p[k][0] - 0.5), static_cast<float>(det->p[k][1] - 0.5));
    }
    tags.push_back(tag);
  }
  apriltag_detections_destroy(found);
  give_back(std::move(ctx));
  return tags;
}

std::string AprilGridDetector::describe_other_target(const GrayView& view) const {
  if (!check_image(view).ok()) return {};
  const std::vector<TagCorners> tags = decode_tags(view, options_.aprilgrid_decimate);
  const int tag_count = target_.tag_rows * target_.tag_cols;
  int outside = 0;
  int largest = -1;
  for (const TagCorners& tag : tags) {
    outside += tag.id >= tag_count ? 1 : 0;
    largest = std::max(largest, tag.id);
  }
  // Most of the tags in view are not on this grid: a larger grid (or another one).
  if (tags.size() < 4 || 2 * outside <= static_cast<int>(tags.size())) return {};
  return "an AprilGrid with tag ids up to " + std::to_string(largest) + " (at least " +
         std::to_string(largest + 1) + " tags)";
}

cv::Rect AprilGridDetector::search_region(const GrayView& view, const DetectionHistory& history) const {
  const TargetObservation* last = history.last;
  if (last == nullptr || last->ids.size() < 4 || last->width != view.width || last->height != view.height)
    return {};
  auto box = [](const TargetObservation& obs) {
    Eigen::Vector2d lo = obs.px.front();
    Eigen::Vector2d hi = obs.px.front();
    for (const Eigen::Vector2d& p : obs.px) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    return std::pair{lo, hi};
  };
  auto [lo, hi] = box(*last);
  // The motion between the two frames before, as the shift of their points' box centres,
  // widens the region both ways.
  Eigen::Vector2d motion = Eigen::Vector2d::Zero();
  if (history.before_last != nullptr && history.before_last->ids.size() >= 4) {
    const auto [lo0, hi0] = box(*history.before_last);
    motion = (0.5 * (lo + hi) - 0.5 * (lo0 + hi0)).cwiseAbs();
  }
  // The whole grid where the frame before's tags put it (a homography from the board's plane,
  // fitted to all its points): tags it missed are searched for too.
  if (board_points_.size() >= 4) {
    std::vector<cv::Point2f> on_board;
    std::vector<cv::Point2f> in_image;
    for (std::size_t k = 0; k < last->ids.size(); ++k) {
      const Eigen::Vector3d& b = board_points_[static_cast<std::size_t>(last->ids[k])];
      on_board.emplace_back(static_cast<float>(b.x()), static_cast<float>(b.y()));
      in_image.emplace_back(static_cast<float>(last->px[k].x()), static_cast<float>(last->px[k].y()));
    }
    const cv::Mat H = cv::findHomography(on_board, in_image, 0);
    if (!H.empty()) {
      std::vector<cv::Point2f> outline;
      cv::perspectiveTransform(board_outline_, outline, H);
      for (const cv::Point2f& q : outline) {
        if (!std::isfinite(q.x) || !std::isfinite(q.y)) continue;
        lo = lo.cwiseMin(Eigen::Vector2d(q.x, q.y));
        hi = hi.cwiseMax(Eigen::Vector2d(q.x, q.y));
      }
    }
  }
  const double margin = kRegionMarginTags * median_tag_edge_px(*last);
  if (!(margin > 0.0)) return {};
  const Eigen::Vector2d grow = Eigen::Vector2d::Constant(margin) + motion;
  lo -= grow;
  hi += grow;
  // The corner on a multiple of 4 pixels: the decimated quad search then samples the same pixels
  // as on the whole image (with another phase it finds other tags at the edge of detection).
  auto down4 = [](double v) { return 4 * static_cast<int>(std::floor(v / 4.0)); };
  const cv::Rect region =
      cv::Rect(cv::Point(down4(lo.x()), down4(lo.y())),
               cv::Point(static_cast<int>(std::ceil(hi.x())) + 1, static_cast<int>(std::ceil(hi.y())) + 1)) &
      cv::Rect(0, 0, view.width, view.height);
  if (static_cast<double>(region.area()) > kMaxRegionShare * view.width * view.height) return {};
  return region;
}

double AprilGridDetector::median_tag_edge_px(const TargetObservation& obs) const {
  // Points r * 2 tag_cols + c: a tag's lower edge joins an even column c to c + 1.
  const int row = 2 * target_.tag_cols;
  std::vector<double> edges;
  for (std::size_t k = 0; k + 1 < obs.ids.size() && k + 1 < obs.px.size(); ++k)
    if (obs.ids[k + 1] == obs.ids[k] + 1 && (obs.ids[k] % row) % 2 == 0)
      edges.push_back((obs.px[k + 1] - obs.px[k]).norm());
  if (edges.empty()) return 0.0;
  std::nth_element(edges.begin(), edges.begin() + static_cast<std::ptrdiff_t>(edges.size() / 2), edges.end());
  return edges[edges.size() / 2];
}

std::vector<TagCorners> AprilGridDetector::refined_tags(const GrayView& view,
                                                        const DetectionHistory& history) const {
  // With tags of 28 px or more the quads are found at half resolution as well (98-100 % of the
  // points on the real recordings of docs/targets.md, "Scale of the quad search"), at a third of
  // the cost. The frame before tells the tags' size; when the coarse search decodes fewer than
  // 90 % of the tags the frame before had (the board moved away, a blurred frame), the frame is
  // searched again at full resolution and the search with more tags kept. An explicit
  // decimation (not 1) is used as given. Measured on two real recordings: as many points as the
  // full search or more, at 2.0x the speed where the tags are large (docs/benchmarks.md).
  // Likewise only the region around the frame before's points is searched while it holds
  // as many tags (kRegionMarginTags).
  const double fine = options_.aprilgrid_decimate;
  const bool coarse =
      fine == 1.0 && history.last != nullptr && median_tag_edge_px(*history.last) >= kCoarseTagEdgePx;
  const cv::Rect region = search_region(view, history);
  std::vector<TagCorners> tags = find_tags(view, coarse ? 2.0 : fine, region);
  const double last_tags =
      history.last != nullptr ? static_cast<double>(history.last->ids.size()) / 4.0 : 0.0;
  if ((coarse || region.area() > 0) && static_cast<double>(tags.size()) < kCoarseKeep * last_tags) {
    std::vector<TagCorners> full = find_tags(view, fine);
    if (full.size() > tags.size()) tags = std::move(full);
  }
  if (options_.subpixel) refine(as_mat(view), &tags);
  return tags;
}

std::vector<TagCorners> AprilGridDetector::find_tags(const GrayView& view, double decimate,
                                                     cv::Rect region) const {
  const int tag_count = target_.tag_rows * target_.tag_cols;
  std::vector<TagCorners> tags;
  if (region.area() > 0) {
    const std::size_t stride = view.stride == 0 ? static_cast<std::size_t>(view.width) : view.stride;
    const GrayView part{
        view.data + static_cast<std::size_t>(region.y) * stride + static_cast<std::size_t>(region.x),
        region.width, region.height, stride};
    tags = decode_tags(part, decimate);
    const cv::Point2f origin(static_cast<float>(region.x), static_cast<float>(region.y));
    for (TagCorners& tag : tags) {
      for (cv::Point2f& p : tag.px) p += origin;
    }
  } else {
    tags = decode_tags(view, decimate);
  }
  // Tags not on this grid are left out.
  std::erase_if(tags, [tag_count](const TagCorners& tag) { return tag.id < 0 || tag.id >= tag_count; });
  // A tag id seen twice means a stray tag in view: neither copy can be trusted.
  std::sort(tags.begin(), tags.end(), [](const TagCorners& a, const TagCorners& b) { return a.id < b.id; });
  std::vector<TagCorners> unique;
  for (std::size_t i = 0; i < tags.size(); ++i) {
    const bool dup_prev = i > 0 && tags[i - 1].id == tags[i].id;
    const bool dup_next = i + 1 < tags.size() && tags[i + 1].id == tags[i].id;
    if (!dup_prev && !dup_next) unique.push_back(tags[i]);
  }
  return unique;
}

int AprilGridDetector::subpix_half_window(const TagCorners& tag) const {
  // Around a tag corner the image is a clean X junction out to the tag's 2-bit border (0.2 of
  // its edge) and the corner square (tag_spacing of it); three quarters of that, 2..8 px.
  double edge = 1e9;
  for (int k = 0; k < 4; ++k) {
    const cv::Point2f d = tag.px[(k + 1) % 4] - tag.px[k];
    edge = std::min(edge, static_cast<double>(std::hypot(d.x, d.y)));
  }
  const double clean = std::min(0.2, target_.tag_spacing) * edge;
  return std::clamp(static_cast<int>(0.75 * clean), 2, 8);
}

bool AprilGridDetector::tag_corner_shaped(const cv::Mat& image, const std::vector<cv::Point2f>& corners,
                                          int k) const {
  // A tag corner is an X junction: dark towards the tag (its 2-bit border) and away from it
  // (the grid's corner square), bright across (the gaps between tags); probed a tenth of the
  // tag's sides out (half the narrower of the border and the gap), at least a pixel. A quad that libapriltag
  // fitted a few pixels off (seen at half resolution on a steep, distorted view of the second
  // generator's frames, docs/benchmarks.md) leaves cornerSubPix where it started, inside a
  // border or a corner square: 4 px from the corner, the move check passes it.
  const cv::Point2f p = corners[static_cast<std::size_t>(k)];
  const cv::Point2f e1 = corners[static_cast<std::size_t>((k + 1) % 4)] - p;
  const cv::Point2f e2 = corners[static_cast<std::size_t>((k + 3) % 4)] - p;
  const float f = 0.5f * static_cast<float>(std::min(0.2, target_.tag_spacing));  // within border and gap
  auto level = [&](cv::Point2f d) {
    const float len = std::hypot(d.x, d.y);
    if (len < 1.0f) d *= 1.0f / std::max(len, 1e-3f);  // at least a pixel out
    // Bilinear, clamped to the image (a probe near the border reads the border's pixels).
    const cv::Point2f q = p + d;
    const float x = std::clamp(q.x, 0.0f, static_cast<float>(image.cols - 1));
    const float y = std::clamp(q.y, 0.0f, static_cast<float>(image.rows - 1));
    const int x0 = std::min(static_cast<int>(x), image.cols - 2);
    const int y0 = std::min(static_cast<int>(y), image.rows - 2);
    const float fx = x - static_cast<float>(x0);
    const float fy = y - static_cast<float>(y0);
    const std::uint8_t* r0 = image.ptr<std::uint8_t>(y0) + x0;
    const std::uint8_t* r1 = image.ptr<std::uint8_t>(y0 + 1) + x0;
    return (1.0f - fy) * ((1.0f - fx) * r0[0] + fx * r0[1]) + fy * ((1.0f - fx) * r1[0] + fx * r1[1]);
  };
  const float tag = level(f * (e1 + e2));
  const float square = level(-f * (e1 + e2));
  const float gap1 = level(f * (e1 - e2));
  const float gap2 = level(f * (e2 - e1));
  // Each gap brighter than both dark sides (the two gaps, and the border and the square, may
  // differ: on event frames one side of an edge is often twice the other).
  return std::min(gap1, gap2) - std::max(tag, square) >= kMinTagCornerContrast;
}

void AprilGridDetector::refine(const cv::Mat& image, std::vector<TagCorners>* tags) const {
  // As Kalibr: cornerSubPix on every tag corner (each an X junction with the grid's small
  // corner squares), and tags whose corners moved more than Kalibr's limit (squared 1.5 px^2)
  // dropped: the refinement found something else. A tag with a corner nearer the image edge
  // than its window is dropped first (the window would read replicated border pixels).
  constexpr double kMaxMove2 = 1.5;
  std::vector<TagCorners> kept;
  for (TagCorners tag : *tags) {
    const int half = subpix_half_window(tag);
    const float lo = half + 1.0f;
    const float hi_x = static_cast<float>(image.cols) - half - 2.0f;
    const float hi_y = static_cast<float>(image.rows) - half - 2.0f;
    bool ok = true;
    for (const cv::Point2f& p : tag.px) ok = ok && p.x >= lo && p.y >= lo && p.x <= hi_x && p.y <= hi_y;
    if (!ok) continue;
    std::vector<cv::Point2f> corners(tag.px.begin(), tag.px.end());
    cv::cornerSubPix(image, corners, cv::Size(half, half), cv::Size(-1, -1), kSubpixCriteria);
    for (int k = 0; k < 4; ++k) {
      const cv::Point2f d = corners[k] - tag.px[k];
      ok = ok && d.dot(d) <= kMaxMove2 && tag_corner_shaped(image, corners, k);
    }
    if (!ok) continue;
    std::copy(corners.begin(), corners.end(), tag.px.begin());
    kept.push_back(tag);
  }
  *tags = std::move(kept);
}

Result<TargetObservation> AprilGridDetector::detect_impl(const GrayView& view,
                                                         const DetectionHistory& history) const {
  IMUCAL_TRY(check_image(view));
  TargetObservation obs = empty_observation(view);
  std::vector<TagCorners> tags = refined_tags(view, history);
  if (static_cast<int>(tags.size()) < std::max(1, options_.min_tags)) return obs;
  // Tags are in id order, and a tag's point ids grow with its id row by row; sorting the
  // pairs gives the ascending ids the observation promises.
  std::vector<std::pair<int, Eigen::Vector2d>> points;
  points.reserve(4 * tags.size());
  for (const TagCorners& tag : tags) {
    const std::array<int, 4> ids = target_.tag_point_ids(tag.id);
    for (int k = 0; k < 4; ++k) points.emplace_back(ids[k], Eigen::Vector2d(tag.px[k].x, tag.px[k].y));
  }
  std::sort(points.begin(), points.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  obs.ids.reserve(points.size());
  obs.px.reserve(points.size());
  for (const auto& [id, p] : points) {
    obs.ids.push_back(id);
    obs.px.push_back(p);
  }
  return obs;
}

}  // namespace

Result<std::unique_ptr<TargetDetector>> TargetDetector::create(const TargetDescription& target,
                                                               const DetectionOptions& options) {
  if (auto s = target.validate(); !s.ok()) return s.error().context("target detection");
  if (options.min_tags < 1) {
    return make_error(Errc::kInvalidArgument, "target detection: min_tags must be at least 1");
  }
  if (!(options.aprilgrid_decimate >= 1.0 && options.aprilgrid_decimate <= 8.0)) {
    return make_error(Errc::kInvalidArgument, "target detection: aprilgrid_decimate must be in [1, 8]");
  }
  if (target.type == TargetDescription::Type::kCheckerboard) {
    if (target.cols < 3 || target.rows < 3) {
      return make_error(Errc::kUnsupported,
                        "checkerboard detection needs at least 3 x 3 inner corners (OpenCV's "
                        "detector); use a board with more squares");
    }
    return std::unique_ptr<TargetDetector>(new CheckerboardDetector(target, options));
  }
  return std::unique_ptr<TargetDetector>(new AprilGridDetector(target, options));
}

}  // namespace imucal::calib
