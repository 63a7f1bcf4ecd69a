// SPDX-License-Identifier: BSD-3-Clause
// The camera models beyond pinhole-radtan and pinhole-equi in the intrinsic calibration:
// observations projected through a known camera at known poses with pixel noise, the estimate
// within 3 of its own sigmas; a lens of 200 degrees, on which the evidence (--model auto)
// chooses the double sphere model over the equidistant one.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "calib/camera_intrinsics.hpp"
#include "calib/camera_model_choice.hpp"
#include "tests/support/board_view.hpp"

namespace imucal::calib {
namespace {

TargetDescription wide_board() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 7;
  t.rows = 6;
  t.col_spacing_m = 0.04;
  t.row_spacing_m = 0.04;
  return t;
}

CameraModel model_camera(CameraModelKind kind, Eigen::Vector4d k, Eigen::Vector2d e, Eigen::Vector4d d, int w,
                         int h) {
  CameraModel c;
  c.projection = kind.projection;
  c.distortion_model = kind.distortion;
  c.intrinsics = k;
  c.projection_params = e;
  c.distortion_coeffs = d;
  c.width = w;
  c.height = h;
  return c;
}

/// Views of the board with its centre on the ray of a random pixel anywhere in the image (also
/// beyond 90 degrees off the axis where the model reaches), facing the camera within 35 degrees;
/// views showing fewer than half the corners are redrawn.
std::vector<TargetObservation> wide_views(const CameraModel& camera, unsigned seed, int views,
                                          double noise_px) {
  const TargetDescription target = wide_board();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, noise_px);
  const auto points = target.points();
  const Eigen::Vector3d centre((target.cols - 1) * target.col_spacing_m / 2,
                               (target.rows - 1) * target.row_spacing_m / 2, 0.0);
  std::vector<TargetObservation> out;
  while (static_cast<int>(out.size()) < views) {
    Eigen::Vector3d ray;
    const Eigen::Vector2d px(camera.width * (0.03 + 0.94 * uni(rng)),
                             camera.height * (0.03 + 0.94 * uni(rng)));
    if (!camera.unproject(px, &ray)) continue;
    const Eigen::Vector3d axis = Eigen::Vector3d(uni(rng) - 0.5, uni(rng) - 0.5, 0.0).normalized();
    const Eigen::Matrix3d R =
        Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), ray).toRotationMatrix() *
        Eigen::AngleAxisd((5.0 + 30.0 * uni(rng)) * M_PI / 180.0, axis).toRotationMatrix();
    const Eigen::Vector3d at = ray * (0.25 + 0.3 * uni(rng));
    TargetObservation obs = test::board_view(camera, points, centre, R, at,
                                             static_cast<TimeNs>(out.size()) * 50'000'000, noise, rng);
    if (obs.ids.size() * 2 >= points.size()) out.push_back(std::move(obs));
  }
  return out;
}

/// Every parameter of the model (Kalibr's order) within k sigmas of the truth, with a finite
/// positive sigma; the entries the model does not have carry no sigma (NaN).
void expect_model_within_sigmas(const CameraIntrinsicsResult& r, const CameraModel& truth, double k) {
  const std::string name = camera_model_name(truth.kind());
  ASSERT_EQ(r.camera.kind(), truth.kind()) << name;
  Eigen::Matrix<double, 10, 1> est, ref, sigma;
  est << r.camera.intrinsics, r.camera.projection_params, r.camera.distortion_coeffs;
  ref << truth.intrinsics, truth.projection_params, truth.distortion_coeffs;
  sigma << r.intrinsics_sigma, r.projection_sigma, r.distortion_sigma;
  const std::vector<int> used = kalibr_parameter_indices(truth.kind());
  const std::vector<std::string> names = kalibr_parameter_names(truth.kind());
  for (std::size_t j = 0; j < used.size(); ++j) {
    const int i = used[j];
    EXPECT_TRUE(std::isfinite(sigma[i]) && sigma[i] > 0.0)
        << name << " " << names[j] << " sigma " << sigma[i];
    EXPECT_LE(std::abs(est[i] - ref[i]), k * sigma[i])
        << name << " " << names[j] << ": " << est[i] << " vs truth " << ref[i] << ", sigma " << sigma[i];
    std::printf("%s %s %.6f truth %.6f sigma %.2g (%.2f sigma)\n", name.c_str(), names[j].c_str(), est[i],
                ref[i], sigma[i], (est[i] - ref[i]) / sigma[i]);
  }
  for (int i = 0; i < 10; ++i) {
    if (std::find(used.begin(), used.end(), i) != used.end()) continue;
    EXPECT_TRUE(std::isnan(sigma[i])) << name << " entry " << i << " is no parameter, sigma " << sigma[i];
    EXPECT_EQ(est[i], 0.0) << name << " entry " << i << " is held";
  }
}

