// SPDX-License-Identifier: BSD-3-Clause
// AprilGrid detection on images of Kalibr's targets drawn here (tests/calib/aprilgrid_image.hpp):
// the tags, their ids and corners at any turn, half-resolution search, the region of the frame
// before, partial views and tags off the grid.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <thread>
#include <vector>

#include "calib/target_detection.hpp"
#include "tests/calib/aprilgrid_image.hpp"
#include "tests/calib/detection_helpers.hpp"

namespace imucal::calib {
namespace {

using namespace detection_test;  // NOLINT: the shared helpers

// ---------------------------------------------------------------------------------------------
// AprilGrid, on images of known geometry (tests/calib/aprilgrid_image.hpp)

TargetDescription aprilgrid() {
  TargetDescription t;
  t.type = TargetDescription::Type::kAprilgrid;
  t.tag_cols = 6;
  t.tag_rows = 6;
  t.tag_size_m = 0.088;  // Kalibr's example grid
  t.tag_spacing = 0.3;
  return t;
}

const Eigen::Vector4d kPinhole(450.0, 450.0, 375.5, 239.5);

/// The grid centred `distance_m` ahead, seen from its printed side (its z towards the
/// camera), turned by `roll` about the optical axis and tilted by `tilt`; roll 0 shows the page
/// upright.
Eigen::Matrix3d grid_homography(const TargetDescription& t, double roll, const Eigen::Vector3d& tilt,
                                double distance_m, double offset_x_m = 0.0, double offset_y_m = 0.0) {
  const double pitch = t.tag_size_m * (1 + t.tag_spacing);
  const Eigen::Vector3d centre((t.tag_cols * pitch - t.tag_spacing * t.tag_size_m) / 2,
                               (t.tag_rows * pitch - t.tag_spacing * t.tag_size_m) / 2, 0.0);
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (tilt.norm() > 0) R = Eigen::AngleAxisd(tilt.norm(), tilt.normalized()).toRotationMatrix();
  R = R * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
      Eigen::Vector3d(1, -1, -1).asDiagonal();  // page upright: target y up the image
  const Eigen::Vector3d t_cam = Eigen::Vector3d(offset_x_m, offset_y_m, distance_m) - R * centre;
  return test::plane_homography(kPinhole, R, t_cam);
}

/// Kalibr prints tag36h11 from its own code table (kalibr_create_target_pdf, the codes of the
/// AprilTags C++ library): data bit (row r, column c) of the upright tag, r from the top, is
/// black when bit 35 - (6 r + c) of the code is 0. libapriltag 3 stores the codes in another
/// bit order; the tags it draws (and detects) must be the ones Kalibr prints.
TEST(AprilGridImage, TagsAreTheOnesKalibrPrints) {
  const std::uint64_t kalibr_codes[] = {0xd5d628584ULL, 0xd97f18b49ULL, 0xdd280910eULL, 0xe479e9c98ULL};
  for (int id = 0; id < 4; ++id) {
    const auto bits = test::tag36h11_bits(id);
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) {
        const bool kalibr_white = ((kalibr_codes[id] >> (35 - (6 * r + c))) & 1U) != 0;
        EXPECT_EQ(bits[r][c], kalibr_white) << "tag " << id << " bit " << r << "," << c;
      }
    }
  }
}

struct GridResult {
  TargetObservation obs;
  Errors err;
};

GridResult detect_grid(const TargetDetector& det, const test::AprilGridImage& img) {
  auto obs = det.detect(view_of(img.image));
  EXPECT_TRUE(obs.ok()) << obs.error().message;
  if (!obs.ok()) return {};
  EXPECT_TRUE(std::is_sorted(obs->ids.begin(), obs->ids.end()));
  return {*obs, errors(*obs, img.px)};
}

