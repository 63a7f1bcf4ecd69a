// SPDX-License-Identifier: BSD-3-Clause
// Speed of calibration-target detection on 752 x 480 frames: the checkerboard (rendered by the
// virtual camera) with both OpenCV methods, a frame without a board, and Kalibr's AprilGrid
// (tests/calib/aprilgrid_image.hpp) at two quad decimations; single thread, and a batch of
// frames over every core with std::thread. See docs/targets.md and docs/benchmarks.md.

#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <atomic>
#include <opencv2/core.hpp>
#include <thread>
#include <vector>

#include "calib/target_detection.hpp"
#include "sim/camera_render.hpp"
#include "tests/calib/aprilgrid_image.hpp"

namespace {

using imucal::CameraModel;
using imucal::DistortionModel;
using imucal::TargetDescription;
using imucal::calib::DetectionOptions;
using imucal::calib::GrayView;
using imucal::calib::TargetDetector;

constexpr int kFrames = 8;  // distinct poses, cycled

CameraModel wvga_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics << 400.6, 399.6, 378.7, 235.1;
  c.distortion_coeffs << -0.2865, 0.0731, 2.1e-4, -3.4e-4;
  c.width = 752;
  c.height = 480;
  return c;
}

TargetDescription checkerboard() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 7;
  t.rows = 6;
  t.col_spacing_m = 0.05;
  t.row_spacing_m = 0.05;
  return t;
}

TargetDescription aprilgrid() {
  TargetDescription t;
  t.type = TargetDescription::Type::kAprilgrid;
  t.tag_cols = 6;
  t.tag_rows = 6;
  t.tag_size_m = 0.088;
  t.tag_spacing = 0.3;
  return t;
}

/// Checkerboard frames as the camera-IMU session renders them (sensor noise, lens blur).
const std::vector<cv::Mat>& checkerboard_frames() {
  static const std::vector<cv::Mat> frames = [] {
    imucal::sim::CameraRenderOptions opt;
    opt.noise_sigma_dn = 0.8;
    opt.optics_blur_sigma_px = 0.7;
    const TargetDescription t = checkerboard();
    auto r = imucal::sim::CheckerboardRenderer::create(wvga_camera(), t, opt);
    std::vector<cv::Mat> out;
    if (!r.ok()) return out;
    imucal::sim::Rng rng(3);
    for (int i = 0; i < kFrames; ++i) {
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      T.translate(Eigen::Vector3d(0.03 * (i % 3 - 1), 0.02 * (i % 2), 0.6 + 0.05 * i));
      T.rotate(Eigen::AngleAxisd(0.35, Eigen::Vector3d(0.6, 0.8 - 0.1 * i, 0.1).normalized()));
      T.rotate(Eigen::AngleAxisd(0.4 * i, Eigen::Vector3d::UnitZ()));
      T.translate(-Eigen::Vector3d(3 * t.col_spacing_m, 2.5 * t.row_spacing_m, 0.0));
      const std::vector<Eigen::Isometry3d> single = {T};
      out.push_back((*r)->render(single, &rng));
    }
    return out;
  }();
  return frames;
}

const std::vector<cv::Mat>& aprilgrid_frames() {
  static const std::vector<cv::Mat> frames = [] {
    const TargetDescription t = aprilgrid();
    const double pitch = t.tag_size_m * (1 + t.tag_spacing);
    const Eigen::Vector3d centre(3 * pitch - 0.5 * t.tag_spacing * t.tag_size_m,
                                 3 * pitch - 0.5 * t.tag_spacing * t.tag_size_m, 0.0);
    imucal::test::AprilGridImageOptions opt;
    opt.blur_sigma_px = 0.7;
    std::vector<cv::Mat> out;
    for (int i = 0; i < kFrames; ++i) {
      const Eigen::Matrix3d R =
          (Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.6, 0.8 - 0.1 * i, 0.1).normalized()) *
           Eigen::AngleAxisd(0.4 * i, Eigen::Vector3d::UnitZ()))
              .toRotationMatrix() *
          Eigen::Vector3d(1, -1, -1).asDiagonal();
      const Eigen::Vector3d t_cam = Eigen::Vector3d(0.03 * (i % 3 - 1), 0.0, 0.95 + 0.05 * i) - R * centre;
      out.push_back(
          imucal::test::render_aprilgrid(
              t, imucal::test::plane_homography(Eigen::Vector4d(450, 450, 375.5, 239.5), R, t_cam), opt)
              .image);
    }
    return out;
  }();
  return frames;
}

