// SPDX-License-Identifier: BSD-3-Clause
#include "calib/checkerboard_grid.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <numbers>
#include <opencv2/imgproc.hpp>

namespace imucal::calib {
namespace {

/// Smoothing before the second derivatives: enough to take the pixel noise off, small enough
/// that the junctions of squares 5 px wide stay apart.
constexpr double kBlurSigma = 1.2;
constexpr int kBlurSize = 7;  // 2.5 sigma each way (OpenCV's default, 9, costs a third more)
/// The weakest junction kept: that of an ideal corner between squares this many grey levels
/// apart, behind 0.7 px of lens blur. Boards in use differ by 50-200 levels.
constexpr double kMinContrast = 16.0;
/// At most this many junctions, the strongest (a cap on the cost in busy scenes: each is tried
/// as a seed; 1000 found every board that 1500 did on the frames of docs/benchmarks.md, and
/// 700 and 500 every board that 1000 did, but 500 loses the dim board among crossing bars of
/// test CheckerboardGrid.FindsABoardAmongCrossingBars).
constexpr std::size_t kMaxJunctions = 700;
/// The maxima search looks at about this many of a busy frame's strongest pixels (a maximum
/// and its neighbours above the floor are about 8 pixels).
constexpr std::size_t kBusyPixels = 16 * kMaxJunctions;
/// Junctions nearer the border than this are not found (the derivatives' reach).
constexpr int kBorder = 3;
/// A junction answers an extrapolated point within this fraction of the local grid step.
constexpr float kMatchFraction = 0.3f;
/// Saddle axes of neighbours along a row or column are a quarter turn apart, of diagonal
/// neighbours alike (exactly so under any affine view); the tolerances on both.
constexpr float kQuarterTolerance = 40.0f * std::numbers::pi_v<float> / 180.0f;
/// The 3 x 3 patch's two steps: at least this far apart in angle (sine) and this close in length.
constexpr float kMinSine = 0.5f;
constexpr float kMaxStepRatio = 2.5f;
/// Neighbours of a seed considered for its patch.
constexpr int kSeedNeighbours = 4;
/// A junction joins a grid only if at least this fraction as strong as the one it continues
/// (the edges of squares carry weak saddles, most in JPEG images; the junctions at a fisheye
/// board's rim are down to 0.4 of their neighbours').
constexpr float kMinStrengthRatio = 0.2f;
/// The same within a seed's 3 x 3 patch, where neighbours are alike and the edges' saddles
/// would crowd out the junctions among the nearest.
constexpr float kMinSeedStrengthRatio = 0.45f;
/// Side by side squares of a grid differ by at least this many grey levels.
constexpr float kMinSquareContrast = 8.0f;
/// The squares around a junction are probed this fraction of the grid's diagonal steps away,
/// and the two on a diagonal may differ by at most this fraction of the two diagonals'
/// difference (0 at an X junction; 2 at the L-shaped corners where the board's outer squares
/// meet its margin, which line up with the grid and alternate like its junctions).
constexpr float kSquareProbe = 0.3f;
constexpr float kMaxWithinDiagonal = 0.5f;
/// A seed's squares hold no junction within this fraction of a step of their centres.
constexpr float kEmptySquare = 0.4f;
/// Images at least this large a side are also searched at half resolution.
constexpr int kMinHalfSide = 64;
/// The region of the searches after an undecided grid reaches this many squares beyond the rows
/// and columns the grid lacks: the board's outer squares and the white margin OpenCV's quad
/// search needs around them, with room for a square growing in perspective.
constexpr float kRegionMarginSquares = 2.0f;

struct Junction {
  cv::Point2f p;
  float strength = 0.0f;
  float axis = 0.0f;  // direction of the saddle's rising curvature, [0, pi)
};

// Saddle strength 16 (dxy^2 - dxx * dyy) of the smoothed image, in integers (0 at the border
// rows and columns). Central differences: dxx = I(x+1) + I(x-1) - 2 I(x), dxy the four diagonal
// neighbours' difference over 4.
cv::Mat saddle_strength(const cv::Mat& smooth) {
  cv::Mat out(smooth.size(), CV_32S);
  const int w = smooth.cols;
  out.row(0).setTo(0);
  out.row(out.rows - 1).setTo(0);
  for (int y = 1; y + 1 < smooth.rows; ++y) {
    const std::uint8_t* __restrict up = smooth.ptr<std::uint8_t>(y - 1);
    const std::uint8_t* __restrict mid = smooth.ptr<std::uint8_t>(y);
    const std::uint8_t* __restrict down = smooth.ptr<std::uint8_t>(y + 1);
    std::int32_t* __restrict o = out.ptr<std::int32_t>(y);
    for (int x = 1; x + 1 < w; ++x) {
      const std::int32_t c2 = 2 * static_cast<std::int32_t>(mid[x]);
      const std::int32_t dxx = static_cast<std::int32_t>(mid[x + 1]) + mid[x - 1] - c2;
      const std::int32_t dyy = static_cast<std::int32_t>(down[x]) + up[x] - c2;
      const std::int32_t dxy4 = static_cast<std::int32_t>(down[x + 1]) - down[x - 1] - up[x + 1] + up[x - 1];
      o[x] = dxy4 * dxy4 - 16 * dxx * dyy;
    }
    o[0] = 0;
    o[w - 1] = 0;
  }
  return out;
}

// The grey image smoothed, 8 bits (the rounding adds a third of a level of noise, far below the
// weakest junction kept). sepFilter2D with a float kernel: half the time of GaussianBlur's
// bit-exact fixed-point filter on 8-bit images (0.31 against 0.70 ms at 752 x 480).
cv::Mat smoothed(const cv::Mat& gray) {
  static const cv::Mat kernel = cv::getGaussianKernel(kBlurSize, kBlurSigma, CV_32F);
  cv::Mat out;
  cv::sepFilter2D(gray, out, CV_8U, kernel, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_REPLICATE);
  return out;
}

// The strength of the weakest junction kept: an ideal corner of kMinContrast levels drawn with
// 8 x 8 supersampling and 0.7 px of blur, through the same filters.
std::int32_t strength_floor() {
  static const std::int32_t floor = [] {
    constexpr int kSize = 25;
    constexpr int kSs = 8;
    cv::Mat fine(kSize * kSs, kSize * kSs, CV_32F);
    const double centre = 0.5 * kSize * kSs;  // the junction at a pixel corner
    for (int y = 0; y < fine.rows; ++y) {
      for (int x = 0; x < fine.cols; ++x) {
        const bool dark = ((x + 0.5 - centre) < 0) != ((y + 0.5 - centre) < 0);
        fine.at<float>(y, x) = static_cast<float>(128.0 + (dark ? -0.5 : 0.5) * kMinContrast);
      }
    }
    cv::Mat coarse;
    cv::resize(fine, coarse, cv::Size(kSize, kSize), 0, 0, cv::INTER_AREA);
    cv::GaussianBlur(coarse, coarse, cv::Size(0, 0), 0.7);
    cv::Mat eight;
    coarse.convertTo(eight, CV_8U);
    double best = 0.0;
    cv::minMaxLoc(saddle_strength(smoothed(eight)), nullptr, &best);
    return static_cast<std::int32_t>(best);
  }();
  return floor;
}

float axis_at(const cv::Mat& smooth, int x, int y) {
  // The strength's derivatives (the 3 x 3 around (x, y): wider ones reach the next junction on
  // squares of 4 px).
  auto at = [&](int dx, int dy) { return static_cast<float>(smooth.at<std::uint8_t>(y + dy, x + dx)); };
  const float dxx = at(1, 0) + at(-1, 0) - 2.0f * at(0, 0);
  const float dyy = at(0, 1) + at(0, -1) - 2.0f * at(0, 0);
  const float dxy = 0.25f * (at(1, 1) - at(-1, 1) - at(1, -1) + at(-1, -1));
  float a = 0.5f * std::atan2(2.0f * dxy, dxx - dyy);
  if (a < 0.0f) a += std::numbers::pi_v<float>;
  return a;
}

constexpr int kBlock = 16;
// Whether any of the kBlock values from `p` exceeds `floor`. Vectorised by g++ 12 only as a
// function of its own: inlined into the search loop it stays scalar (-fopt-info-vec).
[[gnu::noinline]] bool any_above(const std::int32_t* p, std::int32_t floor) {
  int over = 0;
  for (int k = 0; k < kBlock; ++k) over |= static_cast<int>(p[k] > floor);
  return over != 0;
}

// Local maxima of the strength above the floor, to a fraction of a pixel (a parabola through
// each maximum and its neighbours along x and along y).
std::vector<Junction> find_junctions(const cv::Mat& gray, cv::Mat* smooth_out) {
  *smooth_out = smoothed(gray);
  const cv::Mat& smooth = *smooth_out;
  const cv::Mat s = saddle_strength(smooth);
  // In a busy frame (textures, clutter) the floor is raised to about the strength that
  // kBusyPixels of the pixels exceed (estimated from every 4th pixel of every 4th row): the
  // maxima search then looks at no more, and the strongest kMaxJunctions maxima are among them.
  std::int32_t floor = strength_floor();
  std::vector<std::int32_t> sample(static_cast<std::size_t>((s.rows / 4 + 1) * (s.cols / 4 + 1)));
  std::size_t n = 0;
  for (int y = kBorder; y < s.rows - kBorder; y += 4) {
    const std::int32_t* row = s.ptr<std::int32_t>(y);
    for (int x = kBorder; x < s.cols - kBorder; x += 4) sample[n++] = row[x];
  }
  sample.resize(n);
  const std::size_t keep = kBusyPixels / 16;
  if (sample.size() > keep) {
    std::nth_element(sample.begin(), sample.begin() + static_cast<std::ptrdiff_t>(keep), sample.end(),
                     std::greater<>());
    floor = std::max(floor, sample[keep]);
  }
  // The maxima first, their positions and axes only for the strongest kept.
  struct Peak {
    std::int32_t v;
    int x;
    int y;
  };
  std::vector<Peak> peaks;
  peaks.reserve(4 * kMaxJunctions);
  for (int y = kBorder; y < s.rows - kBorder; ++y) {
    const std::int32_t* up = s.ptr<std::int32_t>(y - 1);
    const std::int32_t* mid = s.ptr<std::int32_t>(y);
    const std::int32_t* down = s.ptr<std::int32_t>(y + 1);
    auto try_peak = [&](int x) {
      const std::int32_t v = mid[x];
      if (v <= floor) return;
      // Ties go to the first in reading order.
      if (v <= mid[x + 1] || v < mid[x - 1] || v <= down[x] || v < up[x] || v < up[x - 1] || v < up[x + 1] ||
          v <= down[x - 1] || v <= down[x + 1]) {
        return;
      }
      peaks.push_back({v, x, y});
    };
    // Most pixels are below the floor: whole blocks of them are passed over at once.
    const int end = s.cols - kBorder;
    int x = kBorder;
    for (; x + kBlock <= end; x += kBlock) {
      if (!any_above(mid + x, floor)) continue;
      for (int k = x; k < x + kBlock; ++k) try_peak(k);
    }
    for (; x < end; ++x) try_peak(x);
  }
  if (peaks.size() > kMaxJunctions) {
    std::nth_element(peaks.begin(), peaks.begin() + kMaxJunctions, peaks.end(),
                     [](const Peak& a, const Peak& b) { return a.v > b.v; });
    peaks.resize(kMaxJunctions);
  }
  auto offset = [](std::int32_t a, std::int32_t b, std::int32_t c) {
    const float den = static_cast<float>(a - 2 * b + c);
    return den < 0.0f ? std::clamp(0.5f * static_cast<float>(a - c) / den, -0.5f, 0.5f) : 0.0f;
  };
  std::vector<Junction> out;
  out.reserve(peaks.size());
  for (const Peak& k : peaks) {
    const std::int32_t* mid = s.ptr<std::int32_t>(k.y);
    Junction j;
    j.p = cv::Point2f(static_cast<float>(k.x) + offset(mid[k.x - 1], k.v, mid[k.x + 1]),
                      static_cast<float>(k.y) +
                          offset(s.at<std::int32_t>(k.y - 1, k.x), k.v, s.at<std::int32_t>(k.y + 1, k.x)));
    j.strength = static_cast<float>(k.v);
    j.axis = axis_at(smooth, k.x, k.y);
    out.push_back(j);
  }
  return out;
}

// Angle between two saddle axes, [0, pi/2].
float axis_gap(float a, float b) {
  float d = std::abs(a - b);
  if (d > 0.5f * std::numbers::pi_v<float>) d = std::numbers::pi_v<float> - d;
  return d;
}
bool quarter_apart(const Junction& a, const Junction& b) {
  return axis_gap(a.axis, b.axis) >= 0.5f * std::numbers::pi_v<float> - kQuarterTolerance;
}
bool alike(const Junction& a, const Junction& b) { return axis_gap(a.axis, b.axis) <= kQuarterTolerance; }
bool as_strong(const Junction& a, const Junction& b, float ratio = kMinStrengthRatio) {
  return a.strength >= ratio * b.strength && b.strength >= ratio * a.strength;
}

float length2(cv::Point2f v) { return v.x * v.x + v.y * v.y; }
float length(cv::Point2f v) { return std::sqrt(length2(v)); }

// The junctions in square cells for nearest-point queries.
class JunctionIndex {
 public:
  JunctionIndex(const std::vector<Junction>& junctions, cv::Size image, int cell)
      : junctions_(junctions), cell_(cell), nx_(image.width / cell + 1), ny_(image.height / cell + 1) {
    std::vector<int> count(static_cast<std::size_t>(nx_ * ny_) + 1, 0);
    for (const Junction& j : junctions_) ++count[cell_of(j.p) + 1];
    for (std::size_t k = 1; k < count.size(); ++k) count[k] += count[k - 1];
    start_ = count;
    order_.resize(junctions_.size());
    for (std::size_t i = 0; i < junctions_.size(); ++i)
      order_[count[cell_of(junctions_[i].p)]++] = static_cast<int>(i);
  }

