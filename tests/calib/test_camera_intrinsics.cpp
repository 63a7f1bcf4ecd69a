// SPDX-License-Identifier: BSD-3-Clause
// Camera intrinsics on synthetic observations: target points projected through a known camera at
// known poses, with pixel noise; the estimate must hold the truth within its reported sigmas.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "calib/camera_intrinsics.hpp"
#include "tests/support/board_view.hpp"

namespace imucal::calib {
namespace {

TargetDescription board() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 8;
  t.rows = 6;
  t.col_spacing_m = 0.04;
  t.row_spacing_m = 0.04;
  return t;
}

CameraModel radtan_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.width = 640;
  c.height = 480;
  c.intrinsics = {500.0, 502.0, 322.0, 238.0};
  c.distortion_coeffs = {-0.28, 0.08, 0.0005, -0.0003};
  return c;
}

CameraModel equi_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kEquidistant;
  c.width = 640;
  c.height = 480;
  c.intrinsics = {260.0, 261.0, 318.0, 243.0};
  c.distortion_coeffs = {0.02, -0.01, 0.004, -0.001};
  return c;
}

struct SynthOptions {
  int views = 25;
  double noise_px = 0.2;
  bool fronto_parallel = false;  // every view facing the camera at one distance
  double depth_min_m = 0.35;
  double depth_max_m = 0.8;
};

/// Views of the board through `camera` at random poses: the board's centre on the ray of a random
/// pixel, tilted up to 40 degrees; views showing fewer than half the points are redrawn.
std::vector<TargetObservation> synthesize(const CameraModel& camera, const TargetDescription& target,
                                          unsigned seed, const SynthOptions& o) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, o.noise_px);
  const auto points = target.points();
  const Eigen::Vector3d centre((target.cols - 1) * target.col_spacing_m / 2,
                               (target.rows - 1) * target.row_spacing_m / 2, 0.0);
  std::vector<TargetObservation> out;
  while (static_cast<int>(out.size()) < o.views) {
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    Eigen::Vector3d at(0.0, 0.0, 0.5);
    if (!o.fronto_parallel) {
      const Eigen::Vector3d axis =
          Eigen::Vector3d(uni(rng) - 0.5, uni(rng) - 0.5, 0.2 * (uni(rng) - 0.5)).normalized();
      R = Eigen::AngleAxisd((10.0 + 30.0 * uni(rng)) * M_PI / 180.0, axis).toRotationMatrix();
      Eigen::Vector3d ray;
      const Eigen::Vector2d px(camera.width * (0.15 + 0.7 * uni(rng)),
                               camera.height * (0.15 + 0.7 * uni(rng)));
      if (!camera.unproject(px, &ray)) continue;
      at = ray / ray.z() * (o.depth_min_m + (o.depth_max_m - o.depth_min_m) * uni(rng));
    } else {
      at.x() = 0.3 * (uni(rng) - 0.5);
      at.y() = 0.2 * (uni(rng) - 0.5);
    }
    TargetObservation obs = test::board_view(camera, points, centre, R, at,
                                             static_cast<TimeNs>(out.size()) * 50'000'000, noise, rng);
    if (obs.ids.size() * 2 >= points.size()) out.push_back(std::move(obs));
  }
  return out;
}

Eigen::Matrix<double, 8, 1> params(const CameraModel& c) {
  Eigen::Matrix<double, 8, 1> p;
  p << c.intrinsics, c.distortion_coeffs;
  return p;
}

Eigen::Matrix<double, 8, 1> sigmas(const CameraIntrinsicsResult& r) {
  Eigen::Matrix<double, 8, 1> s;
  s << r.intrinsics_sigma, r.distortion_sigma;
  return s;
}

void expect_within_sigmas(const CameraIntrinsicsResult& r, const CameraModel& truth, double k,
                          const std::string& what) {
  const auto est = params(r.camera);
  const auto ref = params(truth);
  const auto s = sigmas(r);
  for (int i = 0; i < 8; ++i) {
    EXPECT_TRUE(std::isfinite(s[i]) && s[i] > 0.0) << what << " parameter " << i << " sigma " << s[i];
    EXPECT_LE(std::abs(est[i] - ref[i]), k * s[i])
        << what << " parameter " << i << ": " << est[i] << " vs truth " << ref[i] << ", sigma " << s[i];
  }
}

CameraIntrinsicsOptions options_for(const CameraModel& c) {
  CameraIntrinsicsOptions o;
  o.model = c.kind();
  o.threads = 1;
  return o;
}

SynthOptions equi_views() {
  SynthOptions o;
  o.depth_min_m = 0.2;
  o.depth_max_m = 0.45;
  return o;
}

