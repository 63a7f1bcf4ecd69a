// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "sim/camera_render.hpp"
#include "sim/camera_scene.hpp"
#include "tests/support/test_helpers.hpp"

namespace imucal::sim {
namespace {

using test::equi_camera;
using test::radtan_camera;

TargetDescription board() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 7;
  t.rows = 6;
  t.col_spacing_m = 0.04;
  t.row_spacing_m = 0.04;
  return t;
}

/// Board seen from `distance_m` with its centre offset in the image and tilted by the rotation
/// vector `rot` (radians), camera frame.
Eigen::Isometry3d pose(const TargetDescription& t, const Eigen::Vector3d& rot, double distance_m,
                       double offset_x_m = 0.0, double offset_y_m = 0.0) {
  const Eigen::Vector3d centre((t.cols - 1) * t.col_spacing_m / 2, (t.rows - 1) * t.row_spacing_m / 2, 0.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translate(Eigen::Vector3d(offset_x_m, offset_y_m, distance_m));
  if (rot.norm() > 0) T.rotate(Eigen::AngleAxisd(rot.norm(), rot.normalized()));
  T.translate(-centre);
  return T;
}

/// RMS distance between detected and true corners; the detector may report the grid from
/// either end, so the smaller of the two orderings counts.
double corner_rms(const std::vector<cv::Point2f>& detected, const CornerTruth& truth) {
  const std::size_t n = truth.px.size();
  double fwd = 0.0;
  double rev = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d d(detected[i].x, detected[i].y);
    fwd += (d - truth.px[i]).squaredNorm();
    rev += (d - truth.px[n - 1 - i]).squaredNorm();
  }
  return std::sqrt(std::min(fwd, rev) / static_cast<double>(n));
}

struct Detection {
  bool found = false;
  double rms_px = 0.0;
  Eigen::Vector2d mean_px = Eigen::Vector2d::Zero();  // mean error: a shifted render shows here
};

Detection detect(const cv::Mat& image, const TargetDescription& t, const CornerTruth& truth) {
  std::vector<cv::Point2f> corners;
  Detection out;
  out.found = cv::findChessboardCorners(image, cv::Size(t.cols, t.rows), corners,
                                        cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!out.found) return out;
  cv::cornerSubPix(image, corners, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  out.rms_px = corner_rms(corners, truth);
  const std::size_t n = truth.px.size();
  const bool reversed = (Eigen::Vector2d(corners[0].x, corners[0].y) - truth.px[0]).norm() >
                        (Eigen::Vector2d(corners[0].x, corners[0].y) - truth.px[n - 1]).norm();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d d(corners[i].x, corners[i].y);
    out.mean_px += d - truth.px[reversed ? n - 1 - i : i];
  }
  out.mean_px /= static_cast<double>(n);
  return out;
}

// Without noise, corners detected in the rendered images must agree with the projected truth.
// What remains is the detector's own error: cornerSubPix locks towards pixel positions on
// sharp edges (about 0.05-0.08 px RMS, zero mean, the same with 1x1 or 8x8 supersampling) and
// does better with a lens blur; a wrong render (shifted by half a pixel, wrong distortion)
// shows in the mean error and the RMS.
double expect_corners_reproject(const CameraModel& camera, double optics_blur_sigma_px) {
  const TargetDescription t = board();
  CameraRenderOptions opt;
  opt.supersampling = 4;
  opt.optics_blur_sigma_px = optics_blur_sigma_px;
  auto r = CheckerboardRenderer::create(camera, t, opt);
  EXPECT_TRUE(r.ok()) << r.error().message;
  if (!r.ok()) return 1e9;
  const std::vector<Eigen::Isometry3d> poses = {
      pose(t, Eigen::Vector3d(0.0, 0.0, 0.0), 0.55),
      pose(t, Eigen::Vector3d(0.35, -0.2, 0.1), 0.5, 0.03, -0.02),
      pose(t, Eigen::Vector3d(-0.3, 0.45, -0.6), 0.6, -0.05, 0.02),
      pose(t, Eigen::Vector3d(0.1, 0.25, 1.2), 0.45, 0.06, 0.03),  // towards the distorted corner
      pose(t, Eigen::Vector3d(0.5, 0.0, 0.3), 0.7, -0.08, -0.04),
  };
  double sum_sq = 0.0;
  int frames = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const CornerTruth truth = (*r)->project_corners(poses[i]);
    EXPECT_EQ(truth.visible_count, t.cols * t.rows) << "pose " << i << " must keep the board in view";
    const std::vector<Eigen::Isometry3d> single = {poses[i]};
    const cv::Mat image = (*r)->render(single, nullptr);
    const Detection d = detect(image, t, truth);
    EXPECT_TRUE(d.found) << "pose " << i;
    if (!d.found) return 1e9;
    EXPECT_LT(d.rms_px, 0.1) << "pose " << i;
    EXPECT_LT(d.mean_px.norm(), 0.03) << "pose " << i << " mean error " << d.mean_px.transpose();
    sum_sq += d.rms_px * d.rms_px;
    ++frames;
  }
  const double rms = std::sqrt(sum_sq / frames);
  EXPECT_LT(rms, 0.1);
  std::printf("corner RMS over %d frames (lens blur %.1f px): %.4f px\n", frames, optics_blur_sigma_px, rms);
  return rms;
}