  /// The strongest junction within `radius` of `p` that `accept` takes, or -1 (the edges of a
  /// junction's squares carry weaker saddles, sometimes nearer the prediction).
  template <class Accept>
  int strongest(cv::Point2f p, float radius, Accept&& accept) const {
    int best = -1;
    float best_strength = 0.0f;
    const float radius2 = radius * radius;
    visit(p, radius, [&](int i) {
      if (length2(junctions_[i].p - p) <= radius2 && junctions_[i].strength > best_strength && accept(i)) {
        best_strength = junctions_[i].strength;
        best = i;
      }
    });
    return best;
  }

  /// Up to `k` junctions nearest to junction `i` within `radius` that `accept` takes, nearest
  /// first (valid until the next call).
  template <class Accept>
  const std::vector<int>& neighbours(int i, int k, float radius, Accept&& accept) const {
    const cv::Point2f p = junctions_[i].p;
    std::vector<std::pair<float, int>>& found = found_;
    found.clear();
    // Rings of cells outwards until k are known to be the nearest, or until the ring is
    // further than kMaxStepRatio times the nearest found (a patch's steps are no further apart).
    const int cx = std::clamp(static_cast<int>(p.x) / cell_, 0, nx_ - 1);
    const int cy = std::clamp(static_cast<int>(p.y) / cell_, 0, ny_ - 1);
    const int rings = static_cast<int>(radius / static_cast<float>(cell_)) + 1;
    const float radius2 = radius * radius;
    float nearest = radius;
    for (int ring = 0; ring <= rings; ++ring) {
      if (static_cast<float>((ring - 1) * cell_) > kMaxStepRatio * nearest) break;
      for (int y = cy - ring; y <= cy + ring; ++y) {
        if (y < 0 || y >= ny_) continue;
        const bool edge_row = y == cy - ring || y == cy + ring;
        for (int x = cx - ring; x <= cx + ring; x += (edge_row || ring == 0) ? 1 : 2 * ring) {
          if (x < 0 || x >= nx_) continue;
          for (int s = start_[y * nx_ + x]; s < start_[y * nx_ + x + 1]; ++s) {
            const int j = order_[s];
            if (j == i) continue;
            const float d2 = length2(junctions_[j].p - p);
            if (d2 <= radius2 && accept(j)) {
              const float d = std::sqrt(d2);
              found.emplace_back(d, j);
              nearest = std::min(nearest, d);
            }
          }
        }
      }
      if (static_cast<int>(found.size()) >= k) {
        std::partial_sort(found.begin(), found.begin() + k, found.end());
        if (found[k - 1].first <= static_cast<float>(ring * cell_)) break;
      }
    }
    std::sort(found.begin(), found.end());
    if (static_cast<int>(found.size()) > k) found.resize(k);
    near_.clear();
    for (const auto& f : found) near_.push_back(f.second);
    return near_;
  }