// Every tag found is reported under its own ids at any turn of the grid (this pins
// libapriltag's corner order and y axis against tag_point_ids()), with subpixel corners. With
// the grid's edges along the image axes every tag is found; near 45 degrees libapriltag loses
// some tags whose corners touch the corner squares along a pixel row or column
// (docs/targets.md has the rates), so there half of them are asked for.
TEST(AprilGridDetection, IdsAndAccuracyAtAnyTurn) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  double sum = 0.0;
  int frames = 0;
  for (int k = 0; k < 8; ++k) {
    const double roll = k * std::numbers::pi / 4 + 0.1;
    const Eigen::Vector3d tilt =
        k % 2 == 0 ? Eigen::Vector3d(0.3, -0.2, 0.0) : Eigen::Vector3d(-0.2, 0.35, 0.0);
    const test::AprilGridImage img = test::render_aprilgrid(t, grid_homography(t, roll, tilt, 0.95));
    ASSERT_TRUE(std::all_of(img.inside.begin(), img.inside.end(), [](std::uint8_t v) { return v != 0; }))
        << "pose " << k << " must keep the grid in view";
    const GridResult g = detect_grid(*det, img);
    if (k % 2 == 0) {
      EXPECT_EQ(static_cast<int>(g.obs.ids.size()), t.point_count()) << "roll " << k * 45 << " deg";
    } else {
      EXPECT_GE(static_cast<int>(g.obs.ids.size()), t.point_count() / 2) << "roll " << k * 45 << " deg";
    }
    EXPECT_LT(g.err.max_px, 0.5) << "roll " << k * 45 << " deg";
    EXPECT_LT(g.err.mean_px, 0.1) << "roll " << k * 45 << " deg";
    sum += g.err.mean_px;
    ++frames;
  }
  std::printf("aprilgrid: mean corner error %.4f px over %d frames\n", sum / frames, frames);
}

// Large tags: with a frame before as history the quads are searched at half resolution
// (kCoarseTagEdgePx), at about a third of the cost; nearly all the tags are kept (at least 90 %,
// else the full search runs as well), no tag the full search did not find appears, and the
// corners, refined on the full image, are as accurate.
TEST(AprilGridDetection, LargeTagsAreSearchedAtHalfResolutionWithTheSameCornersAndAccuracy) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  DetectionOptions half_options;
  half_options.aprilgrid_decimate = 2.0;
  auto half = TargetDetector::create(t, half_options);
  ASSERT_TRUE(half.ok());
  int compared = 0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d tilt(0.25 - 0.1 * k, 0.1 * k - 0.15, 0.0);
    const test::AprilGridImage img = test::render_aprilgrid(t, grid_homography(t, 0.05 * k, tilt, 0.9));
    const auto full = det->detect(view_of(img.image));
    ASSERT_TRUE(full.ok() && !full->empty());
    // The history: this frame's own full detection (tags of about 50 px at 0.9 m).
    DetectionHistory h;
    h.last = &*full;
    const auto coarse = det->detect(view_of(img.image), h);
    ASSERT_TRUE(coarse.ok());
    // What the history chose is the half-resolution search (it kept enough tags here).
    const auto at_half = (*half)->detect(view_of(img.image));
    ASSERT_TRUE(at_half.ok());
    EXPECT_EQ(coarse->ids, at_half->ids) << "frame " << k;
    EXPECT_GE(10 * coarse->ids.size(), 9 * full->ids.size()) << "frame " << k;
    EXPECT_TRUE(std::includes(full->ids.begin(), full->ids.end(), coarse->ids.begin(), coarse->ids.end()))
        << "frame " << k;
    const Errors ef = errors(*full, img.px), ec = errors(*coarse, img.px);
    EXPECT_LT(ec.max_px, 0.5) << "frame " << k;
    EXPECT_LT(ec.mean_px, ef.mean_px + 0.02) << "frame " << k;
    ++compared;
  }
  EXPECT_EQ(compared, 4);
}