TEST(CameraRender, RenderedCornersReprojectRadtan) { expect_corners_reproject(radtan_camera(), 0.0); }

TEST(CameraRender, RenderedCornersReprojectEquidistant) { expect_corners_reproject(equi_camera(), 0.0); }

// Every lens model of the virtual camera (sim_camera_for's presets, up to 195 degrees across):
// the corners detected in its rendered frames agree with the projected truth, on the axis and
// near the image's border, where a fisheye bends the board most.
TEST(CameraRender, RenderedCornersReprojectEveryLensModel) {
  const TargetDescription t = board();
  for (const char* name : {"pinhole-fov", "omni-none", "omni-radtan", "eucm-none", "ds-none"}) {
    const auto model = parse_camera_model_name(name);
    ASSERT_TRUE(model.has_value()) << name;
    const CameraModel camera = sim_camera_for(376, 240, *model);
    CameraRenderOptions opt;
    opt.supersampling = 3;
    opt.optics_blur_sigma_px = 0.6;
    auto r = CheckerboardRenderer::create(camera, t, opt);
    ASSERT_TRUE(r.ok()) << name << ": " << r.error().message;
    const bool fisheye =
        model->projection == ProjectionModel::kEucm || model->projection == ProjectionModel::kDs;
    const double near = fisheye ? 0.16 : 0.3;
    const std::vector<Eigen::Isometry3d> poses = {
        pose(t, Eigen::Vector3d(0.2, -0.1, 0.0), near),
        pose(t, Eigen::Vector3d(0.0, 0.5, 0.1), near, fisheye ? 0.08 : 0.09, 0.02),
    };
    for (std::size_t i = 0; i < poses.size(); ++i) {
      const CornerTruth truth = (*r)->project_corners(poses[i]);
      ASSERT_EQ(truth.visible_count, t.cols * t.rows) << name << " pose " << i;
      const std::vector<Eigen::Isometry3d> single = {poses[i]};
      const Detection d = detect((*r)->render(single, nullptr), t, truth);
      ASSERT_TRUE(d.found) << name << " pose " << i;
      EXPECT_LT(d.rms_px, 0.12) << name << " pose " << i;
      EXPECT_LT(d.mean_px.norm(), 0.05) << name << " pose " << i << " mean error " << d.mean_px.transpose();
    }
  }
}

TEST(CameraRender, RenderedCornersReprojectWithLensBlur) {
  EXPECT_LT(expect_corners_reproject(radtan_camera(), 0.8), 0.05);
}

TEST(CameraRender, TruthIsTheProjectionOfTheInnerCorners) {
  const TargetDescription t = board();
  const CameraModel cam = radtan_camera();
  auto r = CheckerboardRenderer::create(cam, t, {});
  ASSERT_TRUE(r.ok());
  const Eigen::Isometry3d T = pose(t, Eigen::Vector3d(0.2, 0.1, 0.3), 0.5);
  const CornerTruth truth = (*r)->project_corners(T);
  const auto points = t.corner_points();
  ASSERT_EQ(truth.px.size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    EXPECT_EQ(truth.px[i], cam.project(T * points[i]).px);
  }
  // A board far to the side is partly out of view.
  const CornerTruth side = (*r)->project_corners(pose(t, Eigen::Vector3d::Zero(), 0.5, 0.3, 0.0));
  EXPECT_GT(side.visible_count, 0);
  EXPECT_LT(side.visible_count, t.cols * t.rows);
}

