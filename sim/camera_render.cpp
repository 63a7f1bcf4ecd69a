// SPDX-License-Identifier: BSD-3-Clause
#include "sim/camera_render.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

namespace imucal::sim {

namespace {

// Antiderivative of the square wave c(u) = +1 on [2k, 2k+1), -1 on [2k+1, 2k+2): a triangle
// wave between 0 and 1.
inline double square_wave_integral(double u) {
  const double k = std::floor(u);
  const double f = u - k;
  return (static_cast<std::int64_t>(k) & 1) == 0 ? f : 1.0 - f;
}

inline double overlap(double a, double b, double lo, double hi) {
  return std::max(0.0, std::min(b, hi) - std::max(a, lo));
}

// Per-axis geometry of the board, in metres on the board plane.
struct Axis {
  double spacing;     // square size
  double squares_lo;  // squares region
  double squares_hi;
  double board_lo;  // squares + margin
  double board_hi;

  // Averages over [x - h, x + h] of: the board indicator, the squares indicator and the square
  // wave restricted to the squares.
  void averages(double x, double h, double* board, double* squares, double* wave) const {
    const double a = x - h;
    const double b = x + h;
    const double inv = 0.5 / h;
    *board = overlap(a, b, board_lo, board_hi) * inv;
    const double lo = std::max(a, squares_lo);
    const double hi = std::min(b, squares_hi);
    if (hi > lo) {
      *squares = (hi - lo) * inv;
      *wave = spacing * (square_wave_integral(hi / spacing) - square_wave_integral(lo / spacing)) * inv;
    } else {
      *squares = 0.0;
      *wave = 0.0;
    }
  }

  // True when no edge of the pattern (square edges between squares_lo and squares_hi, the
  // board's outline) lies inside (x - h, x + h).
  bool uniform(double x, double h, int cells) const {
    const double a = x - h;
    const double b = x + h;
    if ((a < board_lo && b > board_lo) || (a < board_hi && b > board_hi)) return false;
    // Grid lines k * spacing for k = -1 .. cells lie on square edges.
    const double first = std::max(std::floor(a / spacing) + 1.0, -1.0);
    const double last = std::min(std::floor(b / spacing), static_cast<double>(cells));
    return first > last;
  }
};

/// The checkerboard in closed form: board, squares and the square wave are separable.
struct CheckerPattern {
  Axis ax;
  Axis ay;
  int cols;
  int rows;
  double bg;
  double white_minus_bg;
  double black_minus_white;

  double value(double bx, double by, double sqx, double sqy, double cx, double cy) const {
    // Black where the square waves agree: (1 + c(x) c(y)) / 2 inside the squares.
    const double black = 0.5 * (sqx * sqy + cx * cy);
    return bg + white_minus_bg * bx * by + black_minus_white * black;
  }
  /// True, with the average over the box, when no edge crosses it (then it is one colour).
  bool uniform(double x, double hx, double y, double hy, double* out) const {
    if (!ax.uniform(x, hx, cols) || !ay.uniform(y, hy, rows)) return false;
    *out = average(x, hx, y, hy);
    return true;
  }
  /// Average reflectance over the box [x - hx, x + hx] x [y - hy, y + hy].
  double average(double x, double hx, double y, double hy) const {
    double bx, sqx, cx, by, sqy, cy;
    ax.averages(x, hx, &bx, &sqx, &cx);
    ay.averages(y, hy, &by, &sqy, &cy);
    return value(bx, by, sqx, sqy, cx, cy);
  }
};

/// A reflectance that is constant on the cells of an axis-aligned grid (the AprilGrid):
/// integrals over a box are sums over the cells it overlaps.
struct CellPattern {
  std::span<const double> ex;  // sorted cell edges along x; cells 0 and ex.size() are unbounded
  std::span<const double> ey;
  std::span<const double> dn;  // (ey.size() + 1) rows of (ex.size() + 1) cells

