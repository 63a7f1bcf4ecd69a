// SPDX-License-Identifier: BSD-3-Clause
// Static multi-position calibration on the virtual rig: statistical validity over many seeds
// (mean error vs spread, reported sigma vs observed spread, per parameter) and the speed of a
// whole run (log import included) with its breakdown. Prints figures; asserts nothing.
//
//   bench_static [--seeds N] [--speed-runs N] [--skip-stats] [--skip-speed]

#include <time.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "calib/static_calibration.hpp"
#include "log/session_log.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"
#include "sim/truth.hpp"

using namespace imucal;

namespace {

constexpr double kRateHz = 100.0;

struct Recording {
  std::vector<ImuSample> samples;
  ImuStreamInfo info;
  TedaldiImuModel truth;  // in counts
};

/// The statistical configuration: the Tedaldi model only (no g-sensitivity, no bias drift, no
/// temperature effects), MPU-6000 datasheet white noise, 36-50 poses held 1-4 s, 50 s still start.
Recording simulate(std::uint64_t seed, int poses, bool model_only, double still_s = 50.0) {
  sim::StaticProtocolOptions so;
  so.initial_still_s = still_s;
  so.poses = poses;
  so.hold_min_s = 1.0;
  so.hold_max_s = 4.0;
  auto traj = sim::make_static_protocol(so, seed);
  if (!traj.ok()) {
    std::fprintf(stderr, "make_static_protocol: %s\n", traj.error().message.c_str());
    std::exit(1);
  }
  sim::ImuModelParams p = sim::ImuModelParams::draw(seed);
  if (model_only) {
    p.g_sensitivity.setZero();
    p.accel_bias_random_walk = 0.0;
    p.gyro_bias_random_walk = 0.0;
    p.accel_bias_temp_coeff.setZero();
    p.gyro_bias_temp_coeff.setZero();
    p.earth_rotation = false;
  }
  sim::ImuSimulator imu(p, seed * 7 + 1, (*traj)->start_ns());
  Recording rec;
  const TimeNs period = static_cast<TimeNs>(std::llround(1e9 / kRateHz));
  for (TimeNs t = (*traj)->start_ns(); t <= (*traj)->end_ns(); t += period) {
    rec.samples.push_back(imu.sample(t, (*traj)->at(t), 1.0 / kRateHz));
  }
  rec.info.name = "imu0";
  rec.info.units = ImuUnits::kRaw;
  rec.info.rate_hz = kRateHz;
  rec.info.accel.scale.setConstant(p.accel_mps2_per_count());
  rec.info.gyro.scale.setConstant(p.gyro_radps_per_count());
  rec.info.accel_full_scale_g = p.accel_full_scale_g;
  rec.info.gyro_full_scale_dps = p.gyro_full_scale_dps;
  rec.info.device = "sim";
  rec.truth = sim::tedaldi_form(p, /*counts=*/true).model;
  return rec;
}

calib::StaticCalibrationOptions options_for(const ImuStreamInfo& info) {
  calib::StaticCalibrationOptions o;
  o.gravity_mps2 = kStandardGravity;
  o.accel_init = info.accel;
  o.gyro_init = info.gyro;
  return o;
}

/// Parameter vector: accel [alpha(3), s(3), b(3)], gyro [gamma(6), s(3), b(3)], with sigmas.
constexpr int kParams = 21;
const char* kNames[kParams] = {
    "a.alpha_yz", "a.alpha_zy", "a.alpha_zx", "a.s_x",      "a.s_y",      "a.s_z",      "a.b_x",
    "a.b_y",      "a.b_z",      "g.gamma_yz", "g.gamma_zy", "g.gamma_xz", "g.gamma_zx", "g.gamma_xy",
    "g.gamma_yx", "g.s_x",      "g.s_y",      "g.s_z",      "g.b_x",      "g.b_y",      "g.b_z"};

Eigen::Matrix<double, kParams, 1> flatten(const TedaldiImuModel& m) {
  Eigen::Matrix<double, kParams, 1> v;
  v << accel_angles(m.accel.T), m.accel.scale, m.accel.bias, gyro_angles(m.gyro.T), m.gyro.scale, m.gyro.bias;
  return v;
}

Eigen::Matrix<double, kParams, 1> flatten_sigma(const calib::TriadSigma& a, const calib::TriadSigma& g) {
  Eigen::Matrix<double, kParams, 1> v;
  v << a.T(0, 1), a.T(0, 2), a.T(1, 2), a.scale, a.bias, g.T(0, 1), g.T(0, 2), g.T(1, 0), g.T(1, 2),
      g.T(2, 0), g.T(2, 1), g.scale, g.bias;
  return v;
}

void run_stats(int seeds) {
  std::printf(
      "== statistical validity: %d seeds, virtual rig (MPU-6000 datasheet white noise, 100 Hz,\n"
      "   36-50 poses held 1-4 s, 50 s still start, raw counts, Tedaldi model only)\n",
      seeds);
  std::vector<Eigen::Matrix<double, kParams, 1>> err, sig;
  int failed = 0;
  for (int s = 0; s < seeds; ++s) {
    const std::uint64_t seed = 1000 + static_cast<std::uint64_t>(s);
    const int poses = 36 + static_cast<int>(seed % 15);
    const Recording rec = simulate(seed, poses, true);
    auto res = calib::calibrate_static(rec.samples, options_for(rec.info));
    if (!res.ok()) {
      ++failed;
      std::printf("  seed %llu: %s\n", static_cast<unsigned long long>(seed), res.error().message.c_str());
      continue;
    }
    err.push_back(flatten(res->model) - flatten(rec.truth));
    sig.push_back(flatten_sigma(res->accel_sigma, res->gyro_sigma));
  }
  const double n = static_cast<double>(err.size());
  std::printf("  runs ok %zu, failed %d\n", err.size(), failed);
  std::printf("  %-11s %12s %12s %10s %12s %10s  %s\n", "param", "mean err", "spread", "mean/spr",
              "rms sigma", "sig/spr", "verdict");
  int bad = 0;
  for (int i = 0; i < kParams; ++i) {
    double mean = 0, ms = 0;
    for (std::size_t k = 0; k < err.size(); ++k) {
      mean += err[k][i];
      ms += sig[k][i] * sig[k][i];
    }
    mean /= n;
    double var = 0;
    for (const auto& e : err) var += (e[i] - mean) * (e[i] - mean);
    const double spread = std::sqrt(var / (n - 1));
    const double rms_sigma = std::sqrt(ms / n);
    const double r1 = std::abs(mean) / spread, r2 = rms_sigma / spread;
    const bool ok = r1 < 0.3 && r2 < 1.5 && r2 > 1.0 / 1.5;
    bad += ok ? 0 : 1;
    std::printf("  %-11s %12.4e %12.4e %10.3f %12.4e %10.3f  %s\n", kNames[i], mean, spread, r1, rms_sigma,
                r2, ok ? "ok" : "FAIL");
  }
  std::printf("  parameters outside the criteria (|mean| < 0.3 spread, sigma/spread in [1/1.5, 1.5]): %d\n",
              bad);
}

/// CPU time of this thread, s: meaningful on a loaded machine, unlike wall time.
double cpu_now() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void run_speed(int runs) {
  // A ~512 s recording: 100 poses and a still start long enough to fill it.
  Recording rec = simulate(77, 100, false);
  const double missing_s = 512.0 - static_cast<double>(rec.samples.size()) / kRateHz;
  if (missing_s > 0) rec = simulate(77, 100, false, 50.0 + missing_s);
  const std::string dir =
      std::filesystem::temp_directory_path() / ("bench_static_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/static.imulog";
  {
    log::SessionLogWriterOptions wo;
    wo.overwrite = true;
    auto w = log::SessionLogWriter::create(path, wo);
    if (!w.ok()) {
      std::fprintf(stderr, "cannot write %s: %s\n", path.c_str(), w.error().message.c_str());
      std::exit(1);
    }
    auto id = (*w)->add_imu_stream(rec.info);
    if (!id.ok() || !(*w)->append_imu(*id, rec.samples).ok() || !(*w)->close().ok()) {
      std::fprintf(stderr, "writing the log failed\n");
      std::exit(1);
    }
  }
  std::printf(
      "== speed: %.1f s recording, %zu samples at 100 Hz, one thread, %d runs (median CPU time of the "
      "thread)\n",
      static_cast<double>(rec.samples.size()) / kRateHz, rec.samples.size(), runs);
  std::vector<double> t_import, t_det, t_thr, t_acc, t_gyro, t_total, t_wall;
  int transfers = 0, intervals = 0;
  for (int r = 0; r < runs; ++r) {
    const auto w0 = std::chrono::steady_clock::now();
    const double t0 = cpu_now();
    auto log = log::SessionLogReader::open(path);
    if (!log.ok()) std::exit(1);
    auto id = (*log)->find_imu_stream();
    auto samples = (*log)->read_imu(*id);
    if (!samples.ok()) std::exit(1);
    const ImuStreamInfo info = (*log)->imu_streams().at(*id);
    const double t1 = cpu_now();
    auto res = calib::calibrate_static(*samples, options_for(info));
    const double t2 = cpu_now();
    const auto w2 = std::chrono::steady_clock::now();
    if (!res.ok()) {
      std::fprintf(stderr, "calibration failed: %s\n", res.error().message.c_str());
      std::exit(1);
    }
    t_import.push_back(t1 - t0);
    t_total.push_back(t2 - t0);
    t_wall.push_back(std::chrono::duration<double>(w2 - w0).count());
    t_det.push_back(res->timings.detector_s);
    t_thr.push_back(res->timings.threshold_search_s);
    t_acc.push_back(res->timings.accel_s);
    t_gyro.push_back(res->timings.gyro_s);
    transfers = res->gyro_transfers;
    intervals = static_cast<int>(res->intervals.size());
  }
  std::filesystem::remove_all(dir);
  std::printf("  static intervals %d, gyro transfers %d\n", intervals, transfers);
  std::printf("  import (open + read)  %8.4f s\n", median(t_import));
  std::printf("  detector + T_init     %8.4f s\n", median(t_det));
  std::printf("  threshold search      %8.4f s\n", median(t_thr));
  std::printf("  accel (final + cov)   %8.4f s\n", median(t_acc));
  std::printf("  gyro (solve + cov)    %8.4f s\n", median(t_gyro));
  std::printf("  total                 %8.4f s\n", median(t_total));
  std::printf("  (wall time of the total %8.4f s: depends on the machine load)\n", median(t_wall));
}

}  // namespace

int main(int argc, char** argv) {
  int seeds = 100, runs = 7;
  bool stats = true, speed = true;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--seeds") && i + 1 < argc)
      seeds = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--speed-runs") && i + 1 < argc)
      runs = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--skip-stats"))
      stats = false;
    else if (!std::strcmp(argv[i], "--skip-speed"))
      speed = false;
    else {
      std::fprintf(stderr, "usage: %s [--seeds N] [--speed-runs N] [--skip-stats] [--skip-speed]\n", argv[0]);
      return 2;
    }
  }
  if (speed) run_speed(std::max(1, runs));
  if (stats) run_stats(std::max(3, seeds));
  return 0;
}