 private:
  int cell_of(cv::Point2f p) const {
    const int x = std::clamp(static_cast<int>(p.x) / cell_, 0, nx_ - 1);
    const int y = std::clamp(static_cast<int>(p.y) / cell_, 0, ny_ - 1);
    return y * nx_ + x;
  }
  template <class F>
  void visit(cv::Point2f p, float radius, F&& f) const {
    const int x0 = std::max(0, static_cast<int>((p.x - radius) / static_cast<float>(cell_)));
    const int x1 = std::min(nx_ - 1, static_cast<int>((p.x + radius) / static_cast<float>(cell_)));
    const int y0 = std::max(0, static_cast<int>((p.y - radius) / static_cast<float>(cell_)));
    const int y1 = std::min(ny_ - 1, static_cast<int>((p.y + radius) / static_cast<float>(cell_)));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        for (int s = start_[y * nx_ + x]; s < start_[y * nx_ + x + 1]; ++s) f(order_[s]);
      }
    }
  }

  const std::vector<Junction>& junctions_;
  int cell_;
  int nx_;
  int ny_;
  std::vector<int> start_;
  std::vector<int> order_;
  // Scratch for neighbours(), kept between calls (one a seed).
  mutable std::vector<std::pair<float, int>> found_;
  mutable std::vector<int> near_;
};

