// SPDX-License-Identifier: BSD-3-Clause
#include "tests/calib/aprilgrid_image.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <array>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace imucal::test {
namespace {

constexpr int kBits = 10;  // black square: 6 data bits and a 2-bit border each side (Kalibr)

/// The 6 x 6 data bits of a tag36h11 code, row 0 at the top of the upright tag, true = white.
/// As libapriltag draws a tag (apriltag_to_image): code bit i, counted from the most
/// significant of nbits, is white when set, at (bit_x[i], bit_y[i]) counted from the black
/// square's upper left corner in bits (1..6 for tag36h11, inside a 1-bit border).
using TagBits = std::array<std::array<bool, 6>, 6>;

}  // namespace

std::array<std::array<bool, 6>, 6> tag36h11_bits(int id) {
  apriltag_family_t* family = tag36h11_create();
  std::array<std::array<bool, 6>, 6> bits{};
  const std::uint64_t code = family->codes[id];
  for (std::uint32_t i = 0; i < family->nbits; ++i) {
    const bool white = ((code >> (family->nbits - 1 - i)) & 1U) != 0;
    bits[family->bit_y[i] - 1][family->bit_x[i] - 1] = white;
  }
  tag36h11_destroy(family);
  return bits;
}

namespace {

struct Page {
  const TargetDescription& t;
  std::vector<TagBits> bits;  // per grid position; a position without a code shows no tag
  std::vector<bool> has_tag;
  double pitch = 0.0;    // tag + spacing
  double spacing = 0.0;  // metres
  double x_min = 0.0, x_max = 0.0, y_min = 0.0, y_max = 0.0;

  /// Reflectance class at target point (x, y): 0 black, 1 white, 2 beyond the page.
  int at(double x, double y) const {
    if (x < x_min || x >= x_max || y < y_min || y >= y_max) return 2;
    const double s = t.tag_size_m;
    const int i = static_cast<int>(std::floor(x / pitch));
    const int j = static_cast<int>(std::floor(y / pitch));
    const double fx = x - i * pitch;
    const double fy = y - j * pitch;
    const bool in_cols = i >= -1 && i < t.tag_cols;
    const bool in_rows = j >= -1 && j < t.tag_rows;
    if (fx >= s && fy >= s) return in_cols && in_rows ? 0 : 1;  // corner squares between tags
    if (fx >= s || fy >= s || i < 0 || j < 0 || i >= t.tag_cols || j >= t.tag_rows) return 1;
    const int pos = j * t.tag_cols + i;
    if (!has_tag[pos]) return 1;
    const int b = static_cast<int>(fx / s * kBits);
    const int a = kBits - 1 - static_cast<int>(fy / s * kBits);  // bit row from the top
    if (a < 2 || a > 7 || b < 2 || b > 7) return 0;              // the black border
    return bits[pos][a - 2][b - 2] ? 1 : 0;
  }
};

}  // namespace

Eigen::Matrix3d plane_homography(const Eigen::Vector4d& pinhole, const Eigen::Matrix3d& R_cam_target,
                                 const Eigen::Vector3d& t_cam_target) {
  Eigen::Matrix3d K;
  K << pinhole[0], 0, pinhole[2], 0, pinhole[1], pinhole[3], 0, 0, 1;
  Eigen::Matrix3d M;
  M << R_cam_target.col(0), R_cam_target.col(1), t_cam_target;
  return K * M;
}

AprilGridImage render_aprilgrid(const TargetDescription& target, const Eigen::Matrix3d& H_img_target,
                                const AprilGridImageOptions& options) {
  Page page{target, {}, {}, 0, 0, 0, 0, 0, 0};
  const int tags = target.tag_cols * target.tag_rows;
  page.bits.resize(tags);
  page.has_tag.resize(tags, false);
  for (int pos = 0; pos < tags; ++pos) {
    const int id = options.tag_ids.empty() ? pos : options.tag_ids[pos];
    if (id < 0 || id >= kTag36h11Codes) continue;
    page.bits[pos] = tag36h11_bits(id);
    page.has_tag[pos] = true;
  }
  page.spacing = target.tag_spacing * target.tag_size_m;
  page.pitch = target.tag_size_m + page.spacing;
  const double border = page.spacing + options.margin_tags * target.tag_size_m;
  page.x_min = page.y_min = -border;
  page.x_max = target.tag_cols * page.pitch - page.spacing + border;
  page.y_max = target.tag_rows * page.pitch - page.spacing + border;

  const Eigen::Matrix3d H_target_img = H_img_target.inverse();
  const int n = options.supersampling;
  const double levels[3] = {options.black_dn, options.white_dn, options.background_dn};
  cv::Mat acc(options.height, options.width, CV_32F);
  for (int v = 0; v < options.height; ++v) {
    for (int u = 0; u < options.width; ++u) {
      double sum = 0.0;
      for (int sv = 0; sv < n; ++sv) {
        for (int su = 0; su < n; ++su) {
          const Eigen::Vector3d p =
              H_target_img * Eigen::Vector3d(u + (su + 0.5) / n - 0.5, v + (sv + 0.5) / n - 0.5, 1.0);
          sum += p.z() > 0 ? levels[page.at(p.x() / p.z(), p.y() / p.z())] : options.background_dn;
        }
      }
      acc.at<float>(v, u) = static_cast<float>(sum / (n * n));
    }
  }
  if (options.blur_sigma_px > 0) cv::GaussianBlur(acc, acc, cv::Size(0, 0), options.blur_sigma_px);
  AprilGridImage out;
  acc.convertTo(out.image, CV_8U);  // rounds and saturates

  const std::vector<Eigen::Vector3d> points = target.points();
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector3d q = H_img_target * Eigen::Vector3d(p.x(), p.y(), 1.0);
    const Eigen::Vector2d px = q.hnormalized();
    out.px.push_back(px);
    const bool inside = q.z() > 0 && px.x() >= 0 && px.y() >= 0 && px.x() <= options.width - 1 &&
                        px.y() <= options.height - 1;
    out.inside.push_back(inside ? 1 : 0);
  }
  return out;
}

}  // namespace imucal::test