std::vector<CameraModel> wide_model_cameras() {
  using P = ProjectionModel;
  using D = DistortionModel;
  return {
      model_camera({P::kPinhole, D::kFov}, {190.0, 189.5, 188.7, 120.4}, {0, 0}, {0.9, 0, 0, 0}, 376, 240),
      model_camera({P::kOmni, D::kNone}, {270.0, 269.4, 188.2, 119.1}, {0.8, 0}, {0, 0, 0, 0}, 376, 240),
      model_camera({P::kOmni, D::kRadtan}, {270.0, 269.4, 188.2, 119.1}, {0.8, 0},
                   {-0.04, 0.008, 1e-4, -1e-4}, 376, 240),
      model_camera({P::kDs, D::kNone}, {110.0, 109.8, 188.2, 119.1}, {-0.15, 0.6}, {0, 0, 0, 0}, 376, 240),
      model_camera({P::kEucm, D::kNone}, {110.0, 109.8, 188.2, 119.1}, {0.6, 1.1}, {0, 0, 0, 0}, 376, 240),
  };
}

TEST(CameraModelsCalib, EachModelRecoversItsParametersWithinThreeSigmas) {
  for (const CameraModel& truth : wide_model_cameras()) {
    const auto obs = wide_views(truth, 21, 24, 0.2);
    CameraIntrinsicsOptions o;
    o.model = truth.kind();
    o.threads = 1;
    auto r = calibrate_camera_intrinsics(wide_board(), obs, o, {});
    ASSERT_TRUE(r.ok()) << camera_model_name(truth.kind()) << ": " << r.error().message;
    EXPECT_EQ(r->views_used, 24) << camera_model_name(truth.kind());
    EXPECT_LT(r->rms_px, 0.35) << camera_model_name(truth.kind());
    std::printf("%s: profile chi-square %.2f, sigma stretched %.2f times; %s\n",
                camera_model_name(truth.kind()).c_str(), r->profile_chi2, r->profile_stretch,
                r->ambiguity.empty() ? "one solution" : r->ambiguity.c_str());
    expect_model_within_sigmas(*r, truth, 3.0);
  }
}

// A 200-degree lens (double sphere): the pinhole models cannot see the views beyond 90 degrees
// and are left out; the double sphere model has the lowest BIC of those compared, and its
// calibration holds the truth within 3 sigmas.
TEST(CameraModelsCalib, AutoChoosesDoubleSphereForA200DegreeLens) {
  const CameraModel truth = model_camera({ProjectionModel::kDs, DistortionModel::kNone},
                                         {96.0, 95.8, 199.6, 200.3}, {-0.15, 0.6}, {0, 0, 0, 0}, 400, 400);
  Eigen::Vector3d edge;
  ASSERT_TRUE(truth.unproject(Eigen::Vector2d(0.0, 199.6), &edge));
  const double half_field_deg = std::acos(edge.z()) * 180.0 / M_PI;
  EXPECT_GT(2.0 * half_field_deg, 200.0);
  const auto obs = wide_views(truth, 5, 30, 0.2);
  CameraIntrinsicsOptions o;
  o.threads = 1;
  auto chosen = choose_camera_model(wide_board(), obs, o, default_model_candidates());
  ASSERT_TRUE(chosen.ok()) << chosen.error().message;
  std::printf("%s\n", chosen->choice.reason.c_str());
  EXPECT_EQ(camera_model_name(chosen->choice.chosen), "ds-none") << chosen->choice.reason;
  bool equi_beaten = false;
  for (const auto& f : chosen->choice.fits) {
    if (f.model == CameraModelKind{ProjectionModel::kPinhole, DistortionModel::kEquidistant})
      equi_beaten = !f.compared || f.delta_bic > 0.0;
  }
  EXPECT_TRUE(equi_beaten);
  EXPECT_NE(chosen->choice.reason.find("ds-none"), std::string::npos);
  expect_model_within_sigmas(chosen->result, truth, 3.0);
}

TEST(CameraModelsCalib, ModelNamesParseAsKalibrs) {
  auto ds = parse_camera_model_option("ds-none");
  ASSERT_TRUE(ds.ok());
  EXPECT_EQ(ds->projection, ProjectionModel::kDs);
  EXPECT_EQ(camera_model_option_name(*ds), "ds-none");
  auto equi = parse_camera_model_option("pinhole-equi");
  ASSERT_TRUE(equi.ok());
  EXPECT_EQ(equi->distortion, DistortionModel::kEquidistant);
  EXPECT_FALSE(parse_camera_model_option("ds-radtan").ok());
  EXPECT_EQ(default_model_candidates().size(), 7u);
}

}  // namespace
}  // namespace imucal::calib