// How the growth of a grid's side ended.
enum class SideEnd {
  kOpen,     // not tried yet
  kEdge,     // extrapolated points inside the image, (almost) none met a junction: an edge
  kPartial,  // some met junctions, not all: a junction missing, the side undecided
  kCut,      // extrapolated points outside the image
};

class Grid {
 public:
  Grid(const std::vector<Junction>& junctions, const JunctionIndex& index, std::vector<int>* owner, int id,
       const cv::Mat& smooth)
      : junctions_(junctions),
        index_(index),
        owner_(*owner),
        id_(id),
        smooth_(smooth),
        image_(smooth.size()) {}

  /// A 3 x 3 patch around `seed`, or false.
  bool start(int seed, float max_step) {
    const Junction& c = junctions_[seed];
    // Along a row or column: a quarter turn apart and as strong.
    const std::vector<int>& near = index_.neighbours(seed, kSeedNeighbours, max_step, [&](int i) {
      return owner_[i] < 0 && quarter_apart(c, junctions_[i]) &&
             as_strong(c, junctions_[i], kMinSeedStrengthRatio);
    });
    for (std::size_t ia = 0; ia < near.size(); ++ia) {
      const int a = near[ia];
      const cv::Point2f u = junctions_[a].p - c.p;
      const float lu = length(u);
      for (std::size_t ib = ia + 1; ib < near.size(); ++ib) {
        const int b = near[ib];
        const cv::Point2f v = junctions_[b].p - c.p;
        const float lv = length(v);
        if (std::abs(u.x * v.y - u.y * v.x) < kMinSine * lu * lv) continue;
        if (std::max(lu, lv) > kMaxStepRatio * std::min(lu, lv)) continue;
        if (try_patch(seed, a, b, u, v, std::min(lu, lv))) return true;
      }
    }
    return false;
  }

