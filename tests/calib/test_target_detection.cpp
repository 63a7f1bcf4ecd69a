// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <thread>
#include <vector>

#include "calib/checkerboard_grid.hpp"
#include "calib/target_detection.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "sim/camera_render.hpp"
#include "sim/camimu.hpp"
#include "tests/calib/detection_helpers.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::calib {
namespace {

using sim::CheckerboardRenderer;
using namespace detection_test;  // NOLINT: the shared helpers
using sim::CornerTruth;

constexpr double kPi = std::numbers::pi;

// ---------------------------------------------------------------------------------------------
// Checkerboard, on frames of the virtual camera (sim/camera_render.hpp)

/// A WVGA (752 x 480) global-shutter camera with a wide lens, as on the rig.
CameraModel radtan_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics << 400.6, 399.6, 378.7, 235.1;
  c.distortion_coeffs << -0.2865, 0.0731, 2.1e-4, -3.4e-4;
  c.width = 752;
  c.height = 480;
  return c;
}

CameraModel equi_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kEquidistant;
  c.intrinsics << 460.0, 458.4, 374.2, 242.8;
  c.distortion_coeffs << 0.012, -0.004, 0.0021, -4e-4;
  c.width = 752;
  c.height = 480;
  return c;
}

TargetDescription checkerboard(int cols, int rows) {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = cols;
  t.rows = rows;
  t.col_spacing_m = 0.04;
  t.row_spacing_m = 0.04;
  return t;
}

/// Board centred `distance_m` ahead (offset sideways), turned by `roll` about the optical axis
/// and tilted by the rotation vector `tilt` (camera frame). Identity: the board's x to the
/// right and y down the image (its z away from the camera).
Eigen::Isometry3d board_pose(const TargetDescription& t, double roll, const Eigen::Vector3d& tilt,
                             double distance_m, double offset_x_m = 0.0, double offset_y_m = 0.0) {
  const Eigen::Vector3d centre((t.cols - 1) * t.col_spacing_m / 2, (t.rows - 1) * t.row_spacing_m / 2, 0.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translate(Eigen::Vector3d(offset_x_m, offset_y_m, distance_m));
  if (tilt.norm() > 0) T.rotate(Eigen::AngleAxisd(tilt.norm(), tilt.normalized()));
  T.rotate(Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()));
  T.translate(-centre);
  return T;
}

struct Frame {
  cv::Mat image;
  CornerTruth truth;
};

Frame render(const CheckerboardRenderer& r, const Eigen::Isometry3d& T, sim::Rng* rng = nullptr) {
  const std::vector<Eigen::Isometry3d> single = {T};
  return {r.render(single, rng), r.project_corners(T)};
}

std::unique_ptr<CheckerboardRenderer> make_renderer(const CameraModel& cam, const TargetDescription& t,
                                                    double noise_dn = 0.0) {
  sim::CameraRenderOptions opt;
  opt.supersampling = 4;
  opt.noise_sigma_dn = noise_dn;
  auto r = CheckerboardRenderer::create(cam, t, opt);
  EXPECT_TRUE(r.ok()) << r.error().message;
  return r.ok() ? std::move(*r) : nullptr;
}

/// Every corner found, under its own id, within `max_px` of the truth; the mean error.
double expect_full_board(const TargetDetector& det, const Frame& f, double max_px, const char* what) {
  auto obs = det.detect(view_of(f.image));
  EXPECT_TRUE(obs.ok()) << obs.error().message;
  if (!obs.ok()) return 1e9;
  const int n = det.target().point_count();
  EXPECT_EQ(static_cast<int>(obs->ids.size()), n) << what << ": board not found";
  if (static_cast<int>(obs->ids.size()) != n) return 1e9;
  for (int i = 0; i < n; ++i) EXPECT_EQ(obs->ids[i], i);
  EXPECT_EQ(obs->width, f.image.cols);
  const Errors e = errors(*obs, f.truth.px);
  EXPECT_LT(e.max_px, max_px) << what << ": ids not in the target's order, or a poor corner";
  return e.mean_px;
}