TEST(CameraRender, SquaresHaveTheirColours) {
  const TargetDescription t = board();
  CameraModel cam = radtan_camera();
  cam.distortion_coeffs.setZero();
  CameraRenderOptions opt;
  auto r = CheckerboardRenderer::create(cam, t, opt);
  ASSERT_TRUE(r.ok());
  // Fronto-parallel board, corner 0 at the principal point.
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(0, 0, 0.5);
  cv::Mat irr;
  (*r)->render_irradiance(T, &irr);
  const double px_per_m = cam.intrinsics[0] / 0.5;
  auto at = [&](double x_m, double y_m) {
    const int u = static_cast<int>(std::lround(cam.intrinsics[2] + x_m * px_per_m));
    const int v = static_cast<int>(std::lround(cam.intrinsics[3] + y_m * cam.intrinsics[1] / 0.5));
    return static_cast<double>(irr.at<float>(v, u));
  };
  const double s = t.col_spacing_m;
  const BoardAppearance& look = opt.appearance;
  EXPECT_NEAR(at(-0.5 * s, -0.5 * s), look.black_dn, 1e-3);  // the square before corner 0
  EXPECT_NEAR(at(0.5 * s, -0.5 * s), look.white_dn, 1e-3);
  EXPECT_NEAR(at(0.5 * s, 0.5 * s), look.black_dn, 1e-3);
  EXPECT_NEAR(at(-1.0 * s - 0.3 * s, 0.5 * s), look.white_dn, 1e-3);  // the margin
  EXPECT_NEAR(at(-1.0 * s - 1.2 * s, 0.5 * s), look.background_dn, 1e-3);
  // An edge (board x = 0) through a pixel centre half covers that pixel.
  Eigen::Isometry3d T_edge = T;
  T_edge.translation().x() = (std::round(cam.intrinsics[2]) - cam.intrinsics[2]) / px_per_m;
  (*r)->render_irradiance(T_edge, &irr);
  const int u0 = static_cast<int>(std::round(cam.intrinsics[2]));
  const int v0 = static_cast<int>(std::lround(cam.intrinsics[3] + 0.5 * s * cam.intrinsics[1] / 0.5));
  EXPECT_NEAR(irr.at<float>(v0, u0), 0.5 * (look.white_dn + look.black_dn), 0.5);
}