  static int cell(std::span<const double> edges, double v) {
    return static_cast<int>(std::upper_bound(edges.begin(), edges.end(), v) - edges.begin());
  }
  static double lo(std::span<const double> edges, int i) {
    return i == 0 ? -std::numeric_limits<double>::infinity() : edges[static_cast<std::size_t>(i - 1)];
  }
  static double hi(std::span<const double> edges, int i) {
    return static_cast<std::size_t>(i) == edges.size() ? std::numeric_limits<double>::infinity()
                                                       : edges[static_cast<std::size_t>(i)];
  }
  double at(int i, int j) const {
    return dn[static_cast<std::size_t>(j) * (ex.size() + 1) + static_cast<std::size_t>(i)];
  }
  bool uniform(double x, double hx, double y, double hy, double* out) const {
    const int i = cell(ex, x - hx);
    const int j = cell(ey, y - hy);
    if (cell(ex, x + hx) != i || cell(ey, y + hy) != j) return false;
    *out = at(i, j);
    return true;
  }
  double average(double x, double hx, double y, double hy) const {
    const double x0 = x - hx, x1 = x + hx, y0 = y - hy, y1 = y + hy;
    const int i0 = cell(ex, x0), i1 = cell(ex, x1);
    const int j0 = cell(ey, y0), j1 = cell(ey, y1);
    if (i0 == i1 && j0 == j1) return at(i0, j0);
    double sum = 0.0;
    for (int j = j0; j <= j1; ++j) {
      const double wy = std::min(y1, hi(ey, j)) - std::max(y0, lo(ey, j));
      double row = 0.0;
      for (int i = i0; i <= i1; ++i) row += (std::min(x1, hi(ex, i)) - std::max(x0, lo(ex, i))) * at(i, j);
      sum += wy * row;
    }
    return sum / (4.0 * hx * hy);
  }
};

/// What a cell along one axis of the AprilGrid holds.
struct AxisCell {
  enum Kind { kBackground, kMargin, kGap, kTag } kind;
  int tag = 0;   // kTag: tag column (x) or row (y)
  int cell = 0;  // kTag: bit cell from the tag's low edge, 0 .. bits - 1
};

/// Cell edges of the AprilGrid along one axis (`tags` tags): per tag its bit cells, the gaps
/// between tags (and before the first and after the last, where the corner squares sit), the
/// margin, then background. `kinds` receives what each cell holds (edges.size() + 1 cells).
void aprilgrid_axis(int tags, double tag_size, double gap, int bits, double margin,
                    std::vector<double>* edges, std::vector<AxisCell>* kinds) {
  const double pitch = tag_size + gap;
  const double cell = tag_size / bits;
  kinds->push_back({AxisCell::kBackground});
  edges->push_back(-gap - margin);
  kinds->push_back({AxisCell::kMargin});
  edges->push_back(-gap);
  kinds->push_back({AxisCell::kGap});
  for (int k = 0; k < tags; ++k) {
    const double x0 = k * pitch;
    for (int m = 0; m < bits; ++m) {
      edges->push_back(x0 + m * cell);
      kinds->push_back({AxisCell::kTag, k, m});
    }
    edges->push_back(x0 + tag_size);
    kinds->push_back({AxisCell::kGap});
  }
  const double end = (tags - 1) * pitch + tag_size + gap;
  edges->push_back(end);
  kinds->push_back({AxisCell::kMargin});
  edges->push_back(end + margin);
  kinds->push_back({AxisCell::kBackground});
}

/// Bit (column j from the tag's left, row i from its top, as printed) of every tag36h11 code,
/// true for white, from libapriltag's family: code bit nbits - 1 - b sits at (bit_x[b], bit_y[b])
/// with (1, 1) the top-left data bit and y down the upright tag. Kalibr prints the same 6 x 6
/// matrices (its row-major codes are libapriltag's in another bit order).
Result<std::vector<std::array<bool, 36>>> tag36h11_bits(int tags) {
  apriltag_family_t* family = tag36h11_create();
  if (family == nullptr)
    return make_error(Errc::kInternal, "camera renderer: libapriltag gave no tag36h11 family");
  if (tags > static_cast<int>(family->ncodes) || family->nbits != 36) {
    const std::string n = std::to_string(family->ncodes);
    tag36h11_destroy(family);
    return make_error(Errc::kInvalidArgument, "camera renderer: an AprilGrid of tag36h11 has at most " + n +
                                                  " tags (tagCols x tagRows)");
  }
  std::vector<std::array<bool, 36>> out(static_cast<std::size_t>(tags));
  for (int t = 0; t < tags; ++t) {
    const std::uint64_t code = family->codes[t];
    for (std::uint32_t b = 0; b < 36; ++b) {
      const std::uint32_t i = family->bit_y[b] - 1;
      const std::uint32_t j = family->bit_x[b] - 1;
      out[static_cast<std::size_t>(t)][6 * i + j] = ((code >> (35 - b)) & 1u) != 0;
    }
  }
  tag36h11_destroy(family);
  return out;
}

}  // namespace

Result<std::unique_ptr<TargetRenderer>> TargetRenderer::create(const CameraModel& camera,
                                                               const TargetDescription& target,
                                                               const CameraRenderOptions& options) {
  if (auto s = validate_camera(camera); !s.ok()) return s.error().context("camera renderer");
  if (auto s = target.validate(); !s.ok()) return s.error().context("camera renderer");
  if (auto s = options.validate(); !s.ok()) return s.error().context("camera renderer");

  std::unique_ptr<TargetRenderer> r(new TargetRenderer());
  r->camera_ = camera;
  r->target_ = target;
  r->options_ = options;
  r->points_ = target.points();
  if (target.type == TargetDescription::Type::kAprilgrid) IMUCAL_TRY(r->build_aprilgrid_cells());
  const std::size_t n = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  r->rays_.assign(9 * n, 0.0);
  r->ray_valid_.assign(n, 0);
  constexpr double h = 0.25;  // pixels, for the central differences of the ray
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const std::size_t i =
          static_cast<std::size_t>(v) * static_cast<std::size_t>(camera.width) + static_cast<std::size_t>(u);
      Eigen::Vector3d c, u0, u1, v0, v1;
      const bool ok = camera.unproject(Eigen::Vector2d(u, v), &c) &&
                      camera.unproject(Eigen::Vector2d(u - h, v), &u0) &&
                      camera.unproject(Eigen::Vector2d(u + h, v), &u1) &&
                      camera.unproject(Eigen::Vector2d(u, v - h), &v0) &&
                      camera.unproject(Eigen::Vector2d(u, v + h), &v1);
      if (!ok) {
        ++r->invalid_pixels_;
        continue;
      }
      // Within a pixel the sample rays are c + a dr/du + b dr/dv (a, b in pixels); only their
      // direction matters, so the unit rays' derivatives serve.
      const Eigen::Vector3d du = (u1 - u0) / (2 * h);
      const Eigen::Vector3d dv = (v1 - v0) / (2 * h);
      double* p = &r->rays_[9 * i];
      for (int k = 0; k < 3; ++k) {
        p[k] = c[k];
        p[3 + k] = du[k];
        p[6 + k] = dv[k];
      }
      r->ray_valid_[i] = 1;
    }
  }
  return r;
}