  /// Grows the grid side by side while whole rows or columns meet junctions; at most
  /// `max_side` junctions a side.
  void grow(int max_side) {
    bool grew = true;
    while (grew) {
      grew = false;
      for (int side = 0; side < 4; ++side) {
        if (end_[side] != SideEnd::kOpen) continue;
        if ((side < 2 ? cols_ : rows_) >= max_side) {
          end_[side] = SideEnd::kPartial;  // outgrew any board: let a slower search decide
          continue;
        }
        if (extend(side)) {
          grew = true;
        }
      }
    }
  }

  int rows() const { return rows_; }
  int cols() const { return cols_; }
  SideEnd end(int side) const { return end_[side]; }  // 0 right, 1 left, 2 bottom, 3 top
  cv::Point2f at(int r, int c) const { return junctions_[cells_[r * cols_ + c]].p; }

 private:
  bool try_patch(int seed, int a, int b, cv::Point2f u, cv::Point2f v, float step) {
    const float radius = kMatchFraction * step;
    std::array<int, 9> patch{};
    patch.fill(-1);
    patch[4] = seed;
    patch[5] = a;  // (row 1, col 2): +u
    patch[7] = b;  // (row 2, col 1): +v
    const cv::Point2f c = junctions_[seed].p;
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) {
        const int slot = r * 3 + k;
        if (patch[slot] >= 0) continue;
        const cv::Point2f q = c + static_cast<float>(k - 1) * u + static_cast<float>(r - 1) * v;
        const bool diagonal = (r + k) % 2 == 0;
        const int j = index_.strongest(q, radius, [&](int i) {
          if (owner_[i] >= 0 || std::find(patch.begin(), patch.end(), i) != patch.end()) return false;
          const Junction& s = junctions_[seed];
          return as_strong(s, junctions_[i], kMinSeedStrengthRatio) &&
                 (diagonal ? alike(s, junctions_[i]) : quarter_apart(s, junctions_[i]));
        });
        if (j < 0) return false;
        patch[slot] = j;
      }
    }
    // Every point an X junction (an L-shaped corner at the board's rim passes the tests above),
    // and its four squares alternate dark and bright.
    for (int i : patch) {
      if (!x_shaped(junctions_[i].p, u, v)) return false;
    }
    // No junction as strong inside a square: a lattice of knight's moves (two squares along,
    // one across) passes every other test, and holds junctions about 0.3 of its step from the
    // centres of its cells (a board's squares hold none nearer than 0.7 of a step).
    for (int r = 0; r < 2; ++r) {
      for (int k = 0; k < 2; ++k) {
        const cv::Point2f centre =
            0.25f * (junctions_[patch[r * 3 + k]].p + junctions_[patch[r * 3 + k + 1]].p +
                     junctions_[patch[(r + 1) * 3 + k]].p + junctions_[patch[(r + 1) * 3 + k + 1]].p);
        const int inside = index_.strongest(centre, kEmptySquare * step, [&](int i) {
          return as_strong(junctions_[seed], junctions_[i], kMinSeedStrengthRatio);
        });
        if (inside >= 0) return false;
      }
    }
    const std::vector<int> cells(patch.begin(), patch.end());
    const float l00 = square_level(cells, 3, 0, 0);
    const float l01 = square_level(cells, 3, 0, 1);
    const float l10 = square_level(cells, 3, 1, 0);
    const float l11 = square_level(cells, 3, 1, 1);
    const bool dark00 = l00 < l01;
    if (!differ(l00, dark00, l01) || !differ(l00, dark00, l10) || !differ(l11, dark00, l01) ||
        !differ(l11, dark00, l10)) {
      return false;
    }
    dark00_ = dark00;
    rows_ = 3;
    cols_ = 3;
    cells_ = cells;
    for (int i : cells_) owner_[i] = id_;
    return true;
  }

  // One more column (side 0 right, 1 left) or row (2 bottom, 3 top), or the side's end.
  bool extend(int side) {
    const bool column = side < 2;
    const int lines = column ? rows_ : cols_;  // points in the new column or row
    const int depth = column ? cols_ : rows_;  // points along each line towards the side
    auto point = [&](int line, int k) {        // k-th point from the side inwards
      const int along = (side == 0 || side == 2) ? depth - 1 - k : k;
      return column ? at(line, along) : at(along, line);
    };
    auto junction = [&](int line, int k) {
      const int along = (side == 0 || side == 2) ? depth - 1 - k : k;
      return column ? cells_[line * cols_ + along] : cells_[along * cols_ + line];
    };
    std::vector<int> added(static_cast<std::size_t>(lines), -1);
    int inside = 0;
    int matched = 0;
    for (int line = 0; line < lines; ++line) {
      const cv::Point2f p1 = point(line, 0);
      const cv::Point2f p2 = point(line, 1);
      const float step = length(p1 - p2);
      // A quadratic through three points follows the lens's bend; on small squares the
      // junctions' own error, tripled by it, would exceed the tolerance: a straight line.
      cv::Point2f q = 2.0f * p1 - p2;
      if (depth >= 3 && step >= 10.0f) q = 3.0f * p1 - 3.0f * p2 + point(line, 2);
      if (q.x < kBorder || q.y < kBorder || q.x > static_cast<float>(image_.width - 1 - kBorder) ||
          q.y > static_cast<float>(image_.height - 1 - kBorder)) {
        continue;
      }
      ++inside;
      const Junction& last = junctions_[junction(line, 0)];
      // The step to the next line, for the squares around the new junction.
      const cv::Point2f across = line + 1 < lines ? point(line + 1, 0) - p1 : p1 - point(line - 1, 0);
      const int j = index_.strongest(q, std::max(1.5f, kMatchFraction * step), [&](int i) {
        return owner_[i] < 0 && quarter_apart(last, junctions_[i]) && as_strong(last, junctions_[i]) &&
               std::find(added.begin(), added.end(), i) == added.end() &&
               x_shaped(junctions_[i].p, junctions_[i].p - p1, across);
      });
      if (j >= 0) {
        added[static_cast<std::size_t>(line)] = j;
        ++matched;
      }
    }
    if (inside < lines) {
      end_[side] = SideEnd::kCut;
      return false;
    }
    if (matched < lines) {
      end_[side] = matched >= std::max(2, lines / 2) ? SideEnd::kPartial : SideEnd::kEdge;
      return false;
    }
    std::vector<int> cells;
    if (column) {
      cells.reserve(static_cast<std::size_t>(rows_ * (cols_ + 1)));
      for (int r = 0; r < rows_; ++r) {
        if (side == 1) cells.push_back(added[static_cast<std::size_t>(r)]);
        cells.insert(cells.end(), cells_.begin() + r * cols_, cells_.begin() + (r + 1) * cols_);
        if (side == 0) cells.push_back(added[static_cast<std::size_t>(r)]);
      }
    } else {
      if (side == 3) cells = added;
      cells.insert(cells.end(), cells_.begin(), cells_.end());
      if (side == 2) cells.insert(cells.end(), added.begin(), added.end());
    }
    // A row or column added before the first turns the squares' parity.
    const bool dark00 = (side == 1 || side == 3) ? !dark00_ : dark00_;
    const int rows = column ? rows_ : rows_ + 1;
    const int cols = column ? cols_ + 1 : cols_;
    if (!border_squares_alternate(cells, rows, cols, dark00, side)) {
      end_[side] = SideEnd::kEdge;  // junctions in line, but no squares of the board between them
      return false;
    }
    for (int j : added) owner_[j] = id_;
    rows_ = rows;
    cols_ = cols;
    dark00_ = dark00;
    cells_ = std::move(cells);
    return true;
  }

  // The smoothed grey level at the centre of the square between corners (r, c) and (r+1, c+1)
  // of a grid of `cols` columns.
  float square_level(const std::vector<int>& cells, int cols, int r, int c) const {
    const cv::Point2f centre =
        0.25f * (junctions_[cells[r * cols + c]].p + junctions_[cells[r * cols + c + 1]].p +
                 junctions_[cells[(r + 1) * cols + c]].p + junctions_[cells[(r + 1) * cols + c + 1]].p);
    const int x = std::clamp(static_cast<int>(std::lround(centre.x)), 0, smooth_.cols - 1);
    const int y = std::clamp(static_cast<int>(std::lround(centre.y)), 0, smooth_.rows - 1);
    return smooth_.at<std::uint8_t>(y, x);
  }
  // Whether the four squares around a junction at `q` (grid steps `u` and `v`) are dark and
  // bright in turn, alike across each diagonal, as at an X junction; at the L-shaped corners
  // where the outer squares meet the board's margin three of the four are alike.
  bool x_shaped(cv::Point2f q, cv::Point2f u, cv::Point2f v) const {
    auto level = [&](cv::Point2f p) {
      const int x = std::clamp(static_cast<int>(std::lround(p.x)), 0, smooth_.cols - 1);
      const int y = std::clamp(static_cast<int>(std::lround(p.y)), 0, smooth_.rows - 1);
      return static_cast<float>(smooth_.at<std::uint8_t>(y, x));
    };
    const cv::Point2f d1 = kSquareProbe * (u + v);
    const cv::Point2f d2 = kSquareProbe * (u - v);
    const float a = level(q + d1);
    const float c = level(q - d1);
    const float b = level(q + d2);
    const float d = level(q - d2);
    const float between = std::abs(0.5f * (a + c) - 0.5f * (b + d));
    const float within = std::max(std::abs(a - c), std::abs(b - d));
    return between >= kMinSquareContrast && within <= kMaxWithinDiagonal * between;
  }
  // Whether square (r, c) is dark with `dark00` saying whether square (0, 0) is.
  static bool dark(bool dark00, int r, int c) { return ((r + c) % 2 == 0) == dark00; }
  // Whether two neighbouring squares differ as the checkerboard says, by kMinSquareContrast.
  static bool differ(float level, bool is_dark, float other) {
    return is_dark ? other - level >= kMinSquareContrast : level - other >= kMinSquareContrast;
  }
  // Whether the squares of a grid's outermost row or column on `side` alternate with the row
  // or column next to them.
  bool border_squares_alternate(const std::vector<int>& cells, int rows, int cols, bool dark00,
                                int side) const {
    const bool column = side < 2;
    const int outer = side == 0 ? cols - 2 : side == 2 ? rows - 2 : 0;
    const int inner = (side == 0 || side == 2) ? outer - 1 : 1;
    for (int k = 0; k + 1 < (column ? rows : cols); ++k) {
      const int r = column ? k : outer;
      const int c = column ? outer : k;
      const float next = column ? square_level(cells, cols, k, inner) : square_level(cells, cols, inner, k);
      if (!differ(square_level(cells, cols, r, c), dark(dark00, r, c), next)) return false;
    }
    return true;
  }

  const std::vector<Junction>& junctions_;
  const JunctionIndex& index_;
  std::vector<int>& owner_;
  int id_;
  const cv::Mat& smooth_;
  cv::Size image_;
  bool dark00_ = false;  // whether the square between corners (0, 0) and (1, 1) is dark
  int rows_ = 0;
  int cols_ = 0;
  std::vector<int> cells_;  // row-major junction indices
  std::array<SideEnd, 4> end_{SideEnd::kOpen, SideEnd::kOpen, SideEnd::kOpen, SideEnd::kOpen};
};

