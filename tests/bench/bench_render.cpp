// Speed of the virtual camera: ray precomputation, frame rendering (per supersampling and with
// motion blur), and lossless encoding of the frames. See docs/benchmarks.md.

#include <benchmark/benchmark.h>

#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "sim/camera_render.hpp"
#include "sim/camimu.hpp"

namespace {

using imucal::sim::CamImuSimOptions;
using imucal::sim::CheckerboardRenderer;

/// The default simulated camera looking at the default board from 0.8 m, slightly tilted.
Eigen::Isometry3d board_pose(double shift_m = 0.0) {
  const auto t = CamImuSimOptions::default_sim_target();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translate(Eigen::Vector3d(shift_m, 0.0, 0.8));
  T.rotate(Eigen::AngleAxisd(0.35, Eigen::Vector3d(0.6, 0.8, 0.1).normalized()));
  T.translate(-Eigen::Vector3d((t.cols - 1) * t.col_spacing_m / 2, (t.rows - 1) * t.row_spacing_m / 2, 0.0));
  return T;
}

std::unique_ptr<CheckerboardRenderer> make_renderer(int supersampling, double noise_dn, double blur_px) {
  imucal::sim::CameraRenderOptions opt;
  opt.supersampling = supersampling;
  opt.noise_sigma_dn = noise_dn;
  opt.optics_blur_sigma_px = blur_px;
  auto r = CheckerboardRenderer::create(CamImuSimOptions::default_sim_camera(),
                                        CamImuSimOptions::default_sim_target(), opt);
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