TEST(CameraIntrinsics, RecoversRadtanWithinThreeSigmas) {
  const CameraModel truth = radtan_camera();
  for (unsigned seed : {1u, 2u, 3u}) {
    const auto obs = synthesize(truth, board(), seed, {});
    auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
    ASSERT_TRUE(r.ok()) << r.error().message;
    expect_within_sigmas(*r, truth, 3.0, "seed " + std::to_string(seed));
    EXPECT_EQ(r->views_used, 25);
    EXPECT_NEAR(r->residual_sigma_px, 0.2, 0.02);
    EXPECT_TRUE(r->focal_well_determined);
    EXPECT_TRUE(r->covariance_ok);
  }
}

TEST(CameraIntrinsics, RecoversEquidistantWithinThreeSigmas) {
  const CameraModel truth = equi_camera();
  for (unsigned seed : {1u, 2u, 3u}) {
    const auto obs = synthesize(truth, board(), seed, equi_views());
    auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
    ASSERT_TRUE(r.ok()) << r.error().message;
    expect_within_sigmas(*r, truth, 3.0, "seed " + std::to_string(seed));
    EXPECT_EQ(r->camera.distortion_model, DistortionModel::kEquidistant);
  }
}

/// Mean over seeds and parameters of ((estimate - truth) / sigma)^2.
double mean_squared_z(const CameraModel& truth, SynthOptions o, unsigned first_seed, int seeds) {
  double sum = 0.0;
  int n = 0;
  for (unsigned seed = first_seed; seed < first_seed + static_cast<unsigned>(seeds); ++seed) {
    const auto obs = synthesize(truth, board(), seed, o);
    auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
    EXPECT_TRUE(r.ok()) << r.error().message;
    if (!r.ok()) continue;
    const Eigen::Matrix<double, 8, 1> z = (params(r->camera) - params(truth)).cwiseQuotient(sigmas(*r));
    sum += z.squaredNorm();
    n += 8;
  }
  return sum / n;
}

// Over many seeds, the errors divided by the reported sigmas have unit variance when the sigmas
// are right: the mean of their squares is near 1. With 12 seeds of 8 parameters, some strongly
// correlated (the equidistant k1..k4 move together), 0.6 to 1.5 holds it with better than 99 %
// probability; sigmas off by a factor of 1.3 either way fail it.
TEST(CameraIntrinsics, ReportedSigmasMatchTheSpread) {
  SynthOptions radtan;
  radtan.views = 15;
  const double z2_radtan = mean_squared_z(radtan_camera(), radtan, 100, 12);
  EXPECT_GT(z2_radtan, 0.6);
  EXPECT_LT(z2_radtan, 1.5);
  SynthOptions equi = equi_views();
  equi.views = 15;
  const double z2_equi = mean_squared_z(equi_camera(), equi, 200, 12);
  EXPECT_GT(z2_equi, 0.6);
  EXPECT_LT(z2_equi, 1.5);
}

TEST(CameraIntrinsics, RejectsOutlierViewsAndCorners) {
  const CameraModel truth = radtan_camera();
  auto obs = synthesize(truth, board(), 7, {});
  std::mt19937 rng(99);
  // Two views whose points are numbered wrongly (half of them shuffled: no pose fits), one with
  // its corners scattered by 6 px.
  for (int v : {3, 11}) {
    auto& px = obs[static_cast<std::size_t>(v)].px;
    std::shuffle(px.begin(), px.begin() + static_cast<std::ptrdiff_t>(px.size() / 2), rng);
  }
  std::normal_distribution<double> big(0.0, 6.0);
  for (auto& px : obs[17].px) px += Eigen::Vector2d(big(rng), big(rng));
  // Single corners off by 4 px in otherwise good views.
  const std::vector<std::pair<int, int>> bad_corners = {{0, 5}, {1, 20}, {5, 0}, {8, 30}, {20, 12}};
  for (const auto& [v, i] : bad_corners)
    obs[static_cast<std::size_t>(v)].px[static_cast<std::size_t>(i)] += Eigen::Vector2d(4.0, -3.0);

  auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  for (int v : {3, 11, 17}) {
    EXPECT_FALSE(r->views[static_cast<std::size_t>(v)].used) << "view " << v;
    EXPECT_FALSE(r->views[static_cast<std::size_t>(v)].rejected_because.empty());
  }
  EXPECT_EQ(r->views_used, 22);
  EXPECT_GE(r->corners_rejected, 5);
  for (const auto& [v, i] : bad_corners) {
    EXPECT_LT(r->views[static_cast<std::size_t>(v)].points_used, r->views[static_cast<std::size_t>(v)].points)
        << "view " << v;
  }
  expect_within_sigmas(*r, truth, 3.0, "with outliers");
  EXPECT_NEAR(r->residual_sigma_px, 0.2, 0.03);
}

