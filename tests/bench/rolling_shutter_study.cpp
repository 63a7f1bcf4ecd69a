// SPDX-License-Identifier: BSD-3-Clause
// What ignoring a rolling shutter costs, and what modelling it gives back (docs/benchmarks.md,
// "Rolling shutter"). For each line delay and motion scale, a recording of the analytic generator
// (tests/support/rs_analytic_rig.hpp: it shares no code with the simulator; 752 x 480, 20 Hz,
// 200 Hz IMU, checkerboard) is calibrated twice from the true lens with the shutter unknown: with
// --shutter global and with the default (auto). Prints, per run, the errors of T_cam_imu and the
// time offset against the truth, the reprojection RMS, the shutter chosen, the line delay found and
// the CPU time.
//
//   rolling_shutter_study [--line-delays-us 0,15,30,60] [--motion-scales 0.5,1,1.5] [--seed 11]
//                         [--duration 30] [--threads 2]

#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "calib/camimu_calibration.hpp"
#include "calib/so3.hpp"
#include "tests/support/rs_analytic_rig.hpp"

namespace imucal {
namespace {

double cpu_s() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

void run_one(const test::RsAnalyticRig& rig, calib::CamImuShutterOptions::Mode mode, int threads,
             const char* label, double line_delay_us, double scale) {
  calib::CamImuOptions o;
  o.threads = threads;
  o.model = CamImuModelKind::kBasic;  // the generator's IMU has biases only
  o.shutter.mode = mode;
  calib::CamImuCameraInput cam = rig.camera;
  cam.camera.shutter = Shutter{};  // unknown to the solve, as in a user's camera file
  const double c0 = cpu_s();
  auto r = calib::calibrate_camimu(rig.imu, {cam}, rig.target, o);
  const double cpu = cpu_s() - c0;
  if (!r.ok()) {
    std::printf("| %5.0f | %4.1f | %-6s | failed: %s |\n", line_delay_us, scale, label,
                r.error().message.c_str());
    return;
  }
  const CamImuCameraResult& c = r->cameras[0];
  const double dt_mm = 1e3 * (c.T_cam_imu.translation() - rig.T_cam_imu.translation()).norm();
  const double dr_deg =
      180.0 / M_PI * calib::so3::log(c.T_cam_imu.linear() * rig.T_cam_imu.linear().transpose()).norm();
  const double dshift_ms = 1e3 * (c.timeshift_cam_imu_s - rig.timeshift_s);
  const double t_sigma_mm = 1e3 * c.translation_sigma_m.norm();
  const bool rolling = c.camera.shutter.rolling();
  char ld[64] = "-";
  if (rolling)
    std::snprintf(ld, sizeof ld, "%.2f +- %.2f", 1e6 * c.camera.shutter.line_delay_s,
                  1e6 * c.line_delay_sigma_s);
  std::printf(
      "| %5.0f | %4.1f | %-6s | %7.2f (%.2f) | %6.3f | %+7.3f (%.3f) | %6.3f | %-7s | %-14s | %5.1f |\n",
      line_delay_us, scale, label, dt_mm, t_sigma_mm, dr_deg, dshift_ms, 1e3 * c.timeshift_sigma_s,
      c.reprojection_rms_px, rolling ? "rolling" : "global", ld, cpu);
}

}  // namespace
}  // namespace imucal

int main(int argc, char** argv) {
  using namespace imucal;
  CLI::App app{"What ignoring a rolling shutter costs in the camera-IMU solve (analytic generator)"};
  std::vector<double> delays{0.0, 15.0, 30.0, 60.0};
  std::vector<double> scales{0.5, 1.0, 1.5};
  std::uint64_t seed = 11;
  double duration = 30.0;
  int threads = 2;
  app.add_option("--line-delays-us", delays, "Line delays to generate, us per row")->delimiter(',');
  app.add_option("--motion-scales", scales, "Motion amplitude scales")->delimiter(',');
  app.add_option("--seed", seed, "Generator seed");
  app.add_option("--duration", duration, "Recording length, s");
  app.add_option("--threads", threads, "Solver threads");
  CLI11_PARSE(app, argc, argv);
  std::printf(
      "| line delay us | motion | shutter | |dt| mm (sigma) | |dR| deg | d offset ms (sigma) | RMS px | "
      "chosen | line "
      "delay us | CPU s |\n|---|---|---|---|---|---|---|---|---|---|\n");
  for (double d : delays) {
    for (double s : scales) {
      test::RsAnalyticOptions ro;
      ro.seed = seed;
      ro.duration_s = duration;
      ro.line_delay_s = 1e-6 * d;
      ro.motion_scale = s;
      const auto rig = test::make_rs_analytic_rig(ro);
      run_one(rig, calib::CamImuShutterOptions::Mode::kGlobal, threads, "global", d, s);
      run_one(rig, calib::CamImuShutterOptions::Mode::kAuto, threads, "auto", d, s);
      std::fflush(stdout);
    }
  }
  return 0;
}