void expect_accurate(const CameraModel& cam, const char* name) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(cam, t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  const std::vector<Eigen::Isometry3d> poses = {
      board_pose(t, 0.0, Eigen::Vector3d::Zero(), 0.5),
      board_pose(t, 0.1, Eigen::Vector3d(0.35, -0.2, 0.0), 0.45, 0.04, -0.02),
      board_pose(t, -0.6, Eigen::Vector3d(-0.3, 0.45, 0.0), 0.55, -0.08, 0.03),
      board_pose(t, 1.2, Eigen::Vector3d(0.1, 0.25, 0.0), 0.4, 0.1, 0.05),  // into the distorted corner
      board_pose(t, 0.3, Eigen::Vector3d(0.5, 0.0, 0.0), 0.8, -0.15, -0.06),
  };
  double sum = 0.0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const Frame f = render(*r, poses[i]);
    ASSERT_EQ(f.truth.visible_count, t.point_count()) << "pose " << i;
    const double mean = expect_full_board(*det, f, 0.3, name);
    EXPECT_LT(mean, 0.1) << name << " pose " << i;
    sum += mean;
  }
  std::printf("%s: mean corner error %.4f px over %zu frames\n", name, sum / poses.size(), poses.size());
}

TEST(CheckerboardDetection, AccurateOnRadtanCamera) { expect_accurate(radtan_camera(), "radtan"); }

TEST(CheckerboardDetection, AccurateOnEquidistantCamera) { expect_accurate(equi_camera(), "equidistant"); }

// A board with an odd number of squares along one side and an even number along the other
// (cols + rows odd) looks different turned by 180 degrees: the ids follow the board whatever
// way round it is seen.
TEST(CheckerboardDetection, IdsFollowTheBoardAtAnyTurn) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  for (int k = 0; k < 12; ++k) {
    const double roll = k * kPi / 6 + 0.05;
    const Frame f = render(*r, board_pose(t, roll, Eigen::Vector3d(0.25, -0.15, 0.0), 0.5));
    expect_full_board(*det, f, 0.3, ("roll " + std::to_string(k * 30) + " deg").c_str());
  }
}

// Seen with its x axis to the left and the far corner's outer square cut by the image edge,
// the board's colours still decide: the ordering whose outer square is seen black beats the
// one whose outer square cannot be seen (in a recording such a frame turned half round and
// its pose 180 degrees, between frames of the right order).
TEST(CheckerboardDetection, ABoardCutAtItsFarCornerKeepsItsOrder) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  const int last = t.point_count() - 1;
  int tried = 0;
  // Upwards and to the left until the far corner (the last id, top left at this roll) lies
  // within 0.3-0.6 of a square's side from the top edge: its outer square leaves the image,
  // every inner corner stays in view.
  for (double up = 0.0; up < 0.3; up += 0.002) {
    const Eigen::Isometry3d T = board_pose(t, kPi + 0.08, Eigen::Vector3d(0.1, -0.1, 0.0), 0.45, -0.05, -up);
    const CornerTruth truth = r->project_corners(T);
    if (truth.visible_count != t.point_count()) break;
    const double side = (truth.px[last] - truth.px[last - 1]).norm();
    const double y = truth.px[last].y();
    if (y > 0.6 * side || y < 0.3 * side) continue;
    ++tried;
    const Frame f = render(*r, T);
    expect_full_board(*det, f, 0.3,
                      ("far corner " + std::to_string(y / side) + " sides below the edge").c_str());
  }
  EXPECT_GT(tried, 2);
}

// A board that a 180-degree turn maps onto itself (cols + rows even) cannot tell the two
// orderings apart: the detector reports the one whose x axis points to the right of the image.
TEST(CheckerboardDetection, SymmetricBoardTakesTheOrderingWithXToTheRight) {
  const TargetDescription t = checkerboard(7, 5);
  auto r = make_renderer(radtan_camera(), t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  const int n = t.point_count();
  for (const double roll : {0.0, 0.4, -0.5, kPi, kPi + 0.4}) {
    const Frame f = render(*r, board_pose(t, roll, Eigen::Vector3d(0.2, 0.1, 0.0), 0.5));
    auto obs = det->detect(view_of(f.image));
    ASSERT_TRUE(obs.ok());
    ASSERT_EQ(static_cast<int>(obs->ids.size()), n) << "roll " << roll;
    const bool x_right = std::cos(roll) > 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d truth = f.truth.px[x_right ? i : n - 1 - i];
      EXPECT_LT((obs->px[i] - truth).norm(), 0.3) << "roll " << roll << " id " << i;
    }
    EXPECT_GT(obs->px[t.cols - 1].x(), obs->px[0].x()) << "x axis must point to the right";
  }
}