Status TargetRenderer::build_aprilgrid_cells() {
  const TargetDescription& t = target_;
  const BoardAppearance& look = options_.appearance;
  auto codes = tag36h11_bits(t.tag_cols * t.tag_rows);
  if (!codes.ok()) return codes.error();
  // Kalibr: the tag's black square of edge tagSize is 6 data bits plus the border on each side;
  // the gaps between tags are tagSpacing x tagSize, and so are the corner squares.
  const int border = look.tag_border_bits;
  const int bits = 6 + 2 * border;
  const double gap = t.tag_spacing * t.tag_size_m;
  std::vector<AxisCell> kx, ky;
  aprilgrid_axis(t.tag_cols, t.tag_size_m, gap, bits, look.margin_squares * gap, &edges_x_, &kx);
  aprilgrid_axis(t.tag_rows, t.tag_size_m, gap, bits, look.margin_squares * gap, &edges_y_, &ky);
  cell_dn_.assign(kx.size() * ky.size(), look.background_dn);
  for (std::size_t j = 0; j < ky.size(); ++j) {
    for (std::size_t i = 0; i < kx.size(); ++i) {
      const AxisCell& cx = kx[i];
      const AxisCell& cy = ky[j];
      double& dn = cell_dn_[j * kx.size() + i];
      if (cx.kind == AxisCell::kBackground || cy.kind == AxisCell::kBackground) continue;
      if (cx.kind != AxisCell::kTag || cy.kind != AxisCell::kTag) {
        // Margin and gaps are white, but for the squares where two gaps cross: every such
        // crossing is at a corner of some tag, where Kalibr puts a square.
        const bool square = cx.kind == AxisCell::kGap && cy.kind == AxisCell::kGap && look.tag_corner_squares;
        dn = square ? look.black_dn : look.white_dn;
        continue;
      }
      // Tag t = row * tagCols + column; its bit rows count from the top of the printed tag,
      // which is its high-y side (Kalibr's frame: y up the page).
      const int tag = cy.tag * t.tag_cols + cx.tag;
      const int col = cx.cell - border;
      const int row = (bits - 1 - cy.cell) - border;
      const bool data = col >= 0 && col < 6 && row >= 0 && row < 6;
      const bool white =
          data && (*codes)[static_cast<std::size_t>(tag)][static_cast<std::size_t>(6 * row + col)];
      dn = white ? look.white_dn : look.black_dn;
    }
  }
  return {};
}