// A long recording: the starts are solved on an evenly spaced subset of the views, every view
// then joins from that camera. The result must be the one the solve over every view from the
// start gives (the same views and corners used, every parameter within a hundredth of its sigma),
// with the wrongly numbered views left out either way (one of them the subset's first view).
TEST(CameraIntrinsics, ALongRecordingSolvedFromASubsetOfItsViewsGivesTheCameraOfEveryView) {
  const CameraModel truth = radtan_camera();
  auto obs = synthesize(truth, board(), 21, {.views = 400});
  std::mt19937 rng(5);
  for (int v : {0, 137, 301}) {
    auto& px = obs[static_cast<std::size_t>(v)].px;
    std::shuffle(px.begin(), px.begin() + static_cast<std::ptrdiff_t>(px.size() / 2), rng);
  }
  CameraIntrinsicsOptions subset = options_for(truth);
  subset.start_views = 40;
  CameraIntrinsicsOptions every = options_for(truth);
  every.start_views = 0;
  const auto a = calibrate_camera_intrinsics(board(), obs, subset, {});
  const auto b = calibrate_camera_intrinsics(board(), obs, every, {});
  ASSERT_TRUE(a.ok()) << a.error().message;
  ASSERT_TRUE(b.ok()) << b.error().message;
  EXPECT_EQ(a->views_used, 397);
  EXPECT_EQ(a->views_used, b->views_used);
  EXPECT_EQ(a->points_used, b->points_used);
  for (int v : {0, 137, 301}) EXPECT_FALSE(a->views[static_cast<std::size_t>(v)].used) << "view " << v;
  const auto pa = params(a->camera);
  const auto pb = params(b->camera);
  const auto s = sigmas(*b);
  for (int i = 0; i < 8; ++i) {
    EXPECT_LE(std::abs(pa[i] - pb[i]), 0.01 * s[i]) << "parameter " << i << ": " << pa[i] << " vs " << pb[i];
  }
  expect_within_sigmas(*a, truth, 3.0, "from a subset");
}

TEST(CameraIntrinsics, RefusesTooFewViews) {
  const CameraModel truth = radtan_camera();
  SynthOptions o;
  o.views = 4;
  const auto obs = synthesize(truth, board(), 5, o);
  auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInsufficientData);
  EXPECT_NE(r.error().message.find("4 usable views"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("record more views"), std::string::npos) << r.error().message;
}

TEST(CameraIntrinsics, RefusesViewsWithTooFewPoints) {
  const CameraModel truth = radtan_camera();
  auto obs = synthesize(truth, board(), 6, {});
  for (std::size_t v = 0; v < 22; ++v) {
    obs[v].ids.resize(5);
    obs[v].px.resize(5);
  }
  auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInsufficientData);
  EXPECT_NE(r.error().message.find("too few points"), std::string::npos) << r.error().message;
}

TEST(CameraIntrinsics, WarnsWhenEveryViewFacesTheCamera) {
  CameraModel truth = radtan_camera();
  SynthOptions o;
  o.fronto_parallel = true;
  const auto obs = synthesize(truth, board(), 8, o);
  auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->focal_well_determined);
  ASSERT_FALSE(r->warnings.empty());
  EXPECT_NE(r->warnings.front().find("focal length is not determined"), std::string::npos)
      << r->warnings.front();
}

TEST(CameraIntrinsics, CoverageCountsTheCellsHit) {
  const CameraModel truth = radtan_camera();
  const auto obs = synthesize(truth, board(), 9, {});
  auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->coverage_cols, 10);
  EXPECT_EQ(r->coverage_rows, 8);
  int sum = 0;
  for (int c : r->coverage_counts) sum += c;
  EXPECT_EQ(sum, r->points_used);
  EXPECT_GT(r->coverage, 0.5);
  EXPECT_LE(r->coverage, 1.0);

  // Only the left half of the image: coverage at most a half, and a warning.
  std::vector<TargetObservation> left;
  for (const auto& o : synthesize(truth, board(), 10, {.views = 60})) {
    bool inside = true;
    for (const auto& px : o.px) inside = inside && px.x() < 300.0;
    if (inside) left.push_back(o);
  }
  ASSERT_GE(left.size(), 5u);
  auto l = calibrate_camera_intrinsics(board(), left, options_for(truth), {});
  ASSERT_TRUE(l.ok()) << l.error().message;
  EXPECT_LE(l->coverage, 0.5);
  bool warned = false;
  for (const auto& w : l->warnings) warned = warned || w.find("cover only") != std::string::npos;
  EXPECT_TRUE(warned);
}

