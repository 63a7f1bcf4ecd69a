#include "sim/camera_render.hpp"

#include <algorithm>
#include <cmath>
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

}  // namespace

Result<std::unique_ptr<CheckerboardRenderer>> CheckerboardRenderer::create(
    const CameraModel& camera, const TargetDescription& target, const CameraRenderOptions& options) {
  if (auto s = validate_camera(camera); !s.ok()) return s.error().context("camera renderer");
  if (target.type != TargetDescription::Type::kCheckerboard) {
    return make_error(Errc::kUnsupported, "camera renderer: only checkerboard targets can be rendered");
  }
  if (auto s = target.validate(); !s.ok()) return s.error().context("camera renderer");
  if (auto s = options.validate(); !s.ok()) return s.error().context("camera renderer");

  std::unique_ptr<CheckerboardRenderer> r(new CheckerboardRenderer());
  r->camera_ = camera;
  r->target_ = target;
  r->options_ = options;
  r->corner_points_ = target.corner_points();
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

void CheckerboardRenderer::accumulate(const Eigen::Isometry3d& T_cam_target, float weight, float* out) const {
  const Eigen::Isometry3d T_target_cam = T_cam_target.inverse();
  const Eigen::Matrix3d R = T_target_cam.linear();
  const Eigen::Vector3d o = T_target_cam.translation();  // camera centre on the board's side z < 0
  const BoardAppearance& look = options_.appearance;
  const double bg = look.background_dn;
  const float bg_w = static_cast<float>(bg) * weight;
  const std::size_t n_px = ray_valid_.size();
  // The board is printed on its z < 0 side (facing the rig); from behind it shows nothing.
  if (!(o.z() < 0.0)) {
    for (std::size_t i = 0; i < n_px; ++i) out[i] += bg_w;
    return;
  }
  const double sx = target_.col_spacing_m;
  const double sy = target_.row_spacing_m;
  const Axis ax{sx, -sx, target_.cols * sx, -sx * (1.0 + look.margin_squares),
                target_.cols * sx + sx * look.margin_squares};
  const Axis ay{sy, -sy, target_.rows * sy, -sy * (1.0 + look.margin_squares),
                target_.rows * sy + sy * look.margin_squares};
  const double white_minus_bg = look.white_dn - bg;
  const double black_minus_white = look.black_dn - look.white_dn;
  const int ns = options_.supersampling;
  const double inv_ns = 1.0 / ns;
  const double mean_weight = weight / static_cast<double>(ns * ns);
  constexpr double kMinHalfWidth = 1e-9;  // m; below this a sample is a point sample

  for (std::size_t i = 0; i < n_px; ++i) {
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
      if (ax.uniform(x, hx, target_.cols) && ay.uniform(y, hy, target_.rows)) {
        double bx, sqx, cx, by, sqy, cy;
        ax.averages(x, hx, &bx, &sqx, &cx);
        ay.averages(y, hy, &by, &sqy, &cy);
        const double black = 0.5 * (sqx * sqy + cx * cy);
        out[i] += static_cast<float>((bg + white_minus_bg * bx * by + black_minus_white * black) * weight);
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
        double bx, sqx, cx, by, sqy, cy;
        ax.averages(x, hx, &bx, &sqx, &cx);
        ay.averages(y, hy, &by, &sqy, &cy);
        // Black where the square waves agree: (1 + c(x) c(y)) / 2 inside the squares.
        const double black = 0.5 * (sqx * sqy + cx * cy);
        sum += bg + white_minus_bg * bx * by + black_minus_white * black;
      }
    }
    out[i] += static_cast<float>(sum * mean_weight);
  }
}

void CheckerboardRenderer::apply_optics(cv::Mat* irradiance) const {
  const double sigma = options_.optics_blur_sigma_px;
  if (sigma > 0.0)
    cv::GaussianBlur(*irradiance, *irradiance, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
}

void CheckerboardRenderer::render_irradiance(const Eigen::Isometry3d& T_cam_target,
                                             cv::Mat* irradiance) const {
  *irradiance = cv::Mat::zeros(camera_.height, camera_.width, CV_32F);
  accumulate(T_cam_target, 1.0f, irradiance->ptr<float>());
  apply_optics(irradiance);
}

cv::Mat CheckerboardRenderer::render(std::span<const Eigen::Isometry3d> T_cam_target_sub_exposures,
                                     Rng* rng) const {
  cv::Mat acc = cv::Mat::zeros(camera_.height, camera_.width, CV_32F);
  float* a = acc.ptr<float>();
  const std::size_t k = T_cam_target_sub_exposures.size();
  if (k == 0) {
    acc.setTo(static_cast<float>(options_.appearance.background_dn));
  }
  for (const auto& T : T_cam_target_sub_exposures) accumulate(T, 1.0f / static_cast<float>(k), a);
  apply_optics(&acc);
  a = acc.ptr<float>();
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

CornerTruth CheckerboardRenderer::project_corners(const Eigen::Isometry3d& T_cam_target) const {
  CornerTruth truth;
  truth.px.reserve(corner_points_.size());
  truth.visible.reserve(corner_points_.size());
  for (const auto& p : corner_points_) {
    const auto proj = camera_.project(T_cam_target * p);
    truth.px.push_back(proj.px);
    truth.visible.push_back(proj.valid() ? 1 : 0);
    truth.visible_count += proj.valid() ? 1 : 0;
  }
  return truth;
}

int CheckerboardRenderer::sub_exposures_needed(const Eigen::Isometry3d& T_cam_target_begin,
                                               const Eigen::Isometry3d& T_cam_target_end,
                                               double max_step_px) const {
  double max_motion_px = 0.0;
  for (const auto& p : corner_points_) {
    const auto a = camera_.project(T_cam_target_begin * p);
    const auto b = camera_.project(T_cam_target_end * p);
    if (!a.in_front || !b.in_front) continue;
    max_motion_px = std::max(max_motion_px, (a.px - b.px).norm());
  }
  const double steps = std::ceil(max_motion_px / std::max(max_step_px, 1e-3));
  return static_cast<int>(std::clamp(steps, 1.0, 64.0));
}

}  // namespace imucal::sim