void TargetRenderer::accumulate(const Eigen::Isometry3d& T_cam_target, float weight, float* out,
                                std::size_t first, std::size_t last) const {
  const Eigen::Isometry3d T_target_cam = T_cam_target.inverse();
  Eigen::Matrix3d R = T_target_cam.linear();
  Eigen::Vector3d o = T_target_cam.translation();  // camera centre
  const BoardAppearance& look = options_.appearance;
  if (target_.type == TargetDescription::Type::kAprilgrid) {
    // Printed on its z > 0 side: mirrored through the board plane (exact: a sign change), the
    // camera looks at the printed side from z < 0, as for the checkerboard; points on the plane
    // keep their x and y.
    R.row(2) = -R.row(2);
    o.z() = -o.z();
    const CellPattern cells{edges_x_, edges_y_, cell_dn_};
    accumulate_pattern(cells, R, o, weight, out, first, last);
    return;
  }
  const double sx = target_.col_spacing_m;
  const double sy = target_.row_spacing_m;
  const double bg = look.background_dn;
  const CheckerPattern checker{Axis{sx, -sx, target_.cols * sx, -sx * (1.0 + look.margin_squares),
                                    target_.cols * sx + sx * look.margin_squares},
                               Axis{sy, -sy, target_.rows * sy, -sy * (1.0 + look.margin_squares),
                                    target_.rows * sy + sy * look.margin_squares},
                               target_.cols,
                               target_.rows,
                               bg,
                               look.white_dn - bg,
                               look.black_dn - look.white_dn};
  accumulate_pattern(checker, R, o, weight, out, first, last);
}

