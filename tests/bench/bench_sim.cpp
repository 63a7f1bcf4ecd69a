// SPDX-License-Identifier: BSD-3-Clause
// Simulator speed: simulated seconds per wall-clock second, for the motion + IMU model alone and
// for a whole session written to a session log. Prints the median of several runs.
//   build/release/tests/bench_sim [SCRATCH_DIR]

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"
#include "sim/session.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using namespace imucal;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

/// Samples `traj` through the model at `rate_hz`; returns wall seconds.
double model_only(const sim::Trajectory& traj, double rate_hz, std::uint64_t seed, double* checksum) {
  const auto t0 = Clock::now();
  sim::ImuSimulator imu(sim::ImuModelParams::draw(seed), seed);
  const double dt = 1.0 / rate_hz;
  const auto n = static_cast<std::int64_t>(ns_to_s(traj.end_ns() - traj.start_ns()) * rate_hz);
  for (std::int64_t k = 0; k <= n; ++k) {
    const TimeNs t = traj.start_ns() + s_to_ns(static_cast<double>(k) * dt);
    *checksum += imu.sample(t, traj.at(t), dt).accel.z();
  }
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  const std::string dir =
      argc > 1 ? argv[1] : (std::filesystem::temp_directory_path() / "imucal_bench_sim").string();
  std::filesystem::create_directories(dir);
  constexpr int kRuns = 5;
  double checksum = 0.0;

  sim::StaticProtocolOptions so;  // defaults: 50 s still + 40 poses
  auto stat = sim::make_static_protocol(so, 1);
  sim::CheckerboardMotionOptions co;  // 90 s
  auto board = sim::CheckerboardMotion::create(co, 1);
  sim::StillOptions sto;
  sto.duration_s = 600.0;
  auto still = sim::make_still(sto, 1);
  if (!stat.ok() || !board.ok() || !still.ok()) {
    std::fprintf(stderr, "bench_sim: cannot build the scripts\n");
    return 1;
  }

  struct Case {
    const char* name;
    const sim::Trajectory* traj;
    double rate_hz;
  };
  const std::vector<Case> cases = {{"static protocol, 40 poses", stat->get(), 100.0},
                                   {"checkerboard motion, 90 s", board->get(), 200.0},
                                   {"still, 600 s", still->get(), 1000.0}};
  std::printf("%-32s %8s %10s %12s %14s\n", "case (motion + IMU model)", "rate Hz", "sim s", "wall ms",
              "x real time");
  for (const Case& c : cases) {
    std::vector<double> wall;
    for (int r = 0; r < kRuns; ++r) wall.push_back(model_only(*c.traj, c.rate_hz, 1, &checksum));
    const double sim_s = ns_to_s(c.traj->end_ns() - c.traj->start_ns());
    const double w = median(wall);
    std::printf("%-32s %8.0f %10.1f %12.2f %14.0f\n", c.name, c.rate_hz, sim_s, w * 1e3, sim_s / w);
  }

  std::printf("\n%-32s %8s %10s %12s %14s\n", "case (whole session to a log)", "rate Hz", "sim s", "wall ms",
              "x real time");
  for (const Case& c : {cases[0], cases[2]}) {
    std::vector<double> wall;
    for (int r = 0; r < kRuns; ++r) {
      sim::SimImuSessionOptions o;
      o.imu = sim::ImuModelParams::draw(1);
      o.imu_rate_hz = c.rate_hz;
      o.overwrite = true;
      const std::string log = dir + "/bench.imulog";
      const auto t0 = Clock::now();
      auto truth = sim::write_sim_imu_session(o, *c.traj, log, dir + "/bench.truth.yaml");
      wall.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
      if (!truth.ok()) {
        std::fprintf(stderr, "bench_sim: %s\n", truth.error().message.c_str());
        return 1;
      }
    }
    const double sim_s = ns_to_s(c.traj->end_ns() - c.traj->start_ns());
    const double w = median(wall);
    std::printf("%-32s %8.0f %10.1f %12.2f %14.0f\n", c.name, c.rate_hz, sim_s, w * 1e3, sim_s / w);
  }
  std::printf("\n(median of %d runs; checksum %.3f)\n", kRuns, checksum);
  return 0;
}