// A square board with an odd number of squares a side tells quarter turns apart by its
// colours (a half turn it cannot: there the x-to-the-right rule decides, as above). At these
// turns the x axis of a quarter-turned ordering would point more to the right than the true
// one, so only the colour test gets them right.
TEST(CheckerboardDetection, SquareBoardQuarterTurns) {
  const TargetDescription t = checkerboard(5, 5);
  auto r = make_renderer(radtan_camera(), t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  for (const double roll : {0.2, kPi / 2 - 0.3, -kPi / 2 + 0.3}) {
    const Frame f = render(*r, board_pose(t, roll, Eigen::Vector3d(0.15, 0.2, 0.0), 0.45));
    expect_full_board(*det, f, 0.3, ("roll " + std::to_string(roll)).c_str());
  }
}

TEST(CheckerboardDetection, NoBoardGivesAnEmptyObservation) {
  const TargetDescription t = checkerboard(7, 6);
  auto det = make_detector(t);
  ASSERT_TRUE(det);
  cv::Mat grey(480, 752, CV_8U, cv::Scalar(105));
  cv::Mat noise(480, 752, CV_8U);
  cv::randu(noise, 0, 256);
  for (const cv::Mat& image : {grey, noise}) {
    auto obs = det->detect(view_of(image));
    ASSERT_TRUE(obs.ok()) << obs.error().message;
    EXPECT_TRUE(obs->empty());
    EXPECT_EQ(obs->width, 752);
  }
  // A board with a different number of corners is not this board.
  auto r = make_renderer(radtan_camera(), checkerboard(6, 5));
  ASSERT_TRUE(r);
  const Frame other = render(*r, board_pose(checkerboard(6, 5), 0.0, Eigen::Vector3d::Zero(), 0.5));
  auto obs = det->detect(view_of(other.image));
  ASSERT_TRUE(obs.ok());
  EXPECT_TRUE(obs->empty());
  // ... and the detector says what that board is; frames without a board, or with this board,
  // describe nothing.
  EXPECT_EQ(det->describe_other_target(view_of(other.image)), "a checkerboard of 6 x 5 inner corners");
  EXPECT_EQ(det->describe_other_target(view_of(grey)), "");
  EXPECT_EQ(det->describe_other_target(view_of(noise)), "");
  auto same = make_renderer(radtan_camera(), t);
  ASSERT_TRUE(same);
  const Frame own = render(*same, board_pose(t, 0.0, Eigen::Vector3d::Zero(), 0.5));
  EXPECT_EQ(det->describe_other_target(view_of(own.image)), "");
  // A larger board is named as well: the target file may be the smaller one.
  auto small = make_detector(checkerboard(4, 3));
  ASSERT_TRUE(small);
  EXPECT_EQ(small->describe_other_target(view_of(own.image)), "a checkerboard of 7 x 6 inner corners");
}

// OpenCV's detector needs every inner corner: a board cut by the image edge gives nothing
// (docs/targets.md, "Partial views").
TEST(CheckerboardDetection, BoardPartlyOutOfViewGivesNothing) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(equi_camera(), t);  // monotonic far out, unlike the wide radtan lens
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  const Frame f = render(*r, board_pose(t, 0.0, Eigen::Vector3d::Zero(), 0.45, 0.45, 0.0));
  ASSERT_GT(f.truth.visible_count, 0);
  ASSERT_LT(f.truth.visible_count, t.point_count());
  auto obs = det->detect(view_of(f.image));
  ASSERT_TRUE(obs.ok());
  EXPECT_TRUE(obs->empty());
  // The part in view is not taken for a smaller board.
  EXPECT_EQ(det->describe_other_target(view_of(f.image)), "");
}

TEST(CheckerboardDetection, NoisyFrames) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t, 2.0);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  sim::Rng rng(7);
  const Frame f = render(*r, board_pose(t, 0.3, Eigen::Vector3d(0.3, 0.2, 0.0), 0.6), &rng);
  EXPECT_LT(expect_full_board(*det, f, 0.5, "noise 2 DN"), 0.15);
}