// With a frame before, only the region where it puts the grid is searched: the same tags and
// corners as the whole image's search; a grid that moved out of that region is found by the
// whole image's search after all.
TEST(AprilGridDetection, TheRegionOfTheFrameBeforeGivesTheSameTagsAndAGridThatMovedIsStillFound) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  // Far enough that the grid covers under half the image and its tags stay under 28 px (the
  // half-resolution search is not chosen, so only the region differs).
  const test::AprilGridImage left =
      test::render_aprilgrid(t, grid_homography(t, 0.1, {0.1, -0.2, 0.0}, 2.2, -0.35));
  const test::AprilGridImage right =
      test::render_aprilgrid(t, grid_homography(t, -0.1, {0.0, 0.2, 0.0}, 2.2, 0.35));
  const auto full = det->detect(view_of(left.image));
  const auto moved_full = det->detect(view_of(right.image));
  ASSERT_TRUE(full.ok() && moved_full.ok());
  ASSERT_GE(full->ids.size(), 100u);
  ASSERT_GE(moved_full->ids.size(), 100u);
  DetectionHistory h;
  h.last = &*full;
  const auto again = det->detect(view_of(left.image), h);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->ids, full->ids);
  for (std::size_t i = 0; i < again->px.size() && i < full->px.size(); ++i) {
    EXPECT_LT((again->px[i] - full->px[i]).norm(), 1e-3) << "point " << again->ids[i];
  }
  // The grid jumped to the other side of the image: the region finds no tag, the image all.
  const auto jumped = det->detect(view_of(right.image), h);
  ASSERT_TRUE(jumped.ok());
  EXPECT_EQ(jumped->ids, moved_full->ids);
  EXPECT_LT(errors(*jumped, right.px).max_px, 0.5);
}

// libapriltag's corners without refinement: the right ids, and pixel centres moved to OpenCV's
// convention (integer = centre). A half-pixel slip would show as a mean offset of (0.5, 0.5).
TEST(AprilGridDetection, RawCornersInOpenCvPixelConvention) {
  const TargetDescription t = aprilgrid();
  DetectionOptions opt;
  opt.subpixel = false;
  auto det = make_detector(t, opt);
  ASSERT_TRUE(det);
  const test::AprilGridImage img =
      test::render_aprilgrid(t, grid_homography(t, 0.2, Eigen::Vector3d(0.2, 0.1, 0), 0.9));
  const GridResult g = detect_grid(*det, img);
  ASSERT_EQ(static_cast<int>(g.obs.ids.size()), t.point_count());
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < g.obs.ids.size(); ++i) mean += g.obs.px[i] - img.px[g.obs.ids[i]];
  mean /= static_cast<double>(g.obs.ids.size());
  EXPECT_LT(mean.norm(), 0.15) << "mean offset " << mean.transpose();
  EXPECT_LT(g.err.max_px, 1.0);
  std::printf("aprilgrid raw corners: mean error %.3f px, mean offset (%.3f, %.3f) px\n", g.err.mean_px,
              mean.x(), mean.y());
}

// A tag corner is kept only on an X junction of the grid (the tag's border and a corner square
// dark, the gaps bright). libapriltag fitted one quad 4 px off on a steep, distorted view of the
// second generator's frames (docs/benchmarks.md), and cornerSubPix, inside the tag's border,
// left its corners there. Here one corner square is printed white: the four tags around it meet
// the page at an L-shaped corner instead, and only they are left out.
TEST(AprilGridDetection, TagCornersOffTheGridsJunctionsAreLeftOut) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  const Eigen::Matrix3d H = grid_homography(t, 0.1, Eigen::Vector3d(0.15, 0.1, 0), 0.9);
  test::AprilGridImage img = test::render_aprilgrid(t, H);
  ASSERT_EQ(static_cast<int>(detect_grid(*det, img).obs.ids.size()), t.point_count());
  // The square between tags (2, 2), (3, 2), (2, 3) and (3, 3) (column, row from the bottom).
  const double pitch = t.tag_size_m * (1 + t.tag_spacing);
  const double x0 = 2 * pitch + t.tag_size_m;
  const double y0 = 2 * pitch + t.tag_size_m;
  std::vector<cv::Point> square;
  for (const auto& [x, y] : {std::pair{x0, y0},
                             {x0 + t.tag_spacing * t.tag_size_m, y0},
                             {x0 + t.tag_spacing * t.tag_size_m, y0 + t.tag_spacing * t.tag_size_m},
                             {x0, y0 + t.tag_spacing * t.tag_size_m}}) {
    const Eigen::Vector3d q = H * Eigen::Vector3d(x, y, 1.0);
    square.emplace_back(static_cast<int>(std::lround(q.x() / q.z())),
                        static_cast<int>(std::lround(q.y() / q.z())));
  }
  cv::fillConvexPoly(img.image, square, cv::Scalar(215), cv::LINE_8);
  const GridResult g = detect_grid(*det, img);
  std::vector<int> tags;  // the tag of each point (tag_point_ids: two point rows and columns a tag)
  for (const int id : g.obs.ids) {
    const int point_row = id / (2 * t.tag_cols);
    const int point_col = id % (2 * t.tag_cols);
    tags.push_back((point_row / 2) * t.tag_cols + point_col / 2);
  }
  for (int tag : {2 * 6 + 2, 2 * 6 + 3, 3 * 6 + 2, 3 * 6 + 3}) {
    EXPECT_EQ(std::count(tags.begin(), tags.end(), tag), 0) << "tag " << tag << " touches the white square";
  }
  EXPECT_EQ(static_cast<int>(g.obs.ids.size()), t.point_count() - 16);
  EXPECT_LT(g.err.max_px, 0.5);
}

