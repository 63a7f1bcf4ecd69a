// SPDX-License-Identifier: BSD-3-Clause
// The camera models beyond pinhole-radtan and pinhole-equi (core/camera_projection.hpp):
// projection and unprojection over the whole field of view, Jet derivatives against central
// differences, and Kalibr camchain entries read and written back with the same numbers.

#include <ceres/jet.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "core/camera_model.hpp"

namespace imucal {
namespace {

struct WideCase {
  const char* name;
  CameraModel camera;
  double min_field_deg;  // the full field of view the image must reach (diagonal, across the centre)
};

CameraModel wide_camera(CameraModelKind kind, Eigen::Vector4d intrinsics, Eigen::Vector2d projection,
                        Eigen::Vector4d distortion, int width, int height) {
  CameraModel c;
  c.projection = kind.projection;
  c.distortion_model = kind.distortion;
  c.intrinsics = intrinsics;
  c.projection_params = projection;
  c.distortion_coeffs = distortion;
  c.width = width;
  c.height = height;
  return c;
}

std::vector<WideCase> wide_cases() {
  using P = ProjectionModel;
  using D = DistortionModel;
  return {
      {"pinhole-fov",
       wide_camera({P::kPinhole, D::kFov}, {270.0, 271.0, 321.0, 239.0}, {0, 0}, {0.92, 0, 0, 0}, 640, 480),
       140.0},
      {"omni-none",
       wide_camera({P::kOmni, D::kNone}, {400.0, 401.0, 318.0, 242.0}, {1.2, 0}, {0, 0, 0, 0}, 640, 480),
       150.0},
      {"omni-radtan",
       wide_camera({P::kOmni, D::kRadtan}, {350.0, 349.0, 322.0, 236.0}, {0.9, 0}, {-0.05, 0.01, 2e-4, -1e-4},
                   640, 480),
       150.0},
      {"eucm-none",
       wide_camera({P::kEucm, D::kNone}, {160.0, 159.5, 255.0, 257.0}, {0.62, 1.05}, {0, 0, 0, 0}, 512, 512),
       185.0},
      {"ds-none",
       wide_camera({P::kDs, D::kNone}, {158.3, 158.2, 254.9, 256.9}, {-0.18, 0.59}, {0, 0, 0, 0}, 512, 512),
       185.0},
  };
}

double angle_deg(const Eigen::Vector3d& ray) {
  return std::acos(ray.normalized().z()) * 180.0 / std::numbers::pi;
}

TEST(CameraModelsWide, NamesAndParameterCountsAreKalibrs) {
  for (const auto& c : wide_cases()) {
    EXPECT_EQ(camera_model_name(c.camera.kind()), c.name);
    const auto parsed = parse_camera_model_name(c.name);
    ASSERT_TRUE(parsed.has_value()) << c.name;
    EXPECT_EQ(*parsed, c.camera.kind());
    EXPECT_TRUE(validate_camera(c.camera).ok())
        << c.name << ": " << validate_camera(c.camera).error().message;
  }
  EXPECT_EQ(kalibr_intrinsics_layout(ProjectionModel::kDs), "[xi, alpha, fu, fv, pu, pv]");
  EXPECT_EQ(kalibr_intrinsics_layout(ProjectionModel::kEucm), "[alpha, beta, fu, fv, pu, pv]");
  EXPECT_EQ(distortion_coeff_count(DistortionModel::kFov), 1);
  EXPECT_EQ(distortion_coeff_count(DistortionModel::kNone), 0);
  EXPECT_FALSE(parse_camera_model_name("ds-radtan").has_value());
  EXPECT_FALSE(parse_camera_model_name("eucm").has_value());
}

// Every pixel that unprojects projects back onto itself, the pixels cover the model's whole
// field (beyond 180 degrees for eucm and ds), and every ray that projects into the image
// unprojects back to itself.
TEST(CameraModelsWide, RoundTripOverTheWholeFieldOfView) {
  for (const auto& c : wide_cases()) {
    const CameraModel& cam = c.camera;
    int lifted = 0;
    double widest = 0.0;
    for (int v = 0; v < cam.height; v += 7) {
      for (int u = 0; u < cam.width; u += 7) {
        const Eigen::Vector2d px(u, v);
        Eigen::Vector3d ray;
        if (!cam.unproject(px, &ray)) continue;
        ++lifted;
        EXPECT_NEAR(ray.norm(), 1.0, 1e-12);
        widest = std::max(widest, angle_deg(ray));
        const auto back = cam.project(ray * 2.5);
        ASSERT_TRUE(back.valid()) << c.name << " at " << px.transpose();
        EXPECT_LT((back.px - px).norm(), 1e-7) << c.name << " at " << px.transpose();
      }
    }
    const int sampled = ((cam.height + 6) / 7) * ((cam.width + 6) / 7);
    EXPECT_GT(lifted, sampled / 2) << c.name;
    EXPECT_GT(2.0 * widest, c.min_field_deg) << c.name;

    std::mt19937_64 rng(11);
    std::normal_distribution<double> n(0.0, 1.0);
    int projected = 0;
    for (int i = 0; i < 4000; ++i) {
      const Eigen::Vector3d ray = Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
      const auto p = cam.project(ray * 0.7);
      if (!p.valid()) continue;
      ++projected;
      Eigen::Vector3d back;
      ASSERT_TRUE(cam.unproject(p.px, &back)) << c.name << " ray " << ray.transpose();
      EXPECT_LT((back - ray).norm(), 1e-9) << c.name << " ray " << ray.transpose();
    }
    EXPECT_GT(projected, 400) << c.name;
  }
}

// The Jet derivatives in the point, the four intrinsics, the projection's two parameters and the
// four coefficients agree with central differences, also beyond 90 degrees where the model goes.
TEST(CameraModelsWide, JetDerivativesMatchNumeric) {
  using Jet = ceres::Jet<double, 13>;  // point 0-2, intrinsics 3-6, projection 7-8, distortion 9-12
  for (const auto& c : wide_cases()) {
    const CameraModel& cam = c.camera;
    std::vector<Eigen::Vector3d> points = {{0.11, -0.07, 0.9}, {-0.6, 0.4, 0.5}};
    if (c.min_field_deg > 180.0) points.emplace_back(0.8, 0.5, -0.12);  // 98 degrees off the axis
    for (const Eigen::Vector3d& point : points) {
      Jet ji[4], je[2], jd[4];
      for (int k = 0; k < 4; ++k) ji[k] = Jet(cam.intrinsics[k], 3 + k);
      for (int k = 0; k < 2; ++k) je[k] = Jet(cam.projection_params[k], 7 + k);
      for (int k = 0; k < 4; ++k) jd[k] = Jet(cam.distortion_coeffs[k], 9 + k);
      const auto jcam = CameraModelT<Jet>::from_params(cam.kind(), ji, je, jd, cam.width, cam.height);
      const auto proj =
          jcam.project(Eigen::Matrix<Jet, 3, 1>(Jet(point.x(), 0), Jet(point.y(), 1), Jet(point.z(), 2)));
      ASSERT_TRUE(proj.in_front) << c.name << " " << point.transpose();
      auto eval = [&](int index, double delta) {
        Eigen::Matrix<double, 13, 1> x;
        x << point, cam.intrinsics, cam.projection_params, cam.distortion_coeffs;
        x[index] += delta;
        const auto moved = CameraModel::from_params(cam.kind(), x.data() + 3, x.data() + 7, x.data() + 9,
                                                    cam.width, cam.height);
        return moved.project(x.head<3>()).px;
      };
      for (int k = 0; k < 13; ++k) {
        const double h = 1e-6;
        const Eigen::Vector2d numeric = (eval(k, h) - eval(k, -h)) / (2 * h);
        for (int r = 0; r < 2; ++r) {
          EXPECT_NEAR(proj.px(r).v[k], numeric(r), 2e-5 * std::max(1.0, std::abs(numeric(r))))
              << c.name << " parameter " << k << " row " << r << " point " << point.transpose();
        }
      }
    }
  }
}

// The FOV distortion's series branch near w = 0 joins the closed form smoothly.
TEST(CameraModelsWide, FovSeriesJoinsClosedForm) {
  for (double r : {0.1, 0.8, 1.5}) {
    const double w_series = 0.99e-4;
    const double w_closed = 1.01e-4;
    double xs, ys, xc, yc;
    distort_fov(&w_series, r, 0.0, &xs, &ys);
    distort_fov(&w_closed, r, 0.0, &xc, &yc);
    EXPECT_NEAR(xs, xc, 1e-9 * r) << r;
  }
}

// A Kalibr camchain with each model's name reads, and writes back the same numbers in Kalibr's
// order (the projection's parameters before fu fv pu pv; [] and [w] for none and fov).
TEST(CameraModelsWide, KalibrCamchainEntriesReadAndWriteBack) {
  const std::vector<std::pair<std::string, std::string>> entries = {
      {"pinhole-fov",
       "camera_model: pinhole\nintrinsics: [277.4786, 291.7701, 312.4052, 239.4076]\n"
       "distortion_model: fov\ndistortion_coeffs: [0.9252]\nresolution: [640, 480]\n"},
      {"omni-none",
       "camera_model: omni\nintrinsics: [1.6542, 1147.4, 1146.8, 367.8, 245.4]\n"
       "distortion_model: none\ndistortion_coeffs: []\nresolution: [752, 480]\n"},
      {"omni-radtan",
       "camera_model: omni\nintrinsics: [0.80065662, 833.006, 830.345, 373.850, 253.749]\n"
       "distortion_model: radtan\ndistortion_coeffs: [-0.33518750, 0.13211436, 0.00055967, 0.00057686]\n"
       "resolution: [752, 480]\n"},
      {"eucm-none",
       "camera_model: eucm\nintrinsics: [0.6266, 1.0723, 157.9613, 157.7921, 254.9089, 256.8916]\n"
       "distortion_model: none\ndistortion_coeffs: []\nresolution: [512, 512]\n"},
      {"ds-none",
       "camera_model: ds\nintrinsics: [-0.2038, 0.5909, 158.2838, 158.2706, 254.9091, 256.8854]\n"
       "distortion_model: none\ndistortion_coeffs: []\nresolution: [512, 512]\n"},
  };
  for (const auto& [name, entry] : entries) {
    const YAML::Node chain = YAML::Load("cam0:\n" + [&] {
      std::string indented;
      std::size_t at = 0;
      while (at < entry.size()) {
        const std::size_t end = entry.find('\n', at);
        indented += "  " + entry.substr(at, end - at + 1);
        at = end + 1;
      }
      return indented;
    }() + "  T_cam_imu:\n  - [1, 0, 0, 0.01]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n");
    auto camera = camera_from_yaml(chain["cam0"], "camchain.yaml");
    ASSERT_TRUE(camera.ok()) << name << ": " << camera.error().message;
    EXPECT_EQ(camera_model_name(camera->kind()), name);
    YAML::Node out = YAML::Clone(chain);
    YAML::Node cam0 = out["cam0"];
    camera_to_yaml(*camera, cam0);
    YAML::Emitter emitter;
    emitter << out;
    const YAML::Node written = YAML::Load(emitter.c_str());
    const YAML::Node original = YAML::Load(entry);
    for (const char* key : {"camera_model", "distortion_model"})
      EXPECT_EQ(written["cam0"][key].as<std::string>(), original[key].as<std::string>())
          << name << " " << key;
    for (const char* key : {"intrinsics", "distortion_coeffs", "resolution"}) {
      const auto a = written["cam0"][key].as<std::vector<double>>();
      const auto b = original[key].as<std::vector<double>>();
      EXPECT_EQ(a, b) << name << " " << key;
    }
    EXPECT_EQ(written["cam0"]["T_cam_imu"][0][3].as<double>(), 0.01) << name;
    auto again = camera_from_yaml(written["cam0"], "written");
    ASSERT_TRUE(again.ok()) << name << ": " << again.error().message;
    EXPECT_EQ(again->intrinsics, camera->intrinsics);
    EXPECT_EQ(again->projection_params, camera->projection_params);
    EXPECT_EQ(again->distortion_coeffs, camera->distortion_coeffs);
  }
}

}  // namespace
}  // namespace imucal