// The committed camera-IMU fixture (fixtures/camimu.imulog: 376x240, wide radtan lens, motion
// blur): the whole board is on the sensor in each of its first 100 frames. With
// CALIB_CB_FAST_CHECK the detector found the board in only 84 of them (636 of 1169 over the
// recording); every frame must give the board, with ids and corners that match the truth
// projected by the renderer that drew the frames.
TEST(CheckerboardDetection, FindsTheBoardInTheFixtureFrames) {
  const std::string path = test::source_path("fixtures/camimu.imulog");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "fixture " << path << " is missing";
  auto reader = log::SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  auto cam_id = (*reader)->find_camera_stream("cam0");
  ASSERT_TRUE(cam_id.ok()) << cam_id.error().message;
  sim::CamImuSimOptions o;  // the fixture's settings: the defaults, seed 104
  o.seed = 104;
  auto motion = sim::CheckerboardMotion::create(o.motion, o.seed);
  ASSERT_TRUE(motion.ok()) << motion.error().message;
  const Eigen::Isometry3d T_world_board = (*motion)->T_world_board(o.target);
  auto renderer = sim::TargetRenderer::create(o.camera, o.target, sim::CameraRenderOptions{});
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  auto det = make_detector(o.target);
  ASSERT_TRUE(det);

  constexpr int kFrames = 100;
  int frames = 0, whole_board = 0, found = 0, matched = 0;
  double err_sum = 0.0;
  std::size_t err_n = 0;
  // Each frame twice: searched, and tracked from the two frames before (as calibrate camera
  // does within its batches); both must find the board with the truth's ids and corners.
  TargetObservation last, before_last;
  int tracked_found = 0, tracked_matched = 0;
  auto visited = (*reader)->for_each_frame(*cam_id, log::kTimeMin, log::kTimeMax, [&](const CameraFrame& f) {
    auto image = log::decode_image(f.data, log::ReadMode::kGray8);
    EXPECT_TRUE(image.ok()) << image.error().message;
    if (!image.ok()) return false;
    const sim::RigState s = (*motion)->at(f.t_ns + s_to_ns(o.timeshift_cam_imu_s));
    Eigen::Isometry3d T_world_body = Eigen::Isometry3d::Identity();
    T_world_body.linear() = s.q_world_body.toRotationMatrix();
    T_world_body.translation() = s.p_world_body;
    const sim::CornerTruth truth =
        (*renderer)->project_corners(o.T_cam_imu * T_world_body.inverse() * T_world_board);
    whole_board += truth.visible_count == o.target.point_count() ? 1 : 0;
    auto obs = det->detect(GrayView{image->data.data(), image->width, image->height, image->row_bytes()});
    EXPECT_TRUE(obs.ok());
    if (obs.ok() && !obs->empty()) {
      ++found;
      double worst = 0.0;
      for (std::size_t i = 0; i < obs->ids.size(); ++i) {
        const double e = (obs->px[i] - truth.px[obs->ids[i]]).norm();
        worst = std::max(worst, e);
        err_sum += e;
      }
      err_n += obs->ids.size();
      EXPECT_LT(worst, 0.5) << "frame " << frames << ": a corner is off or the ids are mis-ordered";
      matched += worst < 0.5 ? 1 : 0;
    }
    DetectionHistory history;
    history.t_ns = f.t_ns;
    history.last = last.empty() ? nullptr : &last;
    history.before_last = before_last.empty() || last.empty() ? nullptr : &before_last;
    auto tracked =
        det->detect(GrayView{image->data.data(), image->width, image->height, image->row_bytes()}, history);
    EXPECT_TRUE(tracked.ok());
    if (tracked.ok() && !tracked->empty()) {
      ++tracked_found;
      double worst = 0.0;
      for (std::size_t i = 0; i < tracked->ids.size(); ++i)
        worst = std::max(worst, (tracked->px[i] - truth.px[tracked->ids[i]]).norm());
      EXPECT_LT(worst, 0.5) << "frame " << frames << " tracked: a corner is off or the ids are mis-ordered";
      tracked_matched += worst < 0.5 ? 1 : 0;
      tracked->t_ns = f.t_ns;
      before_last = last;
      last = *tracked;
    } else {
      last = before_last = TargetObservation{};
    }
    return ++frames < kFrames;
  });
  EXPECT_EQ(tracked_found, kFrames);
  EXPECT_EQ(tracked_matched, tracked_found);
  ASSERT_TRUE(visited.ok()) << visited.error().message;
  ASSERT_EQ(frames, kFrames);
  EXPECT_EQ(whole_board, kFrames);
  EXPECT_EQ(found, whole_board) << "frames with the whole board in view where the detector found nothing";
  EXPECT_EQ(matched, found);
  ASSERT_GT(err_n, 0u);
  EXPECT_LT(err_sum / static_cast<double>(err_n), 0.1);
}