// A dim grid of little contrast (a dark room: black 35 grey levels, white 60 or 48, lens blur
// and noise) is found as with libapriltag's own threshold setting: the detector raises the
// difference between a tile's brightest and darkest that libapriltag needs (to skip textured
// backgrounds, docs/targets.md, settings): at 12 it finds what the default 5 finds, at 20 the
// grid 13 grey levels apart gives 8 and 16 points instead of 44 and 52.
TEST(AprilGridDetection, ADimGridLosesNoTagToTheRaisedThreshold) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  struct Case {
    double white_dn;
    double distance_m;
    int at_least;  // points: what libapriltag's default threshold (5) gives
  };
  for (const Case& c :
       {Case{60.0, 0.8, 128}, Case{60.0, 1.4, 132}, Case{48.0, 0.8, 44}, Case{48.0, 1.4, 52}}) {
    test::AprilGridImageOptions dim;
    dim.white_dn = c.white_dn;
    dim.black_dn = 35.0;
    dim.background_dn = 30.0;
    dim.blur_sigma_px = 0.8;
    test::AprilGridImage img =
        test::render_aprilgrid(t, grid_homography(t, 0.1, Eigen::Vector3d(0.2, 0.15, 0), c.distance_m), dim);
    cv::Mat noise(img.image.size(), CV_16S);
    cv::RNG rng(7);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.5);
    cv::Mat noisy;
    img.image.convertTo(noisy, CV_16S);
    noisy += noise;
    noisy.convertTo(img.image, CV_8U);
    const GridResult g = detect_grid(*det, img);
    EXPECT_GE(static_cast<int>(g.obs.ids.size()), c.at_least)
        << "white " << c.white_dn << " at " << c.distance_m << " m";
    EXPECT_LT(g.err.max_px, c.white_dn > 50.0 ? 0.5 : 1.0)
        << "white " << c.white_dn << " at " << c.distance_m << " m";
    std::printf("dim aprilgrid, white %.0f at %.1f m: %zu points, worst corner %.2f px\n", c.white_dn,
                c.distance_m, g.obs.ids.size(), g.err.max_px);
  }
}

TEST(AprilGridDetection, PartialViewGivesTheTagsInView) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  // The grid's centre at the right edge of the image: about half of it out of view.
  const test::AprilGridImage img =
      test::render_aprilgrid(t, grid_homography(t, 0.15, Eigen::Vector3d(0.1, 0.2, 0), 0.75, 0.62, 0.0));
  int inside = 0;
  for (auto v : img.inside) inside += v;
  ASSERT_GT(inside, t.point_count() / 4);
  ASSERT_LT(inside, 3 * t.point_count() / 4);
  const GridResult g = detect_grid(*det, img);
  EXPECT_GE(static_cast<int>(g.obs.ids.size()), inside / 2) << "too few of the tags in view";
  for (int id : g.obs.ids) EXPECT_TRUE(img.inside[id]) << "point " << id << " is not in the image";
  EXPECT_LT(g.err.max_px, 0.5);
  EXPECT_LT(g.err.mean_px, 0.1);
}