TEST(CameraRender, DeterministicUnderSeed) {
  const TargetDescription t = board();
  CameraRenderOptions opt;
  opt.noise_sigma_dn = 2.0;
  auto r = CheckerboardRenderer::create(radtan_camera(), t, opt);
  ASSERT_TRUE(r.ok());
  const std::vector<Eigen::Isometry3d> poses = {pose(t, Eigen::Vector3d(0.1, 0.2, 0.3), 0.5)};
  Rng a(42), b(42), c(43);
  const cv::Mat ia = (*r)->render(poses, &a);
  const cv::Mat ib = (*r)->render(poses, &b);
  const cv::Mat ic = (*r)->render(poses, &c);
  EXPECT_EQ(cv::norm(ia, ib, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(ia, ic, cv::NORM_INF), 0.0);
  // The noise has the requested sigma: compare with the noise-free render.
  const cv::Mat clean = (*r)->render(poses, nullptr);
  cv::Mat diff;
  cv::subtract(ia, clean, diff, cv::noArray(), CV_64F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(diff, mean, stddev);
  EXPECT_NEAR(mean[0], 0.0, 0.05);
  // Rounding adds 1/12 DN^2 of variance.
  EXPECT_NEAR(stddev[0], std::sqrt(4.0 + 1.0 / 12.0), 0.05);
}

TEST(CameraRender, MotionBlurAveragesSubExposures) {
  const TargetDescription t = board();
  auto r = CheckerboardRenderer::create(radtan_camera(), t, {});
  ASSERT_TRUE(r.ok());
  const Eigen::Isometry3d T0 = pose(t, Eigen::Vector3d(0.1, 0.0, 0.0), 0.5);
  const Eigen::Isometry3d T1 = pose(t, Eigen::Vector3d(0.1, 0.0, 0.0), 0.5, 0.01, 0.0);  // ~6 px right
  // A static exposure sampled many times is the sharp image.
  const std::vector<Eigen::Isometry3d> still(4, T0);
  const std::vector<Eigen::Isometry3d> one = {T0};
  EXPECT_LE(cv::norm((*r)->render(still, nullptr), (*r)->render(one, nullptr), cv::NORM_INF), 1.0);
  // Moving: the needed sub-exposures follow the image motion.
  const int k = (*r)->sub_exposures_needed(T0, T1, 0.25);
  EXPECT_GE(k, 20);
  EXPECT_LE(k, 30);
  EXPECT_EQ((*r)->sub_exposures_needed(T0, T0, 0.25), 1);
  std::vector<Eigen::Isometry3d> subs;
  for (int i = 0; i < k; ++i) {
    const double f = (i + 0.5) / k;
    Eigen::Isometry3d T = T0;
    T.translation() = (1 - f) * T0.translation() + f * T1.translation();
    subs.push_back(T);
  }
  const cv::Mat blurred = (*r)->render(subs, nullptr);
  const cv::Mat sharp = (*r)->render(one, nullptr);
  // Blur lowers the local contrast: the image gradient energy drops.
  cv::Mat gb, gs;
  cv::Sobel(blurred, gb, CV_64F, 1, 0);
  cv::Sobel(sharp, gs, CV_64F, 1, 0);
  EXPECT_LT(cv::norm(gb), 0.8 * cv::norm(gs));
  // The blurred board's corners sit at the mid-exposure position (uniform motion).
  Eigen::Isometry3d Tmid = T0;
  Tmid.translation() = 0.5 * (T0.translation() + T1.translation());
  const Detection d = detect(blurred, t, (*r)->project_corners(Tmid));
  ASSERT_TRUE(d.found);
  EXPECT_LT(d.rms_px, 0.15);
}

// A rolling shutter: every row of the frame is the row of the image rendered at that row's pose
// (without lens blur, which mixes rows); the board moving during the readout is sheared.
TEST(CameraRender, RollingShutterRowsAreRenderedAtTheirOwnPoses) {
  const TargetDescription t = board();
  CameraRenderOptions opt;
  opt.optics_blur_sigma_px = 0.0;
  const CameraModel camera = radtan_camera();
  auto r = CheckerboardRenderer::create(camera, t, opt);
  ASSERT_TRUE(r.ok());
  const int h = camera.height;
  std::vector<Eigen::Isometry3d> rows;
  for (int y = 0; y < h; ++y)
    rows.push_back(
        pose(t, Eigen::Vector3d(0.1, 0.0, 0.0), 0.5, 0.02 * y / (h - 1), 0.0));  // ~12 px over the frame
  const cv::Mat rolling = (*r)->render_rows(rows, 1, nullptr);
  for (int y : {0, h / 3, h / 2, h - 1}) {
    const std::vector<Eigen::Isometry3d> one = {rows[static_cast<std::size_t>(y)]};
    const cv::Mat global = (*r)->render(one, nullptr);
    EXPECT_EQ(cv::norm(rolling.row(y), global.row(y), cv::NORM_INF), 0.0) << "row " << y;
  }
  // Not the global image of any one pose: the first and last rows come from poses 12 px apart.
  const std::vector<Eigen::Isometry3d> first = {rows.front()};
  EXPECT_GT(cv::norm(rolling, (*r)->render(first, nullptr), cv::NORM_INF), 100.0);
  // A pose list of the wrong length gives the background, not a read past its end.
  rows.pop_back();
  EXPECT_EQ(cv::countNonZero((*r)->render_rows(rows, 1, nullptr) != opt.appearance.background_dn), 0);
}

TEST(CameraRender, RejectsBadInput) {
  TargetDescription april;
  april.type = TargetDescription::Type::kAprilgrid;
  april.tag_cols = 6;
  april.tag_rows = 6;
  april.tag_size_m = 0.088;
  april.tag_spacing = 0.3;
  EXPECT_TRUE(CheckerboardRenderer::create(radtan_camera(), april, {}).ok()) << "AprilGrids render too";
  april.tag_size_m = 0.0;
  auto a = CheckerboardRenderer::create(radtan_camera(), april, {});
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.error().message.find("tagSize"), std::string::npos) << a.error().message;
  CameraRenderOptions opt;
  opt.supersampling = 0;
  auto b = CheckerboardRenderer::create(radtan_camera(), board(), opt);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().message.find("supersampling"), std::string::npos);
  CameraModel bad = radtan_camera();
  bad.width = 0;
  EXPECT_FALSE(CheckerboardRenderer::create(bad, board(), {}).ok());
}

}  // namespace
}  // namespace imucal::sim