// A small board that moved further than the refinement window (a few pixels when the squares
// are 8 px): OpenCV's cornerSubPix puts a corner that wandered beyond its window back where it
// started, so the previous frame's corners came back unchanged and passed every check (one
// frame in 900 of a rendered recording, 5 px off). Such a track is searched instead.
TEST(CheckerboardDetection, ASmallBoardThatMovedBeyondTheWindowIsNotLeftBehind) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  const Eigen::Isometry3d before = board_pose(t, 0.3, Eigen::Vector3d(0.1, 0.05, 0.0), 1.8);
  const Frame first = render(*r, before);
  auto last = det->detect(view_of(first.image));
  ASSERT_TRUE(last.ok());
  ASSERT_EQ(static_cast<int>(last->ids.size()), t.point_count());
  const double side = (last->px[1] - last->px[0]).norm();
  ASSERT_LT(side, 10.0) << "the board must be small for this test";
  int checked = 0;
  for (int k = 0; k < 8; ++k) {
    // 0.5-0.8 of a square (4-7 px), in eight directions, along the image plane.
    const double a = k * kPi / 4 + 0.2;
    const double step_m = (0.5 + 0.05 * (k % 4)) * t.col_spacing_m;
    Eigen::Isometry3d moved = before;
    moved.pretranslate(Eigen::Vector3d(std::cos(a), std::sin(a), 0.0) * step_m);
    const Frame f = render(*r, moved);
    DetectionHistory h;
    h.last = &*last;
    auto obs = det->detect(view_of(f.image), h);
    ASSERT_TRUE(obs.ok());
    if (obs->empty()) continue;  // not found at all is allowed; found in the wrong place is not
    ++checked;
    const Errors e = errors(*obs, f.truth.px);
    EXPECT_LT(e.max_px, 0.3) << "direction " << k << ": the previous frame's corners came back";
  }
  EXPECT_GE(checked, 6);
}

// A history that is wrong (the board one square off, or somewhere else) is not followed: the
// frame is searched and the board reported with its own ids.
TEST(CheckerboardDetection, AWrongHistoryIsNotFollowed) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  const Frame f = render(*r, board_pose(t, 0.2, Eigen::Vector3d(0.05, 0.02, 0.0), 0.5));
  auto truth = det->detect(view_of(f.image));
  ASSERT_TRUE(truth.ok() && !truth->empty());
  // One square along the board's x axis: every corner lands on a neighbour.
  TargetObservation shifted = *truth;
  for (int r0 = 0; r0 < t.rows; ++r0) {
    for (int c = 0; c + 1 < t.cols; ++c) shifted.px[r0 * t.cols + c] = truth->px[r0 * t.cols + c + 1];
    const int e = r0 * t.cols + t.cols - 1;
    shifted.px[e] = 2.0 * truth->px[e] - truth->px[e - 1];
  }
  TargetObservation elsewhere = *truth;
  for (auto& p : elsewhere.px) p += Eigen::Vector2d(23.0, -17.0);
  for (const TargetObservation* wrong : {&shifted, &elsewhere}) {
    DetectionHistory h;
    h.last = wrong;
    auto obs = det->detect(view_of(f.image), h);
    ASSERT_TRUE(obs.ok());
    ASSERT_EQ(obs->ids, truth->ids);
    double worst = 0.0;
    for (std::size_t i = 0; i < obs->px.size(); ++i)
      worst = std::max(worst, (obs->px[i] - truth->px[i]).norm());
    EXPECT_LT(worst, 0.05);
  }
}

// ---------------------------------------------------------------------------------------------
// The junction grid (calib/checkerboard_grid.hpp), the checkerboard's first search

// Boards small, far and steeply tilted, where OpenCV's quad search (without its adaptive
// threshold, as the chain calls it) finds nothing and the old chain went on to the sector-based
// detector at about 100 ms a frame: every board that detector finds, the grid finds, and the
// detector's corners match the truth.
TEST(CheckerboardGrid, FindsTheBoardsTheQuadSearchMisses) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t, 1.0);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  sim::Rng rng(3);
  int missed_by_quads = 0;
  int found_by_sectors = 0;
  int found_by_grid = 0;
  const cv::Size pattern(t.cols, t.rows);
  for (double distance : {0.9, 1.3, 1.7}) {
    for (double tilt : {0.7, 0.9, 1.05}) {
      for (double roll : {0.3, 1.1}) {
        const Frame f = render(
            *r, board_pose(t, roll, Eigen::Vector3d(tilt, 0.4 * tilt, 0.0), distance, 0.05, 0.02), &rng);
        if (f.truth.visible_count != t.point_count()) continue;
        std::vector<cv::Point2f> px;
        if (cv::findChessboardCorners(f.image, pattern, px, 0)) continue;
        ++missed_by_quads;
        SCOPED_TRACE("distance " + std::to_string(distance) + " tilt " + std::to_string(tilt) + " roll " +
                     std::to_string(roll));
        const bool sectors = cv::findChessboardCornersSB(f.image, pattern, px, cv::CALIB_CB_NORMALIZE_IMAGE);
        const bool grid =
            find_checkerboard_grid(f.image, t.cols, t.rows).outcome == CheckerboardGrid::Outcome::kFound;
        found_by_sectors += sectors ? 1 : 0;
        found_by_grid += grid ? 1 : 0;
        if (sectors) {
          EXPECT_TRUE(grid) << "the sector-based detector finds this board, the grid does not";
        }
        if (grid) expect_full_board(*det, f, 0.5, "a board the quad search misses");
      }
    }
  }
  std::printf("boards the quad search misses: %d; the sector-based detector finds %d, the grid %d\n",
              missed_by_quads, found_by_sectors, found_by_grid);
  EXPECT_GE(found_by_sectors, 3) << "the poses no longer make the case this test is for";
}

