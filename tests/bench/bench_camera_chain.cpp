// SPDX-License-Identifier: BSD-3-Clause
// The camera chain's joint solve against the single-camera solves it replaces, on synthetic
// corners of a stereo pair (tests/support/chain_views.hpp): 2 x VIEWS views at 15 Hz, 48 corners
// each, 0.15 px noise, the second camera 10 ms off. Prints the CPU and wall time of each, and
// the errors of the joint solve against the truth. Asserts nothing.
//
//   bench_camera_chain [VIEWS] [THREADS]   (default 1000 views, 1 thread)

#include <time.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <vector>

#include "calib/camera_chain.hpp"
#include "tests/support/chain_views.hpp"

using namespace imucal;

namespace {

double cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double wall_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

Eigen::Isometry3d stereo_pose() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.02, Eigen::Vector3d(0.3, -1.0, 0.2).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(-0.11, 0.004, 0.002);
  return T;
}

}  // namespace

int main(int argc, char** argv) {
  const int views = argc > 1 ? std::atoi(argv[1]) : 1000;
  const int threads = argc > 2 ? std::atoi(argv[2]) : 1;
  test::TruthCamera c0{test::chain_camera(480.0, 322.0)};
  test::TruthCamera c1{test::chain_camera(455.0, 316.0), stereo_pose(), 0.010};
  const auto inputs = test::synthesize_chain({c0, c1}, views / 15.0, 0.15, 7);
  int with_target = 0;
  for (const auto& in : inputs)
    for (const auto& o : in.observations) with_target += o.empty() ? 0 : 1;
  std::printf("camera chain: 2 cameras, %d views with the target, %d threads\n", with_target, threads);

  calib::CameraIntrinsicsOptions single;
  single.threads = threads;
  double c = cpu_s(), w = wall_s();
  for (const auto& in : inputs) {
    single.model = in.model;
    auto r = calib::calibrate_camera_intrinsics(test::chain_board(), in.observations, single, {});
    if (!r.ok()) {
      std::printf("single-camera solve failed: %s\n", r.error().message.c_str());
      return 1;
    }
  }
  const double single_cpu = cpu_s() - c, single_wall = wall_s() - w;
  std::printf("two single-camera solves: %.2f s CPU, %.2f s wall\n", single_cpu, single_wall);

  // The singles assume a global shutter; the joint solve is timed so first (like for like),
  // then as `calibrate camera` runs it by default, with the line delay's evidence test.
  std::optional<calib::CameraChainResult> result;
  for (const auto mode :
       {calib::ShutterSolveOptions::Mode::kGlobal, calib::ShutterSolveOptions::Mode::kAuto}) {
    calib::CameraChainOptions chain;
    chain.threads = threads;
    chain.intrinsics.threads = threads;
    chain.shutter.mode = mode;
    c = cpu_s();
    w = wall_s();
    auto r = calib::calibrate_camera_chain(test::chain_board(), inputs, chain, {});
    const double chain_cpu = cpu_s() - c, chain_wall = wall_s() - w;
    if (!r.ok()) {
      std::printf("chain solve failed: %s\n", r.error().message.c_str());
      return 1;
    }
    std::printf("joint chain solve, %s: %.2f s CPU, %.2f s wall (%d iterations), %.2fx the singles' CPU\n",
                mode == calib::ShutterSolveOptions::Mode::kGlobal ? "global shutter" : "shutter test (auto)",
                chain_cpu, chain_wall, r->iterations, chain_cpu / single_cpu);
    result = std::move(*r);
  }
  const calib::CameraChainResult* r = &*result;
  const auto& cam1 = r->cameras[1];
  const Eigen::Vector3d dt = cam1.T_cam_cam0.translation() - c1.T_cam_cam0.translation();
  std::printf(
      "cam1 translation error [%.3f %.3f %.3f] mm (sigma [%.3f %.3f %.3f]), offset error %.4f ms "
      "(sigma %.4f)\n",
      1e3 * dt.x(), 1e3 * dt.y(), 1e3 * dt.z(), 1e3 * std::sqrt(cam1.T_cam_cam0_covariance(3, 3)),
      1e3 * std::sqrt(cam1.T_cam_cam0_covariance(4, 4)), 1e3 * std::sqrt(cam1.T_cam_cam0_covariance(5, 5)),
      1e3 * (cam1.timeshift_cam0_s - c1.shift_s), 1e3 * cam1.timeshift_sigma_s);
  return 0;
}