// Whether the grid, read with its rows as the board's rows (or, `transposed`, its columns),
// could be the part of the board that is in view: every dimension short of the board's ends on
// at least one side at the image border, and on none at a missing junction.
bool cut_board(const Grid& g, int cols, int rows, bool transposed) {
  const int gr = transposed ? g.cols() : g.rows();
  const int gc = transposed ? g.rows() : g.cols();
  if (gr > rows || gc > cols) return false;
  auto dimension_ok = [&](int have, int need, SideEnd a, SideEnd b) {
    if (have == need) return true;
    if (a == SideEnd::kPartial || b == SideEnd::kPartial) return false;
    return a == SideEnd::kCut || b == SideEnd::kCut;
  };
  // Grid sides 0/1 end its rows (columns added), 2/3 its columns.
  const bool along_rows_ok = dimension_ok(g.cols(), transposed ? rows : cols, g.end(0), g.end(1));
  const bool along_cols_ok = dimension_ok(g.rows(), transposed ? cols : rows, g.end(2), g.end(3));
  return along_rows_ok && along_cols_ok;
}

// Whether the grid ends on every side at the board's edge: a whole board.
bool whole(const Grid& g) {
  for (int side = 0; side < 4; ++side) {
    if (g.end(side) != SideEnd::kEdge) return false;
  }
  return true;
}