TEST(AprilGridDetection, TagsNotOnTheGridAreIgnored) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  test::AprilGridImageOptions opt;
  for (int i = 0; i < t.tag_cols * t.tag_rows; ++i) opt.tag_ids.push_back(i);
  opt.tag_ids[0] = 40;  // a valid tag36h11 code, beyond this grid's 36 tags
  opt.tag_ids[7] = 3;   // a second tag 3: a stray copy, both dropped
  const test::AprilGridImage img =
      test::render_aprilgrid(t, grid_homography(t, 0.0, Eigen::Vector3d(0.1, 0.1, 0), 0.95), opt);
  const GridResult g = detect_grid(*det, img);
  const auto tag0 = t.tag_point_ids(0);
  const auto tag3 = t.tag_point_ids(3);
  const auto tag7 = t.tag_point_ids(7);
  for (int id : g.obs.ids) {
    EXPECT_EQ(std::count(tag0.begin(), tag0.end(), id), 0) << "tag 0's position shows id 40";
    EXPECT_EQ(std::count(tag3.begin(), tag3.end(), id), 0) << "tag 3 is seen twice";
    EXPECT_EQ(std::count(tag7.begin(), tag7.end(), id), 0) << "position 7 shows tag 3";
  }
  EXPECT_GE(static_cast<int>(g.obs.ids.size()), 4 * 28) << "the other tags must still be found";
  EXPECT_LT(g.err.max_px, 0.5);
  // One tag of another grid among 35 of this one: this grid, nothing else to say.
  EXPECT_EQ(det->describe_other_target(view_of(img.image)), "");
}

// A grid whose tags mostly have ids beyond the target file's grid is named.
TEST(AprilGridDetection, ALargerGridIsDescribed) {
  TargetDescription small = aprilgrid();
  small.tag_cols = 3;
  small.tag_rows = 3;
  auto det = make_detector(small);
  ASSERT_TRUE(det);
  const TargetDescription t = aprilgrid();
  const test::AprilGridImage img =
      test::render_aprilgrid(t, grid_homography(t, 0.0, Eigen::Vector3d(0.1, 0.1, 0), 0.95), {});
  EXPECT_EQ(det->describe_other_target(view_of(img.image)),
            "an AprilGrid with tag ids up to 35 (at least 36 tags)");
}

TEST(AprilGridDetection, FewerTagsThanTheMinimumGiveNothing) {
  const TargetDescription t = aprilgrid();
  cv::Mat grey(480, 752, CV_8U, cv::Scalar(105));
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  auto none = det->detect(view_of(grey));
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
  DetectionOptions opt;
  opt.min_tags = 37;  // more than the grid has
  auto strict = make_detector(t, opt);
  ASSERT_TRUE(strict);
  const test::AprilGridImage img =
      test::render_aprilgrid(t, grid_homography(t, 0.0, Eigen::Vector3d::Zero(), 0.95));
  auto obs = strict->detect(view_of(img.image));
  ASSERT_TRUE(obs.ok());
  EXPECT_TRUE(obs->empty());
}

// detect() is const and runs on many threads at once (each borrows its own libapriltag
// detector): the results equal a single thread's.
TEST(AprilGridDetection, ConcurrentCallsAgree) {
  const TargetDescription t = aprilgrid();
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  const test::AprilGridImage img =
      test::render_aprilgrid(t, grid_homography(t, 0.3, Eigen::Vector3d(0.2, 0, 0), 0.9));
  auto ref = det->detect(view_of(img.image));
  ASSERT_TRUE(ref.ok());
  ASSERT_FALSE(ref->empty());
  std::vector<std::thread> threads;
  std::vector<int> mismatches(4, 0);
  for (int k = 0; k < 4; ++k) {
    threads.emplace_back([&, k] {
      for (int rep = 0; rep < 3; ++rep) {
        auto obs = det->detect(view_of(img.image));
        if (!obs.ok() || obs->ids != ref->ids || obs->px != ref->px) ++mismatches[k];
      }
    });
  }
  for (auto& th : threads) th.join();
  for (int k = 0; k < 4; ++k) EXPECT_EQ(mismatches[k], 0) << "thread " << k;
}

}  // namespace
}  // namespace imucal::calib
