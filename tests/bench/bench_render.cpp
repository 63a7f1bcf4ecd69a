// SPDX-License-Identifier: BSD-3-Clause
// Speed of the virtual camera: ray precomputation, frame rendering (per supersampling and with
// motion blur), and lossless encoding of the frames. See docs/benchmarks.md.

#include <benchmark/benchmark.h>

#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "sim/camera_render.hpp"
#include "sim/camimu.hpp"

namespace {

using imucal::TargetDescription;
using imucal::sim::CamImuSimOptions;
using imucal::sim::TargetRenderer;

/// Kalibr's usual AprilGrid (config/aprilgrid-6x6.yaml).
TargetDescription aprilgrid() {
  TargetDescription t;
  t.type = TargetDescription::Type::kAprilgrid;
  t.tag_cols = 6;
  t.tag_rows = 6;
  t.tag_size_m = 0.088;
  t.tag_spacing = 0.3;
  return t;
}

/// The camera looking at the target's centre from `distance_m`, slightly tilted, at the printed
/// side (a checkerboard's z < 0, an AprilGrid's z > 0).
Eigen::Isometry3d board_pose(const TargetDescription& t, double shift_m = 0.0, double distance_m = 0.8) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translate(Eigen::Vector3d(shift_m, 0.0, distance_m));
  T.rotate(Eigen::AngleAxisd(0.35, Eigen::Vector3d(0.6, 0.8, 0.1).normalized()));
  if (t.type == TargetDescription::Type::kAprilgrid) {
    T.rotate(Eigen::AngleAxisd(3.141592653589793, Eigen::Vector3d::UnitX()));
    const double extent = (t.tag_cols - 1) * (1 + t.tag_spacing) * t.tag_size_m + t.tag_size_m;
    T.translate(-Eigen::Vector3d(extent / 2, extent / 2, 0.0));
  } else {
    T.translate(
        -Eigen::Vector3d((t.cols - 1) * t.col_spacing_m / 2, (t.rows - 1) * t.row_spacing_m / 2, 0.0));
  }
  return T;
}
Eigen::Isometry3d board_pose(double shift_m = 0.0) {
  return board_pose(CamImuSimOptions::default_sim_target(), shift_m);
}

/// The default camera, or the same lens on the full 752x480 sensor (`scale` 2).
imucal::CameraModel camera(int scale) {
  imucal::CameraModel c = CamImuSimOptions::default_sim_camera();
  c.intrinsics.head<2>() *= scale;
  c.intrinsics.tail<2>() = (c.intrinsics.tail<2>().array() + 0.5) * scale - 0.5;
  c.width *= scale;
  c.height *= scale;
  return c;
}

std::unique_ptr<TargetRenderer> make_renderer(
    int supersampling, double noise_dn, double blur_px,
    const TargetDescription& target = CamImuSimOptions::default_sim_target(), int scale = 1) {
  imucal::sim::CameraRenderOptions opt;
  opt.supersampling = supersampling;
  opt.noise_sigma_dn = noise_dn;
  opt.optics_blur_sigma_px = blur_px;
  auto r = TargetRenderer::create(camera(scale), target, opt);
  return r.ok() ? std::move(*r) : nullptr;
}

void BM_PrecomputeRays(benchmark::State& state) {
  for (auto _ : state) {
    auto r = make_renderer(2, 0.0, 0.0);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_PrecomputeRays)->Unit(benchmark::kMillisecond);

/// One sharp frame (no motion blur) with noise and lens blur as in the camimu session;
/// argument: supersampling.
void BM_RenderFrame(benchmark::State& state) {
  auto r = make_renderer(static_cast<int>(state.range(0)), 0.8, 0.7);
  if (!r) {
    state.SkipWithError("renderer creation failed");
    return;
  }
  imucal::sim::Rng rng(1);
  const std::vector<Eigen::Isometry3d> poses = {board_pose()};
  for (auto _ : state) {
    cv::Mat image = r->render(poses, &rng);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RenderFrame)->Arg(1)->Arg(2)->Arg(4)->Unit(benchmark::kMillisecond);

/// One sharp frame as in the camimu session (supersampling 2, noise, lens blur 0.7 px) of a
/// target filling a similar part of the view: arguments target (0 the default checkerboard at
/// 0.8 m, 1 Kalibr's 6 x 6 AprilGrid at 1.4 m) and sensor scale (1: 376x240, 2: 752x480).
void BM_RenderTarget(benchmark::State& state) {
  const bool april = state.range(0) == 1;
  const TargetDescription t = april ? aprilgrid() : CamImuSimOptions::default_sim_target();
  auto r = make_renderer(2, 0.8, 0.7, t, static_cast<int>(state.range(1)));
  if (!r) {
    state.SkipWithError("renderer creation failed");
    return;
  }
  imucal::sim::Rng rng(1);
  const std::vector<Eigen::Isometry3d> poses = {board_pose(t, 0.0, april ? 1.4 : 0.8)};
  for (auto _ : state) {
    cv::Mat image = r->render(poses, &rng);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RenderTarget)
    ->Args({0, 1})
    ->Args({1, 1})
    ->Args({0, 2})
    ->Args({1, 2})
    ->Unit(benchmark::kMillisecond);

/// A motion-blurred frame: argument = number of sub-exposures.
void BM_RenderMotionBlur(benchmark::State& state) {
  auto r = make_renderer(2, 0.8, 0.7);
  if (!r) {
    state.SkipWithError("renderer creation failed");
    return;
  }
  imucal::sim::Rng rng(1);
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < state.range(0); ++i) poses.push_back(board_pose(0.001 * i));
  for (auto _ : state) {
    cv::Mat image = r->render(poses, &rng);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RenderMotionBlur)->Arg(4)->Arg(16)->Unit(benchmark::kMillisecond);

/// Lossless encoding of a rendered frame; argument 0 = PNG (level 9), 1 = WebP lossless.
void BM_Encode(benchmark::State& state) {
  auto r = make_renderer(2, 0.8, 0.7);
  if (!r) {
    state.SkipWithError("renderer creation failed");
    return;
  }
  imucal::sim::Rng rng(1);
  const std::vector<Eigen::Isometry3d> poses = {board_pose()};
  const cv::Mat image = r->render(poses, &rng);
  const bool webp = state.range(0) == 1;
  const std::vector<int> params = webp ? std::vector<int>{cv::IMWRITE_WEBP_QUALITY, 101}
                                       : std::vector<int>{cv::IMWRITE_PNG_COMPRESSION, 9};
  std::vector<std::uint8_t> bytes;
  for (auto _ : state) {
    cv::imencode(webp ? ".webp" : ".png", image, bytes, params);
    benchmark::DoNotOptimize(bytes.data());
  }
  state.counters["bytes"] = static_cast<double>(bytes.size());
}
BENCHMARK(BM_Encode)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