// A fisheye lens bends a near board's rows by more than OpenCV's results are allowed (0.3 of a
// side): the junction grid's boards may bend to 0.6 when the refinement barely moved them (the
// real fisheye frames of docs/benchmarks.md bend by up to 0.4).
TEST(CheckerboardGrid, FindsAStronglyBentFisheyeBoard) {
  const TargetDescription t = checkerboard(7, 6);
  CameraModel fisheye = equi_camera();
  fisheye.intrinsics << 190.0, 190.0, 376.0, 240.0;  // about 200 degrees across the sensor
  auto r = make_renderer(fisheye, t, 1.0);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  sim::Rng rng(11);
  auto bend = [&](const std::vector<Eigen::Vector2d>& px) {
    double worst = 0.0;
    auto second = [&](const Eigen::Vector2d& a, const Eigen::Vector2d& p, const Eigen::Vector2d& b) {
      worst = std::max(worst, (a + b - 2.0 * p).norm() / (0.5 * ((a - p).norm() + (b - p).norm())));
    };
    for (int row = 0; row < t.rows; ++row) {
      for (int c = 0; c < t.cols; ++c) {
        const int i = row * t.cols + c;
        if (c > 0 && c + 1 < t.cols) second(px[i - 1], px[i], px[i + 1]);
        if (row > 0 && row + 1 < t.rows) second(px[i - t.cols], px[i], px[i + t.cols]);
      }
    }
    return worst;
  };
  int bent = 0;
  for (double distance : {0.12, 0.15, 0.2}) {
    for (double x : {0.0, 0.06}) {
      const Frame f =
          render(*r, board_pose(t, 0.2, Eigen::Vector3d(0.2, -0.1, 0.0), distance, x, 0.02), &rng);
      if (f.truth.visible_count != t.point_count() || bend(f.truth.px) <= 0.3) continue;
      ++bent;
      SCOPED_TRACE("distance " + std::to_string(distance) + " offset " + std::to_string(x) + ", bend " +
                   std::to_string(bend(f.truth.px)));
      expect_full_board(*det, f, 0.5, "a fisheye board");
    }
  }
  std::printf("fisheye boards bent by more than 0.3 of a side: %d\n", bent);
  EXPECT_GE(bent, 2) << "the poses no longer make the case this test is for";
}

// A dim board in clutter: crossing bars all around it give thousands of saddle points, many
// stronger than the board's junctions; only the strongest are kept and tried, and the board's
// are among them.
TEST(CheckerboardGrid, FindsABoardAmongCrossingBars) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t, 1.0);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  sim::Rng rng(21);
  Frame f = render(*r, board_pose(t, 0.4, Eigen::Vector3d(0.3, -0.2, 0.0), 1.1, 0.05, 0.0), &rng);
  ASSERT_EQ(f.truth.visible_count, t.point_count());
  // The board's box, with a margin of two squares; bars everywhere else.
  cv::Rect2d box(f.truth.px[0].x(), f.truth.px[0].y(), 0, 0);
  for (const Eigen::Vector2d& p : f.truth.px) box |= cv::Rect2d(p.x(), p.y(), 1, 1);
  const double square = (f.truth.px[1] - f.truth.px[0]).norm();
  const cv::Rect keep(
      cv::Point(static_cast<int>(box.x - 2 * square), static_cast<int>(box.y - 2 * square)),
      cv::Point(static_cast<int>(box.br().x + 2 * square), static_cast<int>(box.br().y + 2 * square)));
  cv::Mat bars = f.image.clone();
  cv::RNG bar_rng(8);
  for (int i = 0; i < 150; ++i) {
    const cv::Point a(bar_rng.uniform(0, bars.cols), bar_rng.uniform(0, bars.rows));
    const cv::Point b(bar_rng.uniform(0, bars.cols), bar_rng.uniform(0, bars.rows));
    cv::line(bars, a, b, cv::Scalar(i % 2 == 0 ? 15 : 240), bar_rng.uniform(1, 6), cv::LINE_AA);
  }
  cv::Mat noise(bars.size(), CV_8U);
  cv::randn(noise, 0, 3);
  bars += noise;
  // The board at half its contrast (dim, far from the light): hundreds of the bars' crossings
  // are stronger than its junctions (300 kept junctions miss it; at a quarter of its contrast
  // it takes about 5000, more than are kept: docs/targets.md).
  const cv::Rect inside = keep & cv::Rect(0, 0, bars.cols, bars.rows);
  cv::Mat dim;
  f.image(inside).convertTo(dim, CV_8U, 0.5, 0.5 * 128);
  dim.copyTo(bars(inside));
  f.image = bars;
  const CheckerboardGrid grid = find_checkerboard_grid(f.image, t.cols, t.rows);
  EXPECT_EQ(grid.outcome, CheckerboardGrid::Outcome::kFound);
  expect_full_board(*det, f, 0.5, "a board among crossing bars");
}

