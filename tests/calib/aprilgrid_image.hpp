// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Test-only images of Kalibr's AprilGrid with known corner positions.
//
// The grid is drawn as kalibr_create_target_pdf prints it: tag36h11 tags (libapriltag's
// codes, drawn as apriltag_to_image draws them, upright) with a black border two bits wide, so
// the black square (tag_size_m across) is 10 bits; tag t at column t % tag_cols and row
// t / tag_cols counted from the bottom of the page; a small black square of tag_spacing x
// tag_size at each tag corner, touching it diagonally; white around. The target frame is
// Kalibr's: x to the right, y up the page, z out of the page (towards a camera that sees the
// printed side).
//
// Image formation: each pixel is the mean of supersampling x supersampling point samples, each
// mapped onto the target plane through the inverse of a homography (target metres -> image
// pixels, OpenCV's pixel convention: integer = pixel centre) and given the page's exact
// reflectance there. That is the area average of a page of unlimited resolution, so the true
// corner pixels are exactly the homography's image of the target points (a raster page warped
// with cv::warpPerspective would add the raster's own rounding of the tag edges).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "core/target.hpp"

namespace imucal::test {

struct AprilGridImageOptions {
  int width = 752;
  int height = 480;
  int supersampling = 4;    // per axis
  double white_dn = 215.0;  // printed white
  double black_dn = 30.0;   // printed black
  double background_dn = 105.0;
  double blur_sigma_px = 0.0;  // Gaussian lens blur in image pixels, after sampling
  double margin_tags = 0.5;    // white page beyond the corner squares, in tag sizes
  /// The code drawn at each grid position (index = position t); empty: tag t shows id t.
  std::vector<int> tag_ids;
};

struct AprilGridImage {
  cv::Mat image;                     // CV_8UC1
  std::vector<Eigen::Vector2d> px;   // per point id (TargetDescription::points()): true pixel
  std::vector<std::uint8_t> inside;  // 1 when the point is inside the image
};

constexpr int kTag36h11Codes = 587;

/// The 6 x 6 data bits of tag36h11 code `id` (0 <= id < 587) as libapriltag draws the tag:
/// [row][column], row 0 at the top of the upright tag, true = white.
std::array<std::array<bool, 6>, 6> tag36h11_bits(int id);

/// Homography of a pinhole camera (fx, fy, cx, cy) at pose T_cam_target: target plane (x, y)
/// in metres -> image pixels.
Eigen::Matrix3d plane_homography(const Eigen::Vector4d& pinhole, const Eigen::Matrix3d& R_cam_target,
                                 const Eigen::Vector3d& t_cam_target);

AprilGridImage render_aprilgrid(const TargetDescription& target, const Eigen::Matrix3d& H_img_target,
                                const AprilGridImageOptions& options = {});

}  // namespace imucal::test