// The search at one scale.
CheckerboardGrid search(const cv::Mat& gray, int cols, int rows) {
  CheckerboardGrid out;
  cv::Mat smooth;
  std::vector<Junction> junctions = find_junctions(gray, &smooth);
  std::sort(junctions.begin(), junctions.end(),
            [](const Junction& a, const Junction& b) { return a.strength > b.strength; });
  // The widest step a board in view can have: the whole image across its shorter side.
  const float max_step =
      static_cast<float>(std::max(gray.cols, gray.rows)) / static_cast<float>(std::min(cols, rows) + 1);
  const JunctionIndex index(junctions, gray.size(), 16);
  std::vector<int> owner(junctions.size(), -1);
  const int max_side = 4 * std::max(cols, rows) + 4;  // bounds the growth; no board this size
  bool undecided = false;
  bool cut = false;
  bool other = false;
  int grids = 0;
  for (std::size_t seed = 0; seed < junctions.size(); ++seed) {
    if (owner[seed] >= 0) continue;
    Grid grid(junctions, index, &owner, grids, smooth);
    if (!grid.start(static_cast<int>(seed), max_step)) continue;
    ++grids;
    grid.grow(max_side);
    const bool as_is = grid.rows() == rows && grid.cols() == cols;
    const bool turned = grid.rows() == cols && grid.cols() == rows;
    if (as_is || turned) {
      out.outcome = CheckerboardGrid::Outcome::kFound;
      out.grid_rows = rows;
      out.grid_cols = cols;
      out.corners.resize(static_cast<std::size_t>(cols * rows));
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) out.corners[r * cols + c] = as_is ? grid.at(r, c) : grid.at(c, r);
      }
      return out;
    }
    if (cut_board(grid, cols, rows, false) || cut_board(grid, cols, rows, true)) {
      cut = true;
    } else if (whole(grid)) {
      if (!other && !undecided) {
        out.grid_rows = grid.rows();
        out.grid_cols = grid.cols();
      }
      other = true;
    } else {
      if (!undecided || grid.rows() * grid.cols() > out.grid_rows * out.grid_cols) {
        out.grid_rows = grid.rows();
        out.grid_cols = grid.cols();
        out.corners.resize(static_cast<std::size_t>(grid.rows() * grid.cols()));
        for (int r = 0; r < grid.rows(); ++r) {
          for (int c = 0; c < grid.cols(); ++c) out.corners[r * grid.cols() + c] = grid.at(r, c);
        }
      }
      undecided = true;
    }
  }
  out.outcome = undecided ? CheckerboardGrid::Outcome::kUndecided
                : other   ? CheckerboardGrid::Outcome::kOther
                : cut     ? CheckerboardGrid::Outcome::kCut
                          : CheckerboardGrid::Outcome::kNone;
  return out;
}