GrayView view_of(const cv::Mat& m) { return GrayView{m.data, m.cols, m.rows, m.step[0]}; }

std::unique_ptr<TargetDetector> make(const TargetDescription& t, const DetectionOptions& opt) {
  auto d = TargetDetector::create(t, opt);
  return d.ok() ? std::move(*d) : nullptr;
}

void run_single(benchmark::State& state, const TargetDetector& det, const std::vector<cv::Mat>& frames) {
  std::size_t i = 0;
  std::size_t points = 0;
  for (auto _ : state) {
    auto obs = det.detect(view_of(frames[i++ % frames.size()]));
    if (!obs.ok()) {
      state.SkipWithError(obs.error().message.c_str());
      return;
    }
    points += obs->ids.size();
  }
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["points/frame"] = static_cast<double>(points) / static_cast<double>(state.iterations());
}

/// Argument 0: OpenCV's classic detector + cornerSubPix; 1: findChessboardCornersSB.
void BM_Checkerboard(benchmark::State& state) {
  DetectionOptions opt;
  opt.checkerboard_method = state.range(0) == 0 ? imucal::calib::CheckerboardMethod::kClassic
                                                : imucal::calib::CheckerboardMethod::kSectorBased;
  auto det = make(checkerboard(), opt);
  if (!det || checkerboard_frames().empty()) {
    state.SkipWithError("setup failed");
    return;
  }
  run_single(state, *det, checkerboard_frames());
}
BENCHMARK(BM_Checkerboard)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

/// A frame with no board: how fast a frame is rejected (argument as above).
void BM_CheckerboardNoBoard(benchmark::State& state) {
  DetectionOptions opt;
  opt.checkerboard_method = state.range(0) == 0 ? imucal::calib::CheckerboardMethod::kClassic
                                                : imucal::calib::CheckerboardMethod::kSectorBased;
  auto det = make(checkerboard(), opt);
  if (!det) {
    state.SkipWithError("setup failed");
    return;
  }
  cv::Mat blank(480, 752, CV_8U);
  cv::randn(blank, 105, 20);
  run_single(state, *det, std::vector<cv::Mat>{blank});
}
BENCHMARK(BM_CheckerboardNoBoard)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

/// Argument: libapriltag's quad_decimate.
void BM_Aprilgrid(benchmark::State& state) {
  DetectionOptions opt;
  opt.aprilgrid_decimate = static_cast<double>(state.range(0));
  auto det = make(aprilgrid(), opt);
  if (!det) {
    state.SkipWithError("setup failed");
    return;
  }
  run_single(state, *det, aprilgrid_frames());
}
BENCHMARK(BM_Aprilgrid)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

/// A new detector for every frame: what a libapriltag detector (with its decode table) costs
/// when it is not kept; the reason detectors are pooled.
void BM_AprilgridFreshDetector(benchmark::State& state) {
  const auto& frames = aprilgrid_frames();
  for (auto _ : state) {
    auto det = make(aprilgrid(), {});
    auto obs = det->detect(view_of(frames[0]));
    benchmark::DoNotOptimize(obs);
  }
}
BENCHMARK(BM_AprilgridFreshDetector)->Unit(benchmark::kMillisecond);

/// A batch of 64 frames detected by one thread per core (std::thread), frames handed out
/// through an atomic counter; argument 0 = checkerboard, 1 = AprilGrid.
void BM_BatchAllCores(benchmark::State& state) {
  const bool april = state.range(0) == 1;
  const auto& frames = april ? aprilgrid_frames() : checkerboard_frames();
  auto det = make(april ? aprilgrid() : checkerboard(), {});
  if (!det || frames.empty()) {
    state.SkipWithError("setup failed");
    return;
  }
  const int threads = static_cast<int>(std::max(1U, std::thread::hardware_concurrency()));
  constexpr int kBatch = 64;
  for (auto _ : state) {
    std::atomic<int> next{0};
    std::atomic<int> failed{0};
    std::vector<std::thread> pool;
    for (int k = 0; k < threads; ++k) {
      pool.emplace_back([&] {
        for (int i = next++; i < kBatch; i = next++) {
          auto obs = det->detect(view_of(frames[static_cast<std::size_t>(i) % frames.size()]));
          if (!obs.ok() || obs->empty()) ++failed;
        }
      });
    }
    for (auto& th : pool) th.join();
    if (failed > 0) {
      state.SkipWithError("a frame gave no detection");
      return;
    }
  }
  state.counters["threads"] = threads;
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * kBatch, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BatchAllCores)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