bool warns_of_edges(const std::vector<std::string>& warnings) {
  for (const auto& w : warnings)
    if (w.find("cells along the image's edges") != std::string::npos) return true;
  return false;
}

TEST(CameraIntrinsics, WarnsWhenTheTargetNeverReachedTheImagesEdges) {
  // Views whose corners all stay in the middle of the image: most of the grid's inner cells
  // can be covered while the outer ring stays empty, and that is said apart.
  const CameraModel truth = radtan_camera();
  std::vector<TargetObservation> middle;
  for (const auto& o : synthesize(truth, board(), 11, {.views = 120})) {
    bool inside = true;
    for (const auto& px : o.px)
      inside = inside && px.x() > 0.12 * truth.width && px.x() < 0.88 * truth.width &&
               px.y() > 0.14 * truth.height && px.y() < 0.86 * truth.height;
    if (inside) middle.push_back(o);
  }
  ASSERT_GE(middle.size(), 5u);
  auto m = calibrate_camera_intrinsics(board(), middle, options_for(truth), {});
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_TRUE(warns_of_edges(m->warnings));

  // The counts alone: 10 x 8 cells, the outer ring's 32 cells; 15 of them reached is too few,
  // 16 is enough.
  CameraIntrinsicsResult r;
  r.coverage_cols = 10;
  r.coverage_rows = 8;
  r.coverage = 1.0;
  r.covariance_ok = true;
  r.camera = truth;
  r.intrinsics_sigma.setConstant(1e-3);
  r.coverage_counts.assign(80, 0);
  for (int y = 1; y < 7; ++y)
    for (int x = 1; x < 9; ++x) r.coverage_counts[static_cast<std::size_t>(y * 10 + x)] = 5;
  for (int x = 0; x < 10; ++x) r.coverage_counts[static_cast<std::size_t>(x)] = 1;      // the top row
  for (int y = 1; y < 6; ++y) r.coverage_counts[static_cast<std::size_t>(y * 10)] = 1;  // 5 on the left
  EXPECT_TRUE(warns_of_edges(camera_quality_warnings(r, options_for(truth))));
  r.coverage_counts[60] = 1;
  EXPECT_FALSE(warns_of_edges(camera_quality_warnings(r, options_for(truth))));
  // And the fixture's well-spread views do not warn.
  auto spread =
      calibrate_camera_intrinsics(board(), synthesize(truth, board(), 9, {}), options_for(truth), {});
  ASSERT_TRUE(spread.ok()) << spread.error().message;
  EXPECT_FALSE(warns_of_edges(spread->warnings));
}

TEST(CameraIntrinsics, RefusesMixedImageSizesAndBadIds) {
  const CameraModel truth = radtan_camera();
  auto obs = synthesize(truth, board(), 4, {});
  auto mixed = obs;
  mixed[3].width = 320;
  auto r = calibrate_camera_intrinsics(board(), mixed, options_for(truth), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInvalidArgument);
  auto bad = obs;
  bad[2].ids[0] = 1000;
  r = calibrate_camera_intrinsics(board(), bad, options_for(truth), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInvalidArgument);
}

TEST(CameraIntrinsics, ReportsProgressUpToOne) {
  const CameraModel truth = radtan_camera();
  const auto obs = synthesize(truth, board(), 2, {});
  double last = -1.0;
  bool monotonic = true;
  auto r = calibrate_camera_intrinsics(board(), obs, options_for(truth), [&](double f) {
    monotonic = monotonic && f >= last;
    last = f;
  });
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(monotonic);
  EXPECT_DOUBLE_EQ(last, 1.0);
}

TEST(CameraIntrinsics, OptionsValidateAndModelNames) {
  CameraIntrinsicsOptions o;
  EXPECT_TRUE(o.validate().ok());
  o.min_views = 2;
  EXPECT_FALSE(o.validate().ok());
  const CameraModelKind equi{ProjectionModel::kPinhole, DistortionModel::kEquidistant};
  EXPECT_EQ(*parse_camera_model_option("pinhole-equi"), equi);
  EXPECT_EQ(*parse_camera_model_option("pinhole-radtan"),
            (CameraModelKind{ProjectionModel::kPinhole, DistortionModel::kRadtan}));
  EXPECT_FALSE(parse_camera_model_option("omni-equi").ok());
  EXPECT_EQ(camera_model_option_name(equi), "pinhole-equi");
}

}  // namespace
}  // namespace imucal::calib