// A grid that stops at a lost junction (glare on one corner) leaves the board to OpenCV's quad
// search, which looks only in the region where the rest of the board can be: the grid's box
// grown by the rows it lacks and two squares, not the whole image (on a 1280 x 720 photograph
// the searches after such a grid cost 300 ms before they were bounded: docs/benchmarks.md).
TEST(CheckerboardGrid, AGridStoppedAtALostJunctionIsSearchedOnlyAroundIt) {
  const TargetDescription t = checkerboard(7, 6);
  auto r = make_renderer(radtan_camera(), t, 1.0);
  auto det = make_detector(t);
  ASSERT_TRUE(r && det);
  sim::Rng rng(5);
  Frame f = render(*r, board_pose(t, 0.2, Eigen::Vector3d(0.2, -0.1, 0.0), 1.0, 0.1, 0.05), &rng);
  ASSERT_EQ(f.truth.visible_count, t.point_count());
  const CheckerboardGrid whole = find_checkerboard_grid(f.image, t.cols, t.rows);
  ASSERT_EQ(whole.outcome, CheckerboardGrid::Outcome::kFound);
  EXPECT_EQ(fallback_region(whole, t.cols, t.rows, f.image.size()),
            cv::Rect(0, 0, f.image.cols, f.image.rows));
  // Glare on one inner corner of the last row: its squares at a seventh of their contrast
  // within half a square of it. Its saddle is then a fiftieth of its neighbours' and the grid
  // stops short of it; OpenCV's threshold still splits its squares.
  const double square = (f.truth.px[1] - f.truth.px[0]).norm();
  const Eigen::Vector2d lost = f.truth.px[5 * t.cols + 3];
  for (int y = 0; y < f.image.rows; ++y) {
    for (int x = 0; x < f.image.cols; ++x) {
      if (std::hypot(x - lost.x(), y - lost.y()) > 0.5 * square) continue;
      auto& v = f.image.at<std::uint8_t>(y, x);
      v = cv::saturate_cast<std::uint8_t>(128.0 + (v - 128.0) / 7.0);
    }
  }
  const CheckerboardGrid grid = find_checkerboard_grid(f.image, t.cols, t.rows);
  ASSERT_EQ(grid.outcome, CheckerboardGrid::Outcome::kUndecided);
  ASSERT_GE(2 * grid.grid_cols * grid.grid_rows, t.point_count())
      << "the case this test is for: a large grid";
  ASSERT_EQ(grid.corners.size(), static_cast<std::size_t>(grid.grid_cols * grid.grid_rows));
  for (const cv::Point2f& p : grid.corners) {
    double best = 1e9;
    for (const Eigen::Vector2d& q : f.truth.px) best = std::min(best, std::hypot(p.x - q.x(), p.y - q.y()));
    EXPECT_LT(best, 0.5) << "the undecided grid's junctions are the board's";
  }
  const cv::Rect region = fallback_region(grid, t.cols, t.rows, f.image.size());
  std::printf("undecided grid %d x %d; region %d x %d of %d x %d\n", grid.grid_cols, grid.grid_rows,
              region.width, region.height, f.image.cols, f.image.rows);
  EXPECT_LT(region.area(), f.image.cols * f.image.rows / 3) << "the search after the grid is not bounded";
  // The whole board and its outer squares are inside.
  for (const Eigen::Vector2d& q : f.truth.px) {
    EXPECT_TRUE(
        region.contains(cv::Point(static_cast<int>(q.x() - square), static_cast<int>(q.y() - square))));
    EXPECT_TRUE(
        region.contains(cv::Point(static_cast<int>(q.x() + square), static_cast<int>(q.y() + square))));
  }
  // The quad search in that region finds the board: every corner, refined at full size.
  expect_full_board(*det, f, 0.5, "a board with a lost junction");
}