template <class Pattern>
void TargetRenderer::accumulate_pattern(const Pattern& pattern, const Eigen::Matrix3d& R,
                                        const Eigen::Vector3d& o, float weight, float* out, std::size_t first,
                                        std::size_t last) const {
  const double bg = options_.appearance.background_dn;
  const float bg_w = static_cast<float>(bg) * weight;
  // The printed side faces z < 0 here; from behind the board shows nothing.
  if (!(o.z() < 0.0)) {
    for (std::size_t i = first; i < last; ++i) out[i] += bg_w;
    return;
  }
  const int ns = options_.supersampling;
  const double inv_ns = 1.0 / ns;
  const double mean_weight = weight / static_cast<double>(ns * ns);
  constexpr double kMinHalfWidth = 1e-9;  // m; below this a sample is a point sample

  for (std::size_t i = first; i < last; ++i) {
    if (!ray_valid_[i]) {
      out[i] += bg_w;
      continue;
    }
    const double* p = &rays_[9 * i];
    const Eigen::Vector3d d = R * Eigen::Vector3d(p[0], p[1], p[2]);
    const Eigen::Vector3d du = R * Eigen::Vector3d(p[3], p[4], p[5]);
    const Eigen::Vector3d dv = R * Eigen::Vector3d(p[6], p[7], p[8]);
    // Most pixels see one colour only: when a generous box around the whole pixel's footprint
    // on the board crosses no edge, one evaluation is exact.
    if (d.z() > 0.0) {
      const double lambda = -o.z() / d.z();
      const double x = o.x() + lambda * d.x();
      const double y = o.y() + lambda * d.y();
      const double su = lambda / d.z();
      const double xa = su * (du.x() * d.z() - d.x() * du.z());
      const double ya = su * (du.y() * d.z() - d.y() * du.z());
      const double xb = su * (dv.x() * d.z() - d.x() * dv.z());
      const double yb = su * (dv.y() * d.z() - d.y() * dv.z());
      constexpr double kSafety = 0.65;  // half the bounding box (0.5) plus 30 % for perspective
      const double hx = std::max(kSafety * (std::abs(xa) + std::abs(xb)), kMinHalfWidth);
      const double hy = std::max(kSafety * (std::abs(ya) + std::abs(yb)), kMinHalfWidth);
      double value;
      if (pattern.uniform(x, hx, y, hy, &value)) {
        out[i] += static_cast<float>(value * weight);
        continue;
      }
    }
    double sum = 0.0;
    for (int j = 0; j < ns; ++j) {
      const double b = (j + 0.5) * inv_ns - 0.5;
      for (int k = 0; k < ns; ++k) {
        const double a = (k + 0.5) * inv_ns - 0.5;
        const Eigen::Vector3d dir = d + a * du + b * dv;
        // The ray meets the plane z = 0 ahead of the camera only if it points towards +z.
        if (!(dir.z() > 0.0)) {
          sum += bg;
          continue;
        }
        const double lambda = -o.z() / dir.z();
        const double x = o.x() + lambda * dir.x();
        const double y = o.y() + lambda * dir.y();
        // Footprint of the sample on the board: d(x, y)/d(a, b) over 1/ns pixel.
        const double su = lambda * inv_ns / dir.z();
        const double xa = su * (du.x() * dir.z() - dir.x() * du.z());
        const double ya = su * (du.y() * dir.z() - dir.y() * du.z());
        const double xb = su * (dv.x() * dir.z() - dir.x() * dv.z());
        const double yb = su * (dv.y() * dir.z() - dir.y() * dv.z());
        const double hx = std::max(0.5 * std::hypot(xa, xb), kMinHalfWidth);
        const double hy = std::max(0.5 * std::hypot(ya, yb), kMinHalfWidth);
        sum += pattern.average(x, hx, y, hy);
      }
    }
    out[i] += static_cast<float>(sum * mean_weight);
  }
}