// How much an outcome says, for choosing between the two scales' (a grid found says most).
int weight(CheckerboardGrid::Outcome o) {
  switch (o) {
    case CheckerboardGrid::Outcome::kFound:
      return 4;
    case CheckerboardGrid::Outcome::kUndecided:
      return 3;
    case CheckerboardGrid::Outcome::kOther:
      return 2;
    case CheckerboardGrid::Outcome::kCut:
      return 1;
    case CheckerboardGrid::Outcome::kNone:
      return 0;
  }
  return 0;
}

}  // namespace

cv::Rect fallback_region(const CheckerboardGrid& grid, int cols, int rows, cv::Size image) {
  const cv::Rect whole(0, 0, image.width, image.height);
  const int gc = grid.grid_cols;
  const int gr = grid.grid_rows;
  if (grid.outcome != CheckerboardGrid::Outcome::kUndecided || gc < 2 || gr < 2 ||
      grid.corners.size() != static_cast<std::size_t>(gc * gr)) {
    return whole;
  }
  // The rows or columns of the board the grid lacks, the most either way round that fits (the
  // grid may be the board's rows or its columns; one that outgrew the board lacks none).
  int missing = 0;
  if (gc <= cols && gr <= rows) missing = std::max({missing, cols - gc, rows - gr});
  if (gc <= rows && gr <= cols) missing = std::max({missing, rows - gc, cols - gr});
  // The grid's longest step between neighbours stands for the squares beyond it.
  float step = 0.0f;
  float x0 = grid.corners[0].x;
  float y0 = grid.corners[0].y;
  float x1 = x0;
  float y1 = y0;
  for (int r = 0; r < gr; ++r) {
    for (int c = 0; c < gc; ++c) {
      const cv::Point2f p = grid.corners[r * gc + c];
      x0 = std::min(x0, p.x);
      y0 = std::min(y0, p.y);
      x1 = std::max(x1, p.x);
      y1 = std::max(y1, p.y);
      if (c + 1 < gc) step = std::max(step, length(grid.corners[r * gc + c + 1] - p));
      if (r + 1 < gr) step = std::max(step, length(grid.corners[(r + 1) * gc + c] - p));
    }
  }
  const float margin = (static_cast<float>(missing) + kRegionMarginSquares) * step;
  const cv::Point tl(static_cast<int>(std::floor(x0 - margin)), static_cast<int>(std::floor(y0 - margin)));
  const cv::Point br(static_cast<int>(std::ceil(x1 + margin)) + 1,
                     static_cast<int>(std::ceil(y1 + margin)) + 1);
  return cv::Rect(tl, br) & whole;
}

CheckerboardGrid find_checkerboard_grid(const cv::Mat& gray, int cols, int rows) {
  if (gray.empty() || gray.type() != CV_8UC1 || cols < 2 || rows < 2) {
    CheckerboardGrid out;
    out.outcome = CheckerboardGrid::Outcome::kUndecided;
    return out;
  }
  CheckerboardGrid fine = search(gray, cols, rows);
  using Outcome = CheckerboardGrid::Outcome;
  if (fine.outcome != Outcome::kUndecided) return fine;
  // A grid that stopped short: the same at half resolution, where the smoothing reaches twice as
  // far. Soft or JPEG images of large squares break the junctions into clusters of weak saddles
  // along the edges at full resolution (the real fisheye frames of docs/benchmarks.md).
  if (std::min(gray.cols, gray.rows) < kMinHalfSide) return fine;
  cv::Mat half;
  cv::pyrDown(gray, half);
  CheckerboardGrid coarse = search(half, cols, rows);
  for (cv::Point2f& p : coarse.corners) p *= 2.0f;  // pyrDown's pixel i is centred on pixel 2i
  if (coarse.outcome == Outcome::kFound) return coarse;
  if (weight(coarse.outcome) > weight(fine.outcome) ||
      (coarse.outcome == fine.outcome &&
       coarse.grid_cols * coarse.grid_rows > fine.grid_cols * fine.grid_rows)) {
    return coarse;
  }
  return fine;
}

}  // namespace imucal::calib
