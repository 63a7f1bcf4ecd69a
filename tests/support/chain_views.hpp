// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Synthetic views for the camera chain (tests/calib/test_camera_chain.cpp and
// tests/bench/bench_camera_chain.cpp): a board moving smoothly in front of cameras with their own
// intrinsics, poses relative to cam0, time offsets, rates and stamp phases, projected with pixel
// noise. Written apart from the virtual camera's renderer: corners, not images.

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "calib/camera_chain.hpp"

namespace imucal::test {

using calib::CameraChainInput;
using calib::TargetObservation;

inline TargetDescription chain_board() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 8;
  t.rows = 6;
  t.col_spacing_m = 0.05;
  t.row_spacing_m = 0.05;
  return t;
}

inline CameraModel chain_camera(double f, double cx, DistortionModel model = DistortionModel::kRadtan) {
  CameraModel c;
  c.distortion_model = model;
  c.width = 640;
  c.height = 480;
  c.intrinsics = {f, f * 1.002, cx, 241.0};
  c.distortion_coeffs = model == DistortionModel::kRadtan ? Eigen::Vector4d(-0.22, 0.06, 0.0004, -0.0002)
                                                          : Eigen::Vector4d(0.01, -0.005, 0.002, -0.0005);
  return c;
}

/// cam0 in the board's frame at time t (s): it circles in front of the board's centre at
/// 0.55-0.95 m, looking at it, tilted up to about 35 degrees, rolling a little.
inline Eigen::Isometry3d T_board_cam0(double t) {
  const Eigen::Vector3d centre(0.175, 0.125, 0.0);
  const Eigen::Vector3d p = centre + Eigen::Vector3d(0.45 * std::sin(2 * M_PI * 0.13 * t),
                                                     0.35 * std::sin(2 * M_PI * 0.17 * t + 1.0),
                                                     -0.75 - 0.2 * std::sin(2 * M_PI * 0.07 * t));
  const Eigen::Vector3d z = (centre - p).normalized();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = z.cross(x);
  R.col(2) = z;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R * Eigen::AngleAxisd(0.3 * std::sin(2 * M_PI * 0.11 * t), Eigen::Vector3d::UnitZ());
  T.translation() = p;
  return T;
}

struct TruthCamera {
  CameraModel camera;
  Eigen::Isometry3d T_cam_cam0 = Eigen::Isometry3d::Identity();
  double shift_s = 0.0;  // t_cam0 = t + shift
  double rate_hz = 15.0;
  double stamp_phase_s = 0.0;
  double visible_from_s = -1e9, visible_to_s = 1e9;  // the board is in view only then
};

/// Each camera's frames over `duration_s`: the stamp k / rate + phase, the scene at cam0 time
/// stamp + shift; points behind the camera or off the image left out, noise added.
inline std::vector<CameraChainInput> synthesize_chain(const std::vector<TruthCamera>& cams, double duration_s,
                                                      double noise_px, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_px);
  const auto points = chain_board().points();
  std::vector<CameraChainInput> out;
  for (std::size_t c = 0; c < cams.size(); ++c) {
    CameraChainInput in;
    in.name = "cam" + std::to_string(c);
    in.model = cams[c].camera.kind();
    const int frames = static_cast<int>(duration_s * cams[c].rate_hz);
    for (int k = 0; k < frames; ++k) {
      const double t = k / cams[c].rate_hz + cams[c].stamp_phase_s;
      TargetObservation o;
      o.t_ns = static_cast<TimeNs>(std::llround(t * 1e9)) + 1'000'000'000;
      o.width = cams[c].camera.width;
      o.height = cams[c].camera.height;
      if (t >= cams[c].visible_from_s && t < cams[c].visible_to_s) {
        const Eigen::Isometry3d T_cam_board =
            cams[c].T_cam_cam0 * T_board_cam0(t + cams[c].shift_s).inverse();
        for (std::size_t i = 0; i < points.size(); ++i) {
          const Eigen::Vector3d pc = T_cam_board * points[i];
          const auto pr = cams[c].camera.project(pc);
          if (!pr.in_front || !pr.in_image) continue;
          o.ids.push_back(static_cast<int>(i));
          o.px.push_back(pr.px + Eigen::Vector2d(noise(rng), noise(rng)));
        }
      }
      if (o.ids.size() < points.size() / 2) {
        o.ids.clear();
        o.px.clear();
      }
      in.observations.push_back(std::move(o));
    }
    out.push_back(std::move(in));
  }
  return out;
}

}  // namespace imucal::test