void TargetRenderer::apply_optics(cv::Mat* irradiance) const {
  const double sigma = options_.optics_blur_sigma_px;
  if (sigma > 0.0)
    cv::GaussianBlur(*irradiance, *irradiance, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
}

void TargetRenderer::render_irradiance(const Eigen::Isometry3d& T_cam_target, cv::Mat* irradiance) const {
  *irradiance = cv::Mat::zeros(camera_.height, camera_.width, CV_32F);
  accumulate(T_cam_target, 1.0f, irradiance->ptr<float>());
  apply_optics(irradiance);
}

cv::Mat TargetRenderer::render(std::span<const Eigen::Isometry3d> T_cam_target_sub_exposures,
                               Rng* rng) const {
  cv::Mat acc = cv::Mat::zeros(camera_.height, camera_.width, CV_32F);
  float* a = acc.ptr<float>();
  const std::size_t k = T_cam_target_sub_exposures.size();
  if (k == 0) {
    acc.setTo(static_cast<float>(options_.appearance.background_dn));
  }
  for (const auto& T : T_cam_target_sub_exposures) accumulate(T, 1.0f / static_cast<float>(k), a);
  return finish(&acc, rng);
}

cv::Mat TargetRenderer::render_rows(std::span<const Eigen::Isometry3d> T_cam_target_rows, int sub_exposures,
                                    Rng* rng) const {
  cv::Mat acc = cv::Mat::zeros(camera_.height, camera_.width, CV_32F);
  float* a = acc.ptr<float>();
  const auto h = static_cast<std::size_t>(camera_.height), w = static_cast<std::size_t>(camera_.width);
  const auto k = static_cast<std::size_t>(std::max(sub_exposures, 0));
  if (k == 0 || T_cam_target_rows.size() != k * h) {
    acc.setTo(static_cast<float>(options_.appearance.background_dn));
  } else {
    for (std::size_t i = 0; i < k; ++i)
      for (std::size_t r = 0; r < h; ++r)
        accumulate(T_cam_target_rows[i * h + r], 1.0f / static_cast<float>(k), a, r * w, (r + 1) * w);
  }
  return finish(&acc, rng);
}

cv::Mat TargetRenderer::finish(cv::Mat* irradiance, Rng* rng) const {
  cv::Mat& acc = *irradiance;
  apply_optics(&acc);
  const float* a = acc.ptr<float>();
  cv::Mat out(camera_.height, camera_.width, CV_8U);
  std::uint8_t* o = out.ptr<std::uint8_t>();
  const double sigma = options_.noise_sigma_dn;
  const std::size_t n = static_cast<std::size_t>(camera_.width) * static_cast<std::size_t>(camera_.height);
  for (std::size_t i = 0; i < n; ++i) {
    double v = a[i];
    if (sigma > 0.0 && rng != nullptr) v += sigma * rng->normal();
    o[i] = static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
  }
  return out;
}

CornerTruth TargetRenderer::project_corners(const Eigen::Isometry3d& T_cam_target) const {
  CornerTruth truth;
  truth.px.reserve(points_.size());
  truth.visible.reserve(points_.size());
  for (const auto& p : points_) {
    const auto proj = camera_.project(T_cam_target * p);
    truth.px.push_back(proj.px);
    truth.visible.push_back(proj.valid() ? 1 : 0);
    truth.visible_count += proj.valid() ? 1 : 0;
  }
  return truth;
}

int TargetRenderer::sub_exposures_needed(const Eigen::Isometry3d& T_cam_target_begin,
                                         const Eigen::Isometry3d& T_cam_target_end,
                                         double max_step_px) const {
  double max_motion_px = 0.0;
  for (const auto& p : points_) {
    const auto a = camera_.project(T_cam_target_begin * p);
    const auto b = camera_.project(T_cam_target_end * p);
    if (!a.in_front || !b.in_front) continue;
    max_motion_px = std::max(max_motion_px, (a.px - b.px).norm());
  }
  const double steps = std::ceil(max_motion_px / std::max(max_step_px, 1e-3));
  return static_cast<int>(std::clamp(steps, 1.0, 64.0));
}

}  // namespace imucal::sim