// The grid says when the slower searches cannot find the board, so that they are not run.
TEST(CheckerboardGrid, SaysWhyThereIsNoBoardToSearchFor) {
  using Outcome = CheckerboardGrid::Outcome;
  const TargetDescription t = checkerboard(7, 6);
  cv::Mat grey(480, 752, CV_8U, cv::Scalar(105));
  EXPECT_EQ(find_checkerboard_grid(grey, 7, 6).outcome, Outcome::kNone);
  cv::Mat noise(480, 752, CV_8U);
  cv::randu(noise, 0, 256);
  EXPECT_NE(find_checkerboard_grid(noise, 7, 6).outcome, Outcome::kFound);
  // Crossing black and white bars: many junctions, some in line, no board.
  cv::Mat bars(480, 752, CV_8U, cv::Scalar(128));
  cv::RNG bar_rng(5);
  for (int i = 0; i < 60; ++i) {
    const cv::Point a(bar_rng.uniform(0, 752), bar_rng.uniform(0, 480));
    const cv::Point b(bar_rng.uniform(0, 752), bar_rng.uniform(0, 480));
    cv::line(bars, a, b, cv::Scalar(i % 2 == 0 ? 20 : 235), bar_rng.uniform(2, 12), cv::LINE_AA);
  }
  const CheckerboardGrid crossing = find_checkerboard_grid(bars, 7, 6);
  EXPECT_NE(crossing.outcome, Outcome::kFound);
  EXPECT_LT(2 * crossing.grid_cols * crossing.grid_rows, t.point_count())
      << "would send bars to the slow search";
  // A board cut by the image's border.
  auto equi = make_renderer(equi_camera(), t);
  ASSERT_TRUE(equi);
  const Frame cut = render(*equi, board_pose(t, 0.0, Eigen::Vector3d::Zero(), 0.45, 0.45, 0.0));
  ASSERT_LT(cut.truth.visible_count, t.point_count());
  EXPECT_EQ(find_checkerboard_grid(cut.image, 7, 6).outcome, Outcome::kCut);
  // A whole board of another size, either way round.
  auto other = make_renderer(radtan_camera(), checkerboard(6, 5));
  ASSERT_TRUE(other);
  const Frame six = render(*other, board_pose(checkerboard(6, 5), 0.4, Eigen::Vector3d(0.2, 0.1, 0.0), 0.5));
  const CheckerboardGrid g = find_checkerboard_grid(six.image, 7, 6);
  EXPECT_EQ(g.outcome, Outcome::kOther);
  EXPECT_EQ(std::max(g.grid_cols, g.grid_rows), 6);
  EXPECT_EQ(std::min(g.grid_cols, g.grid_rows), 5);
  // The board itself: its corners, each near a true corner.
  auto own = make_renderer(radtan_camera(), t);
  ASSERT_TRUE(own);
  const Frame f = render(*own, board_pose(t, 2.5, Eigen::Vector3d(-0.3, 0.3, 0.0), 0.6));
  const CheckerboardGrid found = find_checkerboard_grid(f.image, 7, 6);
  ASSERT_EQ(found.outcome, Outcome::kFound);
  ASSERT_EQ(found.corners.size(), 42u);
  for (const cv::Point2f& p : found.corners) {
    double best = 1e9;
    for (const Eigen::Vector2d& q : f.truth.px) best = std::min(best, std::hypot(p.x - q.x(), p.y - q.y()));
    EXPECT_LT(best, 0.5);
  }
}

TEST(TargetDetection, RefusesBadInput) {
  EXPECT_FALSE(TargetDetector::create(checkerboard(7, 1)).ok());
  EXPECT_FALSE(TargetDetector::create(checkerboard(2, 6)).ok());
  DetectionOptions opt;
  opt.min_tags = 0;
  EXPECT_FALSE(TargetDetector::create(checkerboard(7, 6), opt).ok());
  auto det = make_detector(checkerboard(7, 6));
  ASSERT_TRUE(det);
  EXPECT_FALSE(det->detect(GrayView{}).ok());
  std::vector<std::uint8_t> pixels(100, 0);
  EXPECT_FALSE(det->detect(GrayView{pixels.data(), 10, 10, 5}).ok());  // stride < width
}

}  // namespace
}  // namespace imucal::calib
