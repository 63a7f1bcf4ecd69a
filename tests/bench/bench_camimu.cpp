// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU calibration (calib/camimu_calibration.hpp) against the truth over many seeds:
// the accuracy and speed study of docs/benchmarks.md ("Camera-IMU calibration"). Each seed makes a
// synthetic recording (tests/calib/camimu_synth.hpp: the simulator's checkerboard motion and
// MPU-6000 error model, target corners projected with the true camera, T_cam_imu and time offset
// plus Gaussian corner noise) and calibrates it from no prior (identity extrinsics, zero offset,
// S = I, M = 0, C_bg = I, B_g = 0). For every design variable it prints the mean error, the spread
// of the errors over the seeds, the mean reported sigma and Krebs's (2012) table 5.3 value, and
// judges: spread <= paper, |mean error| < spread / 2, sigma / spread within 1/1.5 .. 1.5.
// --compare-models runs the basic and the extended model on the same seeds (Krebs 5.1.3).
//
//   bench_camimu [--seeds 20] [--first-seed 1] [--duration 90] [--imu-rate 200] [--camera-rate 20]
//                [--corner-sigma 0.03] [--model basic|extended] [--threads 2] [--timeshift 0.0042]
//                [--compare-models]

#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "calib/camimu_calibration.hpp"
#include "calib/so3.hpp"
#include "core/imu_model.hpp"
#include "tests/calib/camimu_synth.hpp"

namespace imucal {
namespace {

struct Args {
  int seeds = 20;
  int first_seed = 1;
  double duration_s = 90.0;
  double imu_rate_hz = 200.0;
  double camera_rate_hz = 20.0;
  // Per coordinate; what the detector leaves on the rendered fixture (docs/benchmarks.md).
  double corner_sigma_px = 0.03;
  std::string model = "extended";
  int threads = 2;
  double timeshift_s = 0.0042;
  bool compare = false;
  // What the estimator is told: 0 = it estimates the corner noise (the product's default).
  double assumed_corner_sigma_px = 0.0;
  double knot_spacing_s = calib::CamImuOptions{}.knot_spacing_s;
  int spline_order = calib::CamImuOptions{}.spline_order;
};

/// Errors (estimate - truth) and reported sigmas of one variable's entries over the seeds.
struct Entry {
  std::vector<double> err, sigma;
};

/// A design variable: its entries in print order and Krebs's table 5.3 value (the mean over the
/// entries of their standard deviation, for one 90 s recording).
struct Variable {
  std::string name, unit;
  double paper = 0.0;
  std::vector<std::string> entries;
};

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}
double spread(const std::vector<double>& v) {
  const double m = mean(v);
  double ss = 0;
  for (double x : v) ss += (x - m) * (x - m);
  return v.size() < 2 ? 0.0 : std::sqrt(ss / static_cast<double>(v.size() - 1));
}
double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

const char* kAxis[] = {"x", "y", "z"};

class Collector {
 public:
  void add(const std::string& name, double err, double sigma) {
    if (!entries_.count(name)) order_.push_back(name);
    entries_[name].err.push_back(err);
    entries_[name].sigma.push_back(sigma);
  }
  void add3(const std::string& prefix, const Eigen::Vector3d& err, const Eigen::Vector3d& sigma,
            const std::vector<std::string>& labels) {
    for (int i = 0; i < 3; ++i) add(prefix + " " + labels[static_cast<std::size_t>(i)], err(i), sigma(i));
  }
  const Entry& at(const std::string& name) const { return entries_.at(name); }

 private:
  std::map<std::string, Entry> entries_;
  std::vector<std::string> order_;
};

const std::vector<std::string> kXyz = {"x", "y", "z"};
const std::vector<std::string> kMEntries = {"yx", "zx", "zy"};  // M(1,0), M(2,0), M(2,1)

std::vector<std::string> prefixed(const std::string& p, const std::vector<std::string>& labels) {
  std::vector<std::string> out;
  for (const auto& l : labels) out.push_back(p + " " + l);
  return out;
}

std::vector<Variable> variables() {
  std::vector<std::string> bg;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) bg.push_back(std::string("B_g ") + kAxis[r] + kAxis[c]);
  return {{"rotation cam-IMU", "mrad", 1.586, prefixed("R_cam_imu", kXyz)},
          {"translation cam-IMU", "mm", 4.160, prefixed("t_cam_imu", kXyz)},
          {"time offset", "ms", 0.144, {"timeshift"}},
          {"M_g", "1e-3", 2.456, prefixed("M_g", kMEntries)},
          {"M_a", "1e-3", 1.745, prefixed("M_a", kMEntries)},
          {"S_g", "1e-3", 3.081, prefixed("S_g", kXyz)},
          {"S_a", "1e-3", 1.593, prefixed("S_a", kXyz)},
          {"B_g", "1e-4 (rad/s)/(m/s^2)", 2.11, bg},
          {"rotation accel-gyro C_bg", "mrad", 0.658, prefixed("C_bg", kXyz)}};
}

/// B_g in the Krebs convention of core/imu_model.hpp (w_raw = ... + B_g C_bg^T a): the simulator
/// applies its g-sensitivity to the specific force in the body frame (B_sim a), so
/// B_krebs = B_sim C_bg.
Eigen::Matrix3d krebs_b_g(const sim::ImuModelParams& t) {
  return t.g_sensitivity * t.q_body_gyro.toRotationMatrix();
}

/// Records every design variable's error, in the display units of variables().
void collect(const CamImuCalibrationResult& r, const test::CamImuSynth& s, Collector* c) {
  const CamImuCameraResult& cam = r.cameras.at(0);
  // The sigma is of delta in R_true = exp(delta) R_est (camera axes); the error is its negative,
  // which changes no spread.
  const Eigen::Vector3d drot = calib::so3::log(cam.T_cam_imu.linear() * s.T_cam_imu.linear().transpose());
  c->add3("R_cam_imu", 1e3 * drot, 1e3 * cam.rotation_sigma_rad, kXyz);
  c->add3("t_cam_imu", 1e3 * (cam.T_cam_imu.translation() - s.T_cam_imu.translation()),
          1e3 * cam.translation_sigma_m, kXyz);
  c->add("timeshift", 1e3 * (cam.timeshift_cam_imu_s - s.timeshift_s), 1e3 * cam.timeshift_sigma_s);
  const KrebsImuModel& m = r.imu;
  const KrebsImuSigma& sg = r.imu_sigma;
  const sim::ImuModelParams& t = s.truth;
  c->add3("M_g", 1e3 * (m.M_g - krebs_entries(t.gyro_misalignment)), 1e3 * sg.M_g, kMEntries);
  c->add3("M_a", 1e3 * (m.M_a - krebs_entries(t.accel_misalignment)), 1e3 * sg.M_a, kMEntries);
  c->add3("S_g", 1e3 * (m.S_g - t.gyro_scale), 1e3 * sg.S_g, kXyz);
  c->add3("S_a", 1e3 * (m.S_a - t.accel_scale), 1e3 * sg.S_a, kXyz);
  const Eigen::Matrix3d B = krebs_b_g(t);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      c->add(std::string("B_g ") + kAxis[i] + kAxis[j], 1e4 * (m.B_g(i, j) - B(i, j)), 1e4 * sg.B_g(i, j));
  // The C_bg sigma is of the right perturbation C_bg = C_est Exp(delta) (the solver's manifold).
  const Eigen::Vector3d dc = calib::so3::log(t.q_body_gyro.toRotationMatrix().transpose() * m.C_bg);
  c->add3("C_bg", 1e3 * dc, 1e3 * sg.C_bg, kXyz);
}

struct RunFigures {
  int seed = 0;
  int iterations = 0;
  double wall_s = 0, cpu_s = 0, init_s = 0, solve_s = 0, jacobian_s = 0, linear_s = 0, covariance_s = 0;
  double reprojection_rms_px = 0;
  Eigen::Vector3d accel_rms = Eigen::Vector3d::Zero(), gyro_rms = Eigen::Vector3d::Zero();
  double accel_sigma = 0, gyro_sigma = 0;
  double rot_angle_mrad = 0;
  int parameters = 0, residuals = 0;
};

test::CamImuSynthOptions synth_options(const Args& a, int seed) {
  test::CamImuSynthOptions so;
  so.seed = static_cast<std::uint64_t>(seed);
  so.duration_s = a.duration_s;
  so.imu_rate_hz = a.imu_rate_hz;
  so.camera_rate_hz = a.camera_rate_hz;
  so.corner_sigma_px = a.corner_sigma_px;
  so.timeshift_s = a.timeshift_s;
  return so;
}

/// User + system CPU time of the process so far: on a shared machine the wall time of a run
/// depends on the load, its CPU time much less.
double process_cpu_s() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  const auto sec = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
  };
  return sec(ru.ru_utime) + sec(ru.ru_stime);
}

/// One calibration from no prior, with the product's defaults unless the arguments say otherwise.
Result<CamImuCalibrationResult> calibrate(const Args& a, const test::CamImuSynth& s, CamImuModelKind kind,
                                          RunFigures* fig) {
  calib::CamImuOptions o;
  o.model = kind;
  o.threads = a.threads;
  o.corner_sigma_px = a.assumed_corner_sigma_px;
  o.knot_spacing_s = a.knot_spacing_s;
  o.spline_order = a.spline_order;
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = process_cpu_s();
  auto r = calib::calibrate_camimu(s.imu, s.cameras, s.target, o);
  fig->wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fig->cpu_s = process_cpu_s() - cpu0;
  if (!r.ok()) return r;
  const CamImuQuality& q = r->quality;
  fig->iterations = q.iterations;
  fig->init_s = q.init_s;
  fig->solve_s = q.solve_s;
  fig->jacobian_s = q.jacobian_s;
  fig->linear_s = q.linear_solver_s;
  fig->covariance_s = q.covariance_s;
  fig->reprojection_rms_px = r->cameras.at(0).reprojection_rms_px;
  fig->accel_rms = q.accel_residual_rms;
  fig->gyro_rms = q.gyro_residual_rms;
  fig->accel_sigma = q.accel_sigma;
  fig->gyro_sigma = q.gyro_sigma;
  fig->parameters = q.parameters;
  fig->residuals = q.residuals;
  fig->rot_angle_mrad =
      1e3 * calib::so3::log(r->cameras.at(0).T_cam_imu.linear() * s.T_cam_imu.linear().transpose()).norm();
  return r;
}

void progress_line(const char* model, int seed, int k, int n, const RunFigures& f) {
  std::fprintf(stderr,
               "[%2d/%2d] seed %3d %-8s: %6.1f s wall, %6.1f s CPU (init %.1f, solve %.1f, covariance %.1f), "
               "%2d iterations, "
               "rotation error %.3f mrad, reprojection RMS %.4f px\n",
               k, n, seed, model, f.wall_s, f.cpu_s, f.init_s, f.solve_s, f.covariance_s, f.iterations,
               f.rot_angle_mrad, f.reprojection_rms_px);
}

void print_header(const Args& a, const char* what) {
  std::printf(
      "%s: seeds %d..%d, %.0f s, IMU %.0f Hz, camera %.0f Hz, corner noise %.3f px per coordinate, "
      "time offset %.1f ms, %d threads\n"
      "estimator: spline order %d, knots %s, corner noise %s\n",
      what, a.first_seed, a.first_seed + a.seeds - 1, a.duration_s, a.imu_rate_hz, a.camera_rate_hz,
      a.corner_sigma_px, 1e3 * a.timeshift_s, a.threads, a.spline_order,
      a.knot_spacing_s > 0 ? ("every " + std::to_string(a.knot_spacing_s) + " s").c_str()
                           : "chosen from the motion",
      a.assumed_corner_sigma_px > 0 ? (std::to_string(a.assumed_corner_sigma_px) + " px given").c_str()
                                    : "estimated");
}

struct Verdict {
  bool spread_ok = true, mean_ok = true, sigma_ok = true;
};

Verdict judge(double m, double sd, double sig, double paper) {
  Verdict v;
  v.spread_ok = sd <= paper;
  v.mean_ok = std::abs(m) < sd / 2;
  v.sigma_ok = sd > 0 && sig / sd <= 1.5 && sig / sd >= 1.0 / 1.5;
  return v;
}

std::string verdict_text(const Verdict& v) {
  std::string s;
  s += v.spread_ok ? "ok  " : "FAIL";
  s += v.mean_ok ? " ok  " : " FAIL";
  s += v.sigma_ok ? " ok  " : " FAIL";
  return s;
}

/// The share of |error| / sigma within 1, 2 and 3 over every run of each variable's entries, and
/// over all (a normal error with an honest sigma gives 68.3, 95.4 and 99.7 %); errors without a
/// finite sigma are counted apart.
void print_coverage(const Collector& c) {
  std::printf("\ncoverage: share of |error| / sigma within 1, 2, 3 (normal: 68.3, 95.4, 99.7 %%)\n");
  std::array<int, 3> all{};
  int all_n = 0, all_missing = 0;
  for (const Variable& v : variables()) {
    std::array<int, 3> within{};
    int n = 0, missing = 0;
    for (const std::string& name : v.entries) {
      const Entry& e = c.at(name);
      for (std::size_t k = 0; k < e.err.size(); ++k) {
        if (!(std::isfinite(e.sigma[k]) && e.sigma[k] > 0.0)) {
          ++missing;
          continue;
        }
        const double z = std::abs(e.err[k]) / e.sigma[k];
        for (int b = 0; b < 3; ++b) within[static_cast<std::size_t>(b)] += z <= b + 1;
        ++n;
      }
    }
    for (int b = 0; b < 3; ++b) all[static_cast<std::size_t>(b)] += within[static_cast<std::size_t>(b)];
    all_n += n;
    all_missing += missing;
    if (n > 0)
      std::printf("%-14s %5.1f %5.1f %5.1f %%  (%d errors%s)\n", v.name.c_str(), 100.0 * within[0] / n,
                  100.0 * within[1] / n, 100.0 * within[2] / n, n,
                  missing ? (", " + std::to_string(missing) + " without a sigma").c_str() : "");
  }
  if (all_n > 0)
    std::printf("%-14s %5.1f %5.1f %5.1f %%  (%d errors, %d without a sigma)\n", "all",
                100.0 * all[0] / all_n, 100.0 * all[1] / all_n, 100.0 * all[2] / all_n, all_n, all_missing);
}

/// The accuracy table: one row per entry, then per variable the mean over its entries (the
/// paper's definition of its figure). Returns the number of failed checks.
int print_accuracy(const Collector& c, int runs) {
  std::printf(
      "\nerrors = estimate - truth over %d runs; spread = standard deviation of the errors over the "
      "runs; sigma = mean reported sigma\n",
      runs);
  std::printf("checks: spread <= paper | |mean| < spread/2 | sigma/spread in [1/1.5, 1.5]\n");
  std::printf("%-14s %10s %10s %10s %8s %9s   %s\n", "entry", "mean err", "spread", "sigma", "sig/sd",
              "paper", "spread mean  sigma");
  int failed = 0;
  for (const Variable& v : variables()) {
    std::printf("-- %s [%s]\n", v.name.c_str(), v.unit.c_str());
    double sum_sd = 0, sum_sig = 0, sum_abs_mean = 0;
    for (const std::string& name : v.entries) {
      const Entry& e = c.at(name);
      const double m = mean(e.err), sd = spread(e.err), sig = mean(e.sigma);
      const Verdict vd = judge(m, sd, sig, v.paper);
      failed += !vd.spread_ok + !vd.mean_ok + !vd.sigma_ok;
      sum_sd += sd;
      sum_sig += sig;
      sum_abs_mean += std::abs(m);
      std::printf("%-14s %10.4f %10.4f %10.4f %8.2f %9.4f   %s\n", name.c_str(), m, sd, sig,
                  sd > 0 ? sig / sd : 0.0, v.paper, verdict_text(vd).c_str());
    }
    const double n = static_cast<double>(v.entries.size());
    if (v.entries.size() > 1) {
      std::printf(
          "%-14s %10.4f %10.4f %10.4f %8.2f %9.4f   spread %s (mean |mean err|, spread, sigma over "
          "entries)\n",
          "  mean", sum_abs_mean / n, sum_sd / n, sum_sig / n, sum_sig / sum_sd, v.paper,
          sum_sd / n <= v.paper ? "ok" : "FAIL");
    }
  }
  print_coverage(c);
  return failed;
}

void print_speed(const std::vector<RunFigures>& runs) {
  std::vector<double> wall, cpu, init, solve, per_it, jac, lin, cov, its;
  for (const RunFigures& f : runs) {
    wall.push_back(f.wall_s);
    cpu.push_back(f.cpu_s);
    init.push_back(f.init_s);
    solve.push_back(f.solve_s);
    per_it.push_back(f.iterations > 0 ? f.solve_s / f.iterations : 0.0);
    jac.push_back(f.jacobian_s);
    lin.push_back(f.linear_s);
    cov.push_back(f.covariance_s);
    its.push_back(f.iterations);
  }
  std::printf("\nspeed per run (%d runs): median [min, max]\n", static_cast<int>(runs.size()));
  const auto row = [](const char* name, const std::vector<double>& v, const char* unit) {
    std::printf("  %-28s %8.2f [%.2f, %.2f] %s\n", name, median(v), *std::min_element(v.begin(), v.end()),
                *std::max_element(v.begin(), v.end()), unit);
  };
  row("wall (init+solve+covariance)", wall, "s");
  row("CPU time (user + system)", cpu, "s");
  row("initialisation", init, "s");
  row("solve", solve, "s");
  row("iterations", its, "");
  row("solve per iteration", per_it, "s");
  row("Jacobian evaluation", jac, "s");
  row("linear solver", lin, "s");
  row("covariance", cov, "s");
  std::printf("  problem: %d parameters (tangent), %d residuals\n", runs.front().parameters,
              runs.front().residuals);
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  std::printf("  peak RSS of the process: %.1f MB\n", static_cast<double>(ru.ru_maxrss) / 1024.0);
}

void print_per_seed(const std::vector<RunFigures>& runs) {
  std::printf(
      "\nper run: seed, iterations, wall s, CPU s, solve s, s/iteration, Jacobian s, linear solver s, "
      "covariance s, "
      "reprojection RMS px\n");
  for (const RunFigures& f : runs) {
    std::printf("  %4d %3d %7.2f %7.2f %7.2f %7.3f %7.2f %7.2f %7.2f %8.4f\n", f.seed, f.iterations, f.wall_s,
                f.cpu_s, f.solve_s, f.iterations > 0 ? f.solve_s / f.iterations : 0.0, f.jacobian_s,
                f.linear_s, f.covariance_s, f.reprojection_rms_px);
  }
}

int run_study(const Args& a) {
  const CamImuModelKind kind = a.model == "basic" ? CamImuModelKind::kBasic : CamImuModelKind::kExtended;
  Collector c;
  std::vector<RunFigures> runs;
  std::vector<int> failed_seeds;
  for (int k = 0; k < a.seeds; ++k) {
    const int seed = a.first_seed + k;
    const auto synth = test::make_camimu_synth(synth_options(a, seed));
    RunFigures f;
    f.seed = seed;
    auto r = calibrate(a, synth, kind, &f);
    if (!r.ok()) {
      std::fprintf(stderr, "seed %d: calibration failed: %s\n", seed, r.error().message.c_str());
      failed_seeds.push_back(seed);
      continue;
    }
    collect(*r, synth, &c);
    runs.push_back(f);
    progress_line(camimu_model_name(kind), seed, k + 1, a.seeds, f);
  }
  print_header(a, (std::string("camera-IMU calibration, ") + camimu_model_name(kind) + " model").c_str());
  std::printf("calibrated %d of %d seeds from no prior", static_cast<int>(runs.size()), a.seeds);
  for (int s : failed_seeds) std::printf(" (seed %d failed)", s);
  std::printf("\n");
  if (runs.size() < 2) return 1;
  int failed = 0;
  if (kind == CamImuModelKind::kExtended) {
    failed = print_accuracy(c, static_cast<int>(runs.size()));
  } else {
    // The basic model estimates no IMU intrinsics: only the extrinsics and the offset are judged.
    std::printf("(basic model: the IMU intrinsics are held at identity; see --compare-models)\n");
  }
  std::printf("failed checks: %d\n", failed);
  print_speed(runs);
  print_per_seed(runs);
  return failed_seeds.empty() ? 0 : 1;
}

/// The rotation error against the camera-to-gyroscope rotation R_cam_imu C_bg: the basic model
/// has no C_bg, so its "IMU" frame is whatever frame the gyroscope and accelerometer agree on best;
/// this row shows how much of its rotation error is the accelerometer-gyroscope misalignment.
void collect_gyro_frame(const CamImuCalibrationResult& r, const test::CamImuSynth& s, Collector* c) {
  const CamImuCameraResult& cam = r.cameras.at(0);
  const Eigen::Matrix3d R_cam_gyro = s.T_cam_imu.linear() * s.truth.q_body_gyro.toRotationMatrix();
  const Eigen::Matrix3d R_est = cam.T_cam_imu.linear() * r.imu.C_bg;
  c->add3("R_cam_gyro", 1e3 * calib::so3::log(R_est * R_cam_gyro.transpose()), 1e3 * cam.rotation_sigma_rad,
          kXyz);
}

/// Krebs 5.1.3: the basic model on an IMU with S, M != I biases the extrinsics.
void print_model_rows(const char* model, const Collector& c, const std::vector<RunFigures>& runs) {
  std::printf("-- %s model\n", model);
  const std::vector<std::pair<std::string, std::vector<std::string>>> groups = {
      {"mrad", prefixed("R_cam_imu", kXyz)},
      {"mrad", prefixed("R_cam_gyro", kXyz)},
      {"mm", prefixed("t_cam_imu", kXyz)},
      {"ms", {"timeshift"}}};
  for (const auto& [unit, names] : groups) {
    for (const std::string& name : names) {
      const Entry& e = c.at(name);
      double rms = 0, z = 0;
      for (std::size_t i = 0; i < e.err.size(); ++i) {
        rms += e.err[i] * e.err[i];
        z += e.sigma[i] > 0 ? e.err[i] * e.err[i] / (e.sigma[i] * e.sigma[i]) : 0.0;
      }
      const double n = static_cast<double>(e.err.size());
      std::printf(
          "  %-12s %-5s mean err %9.4f  RMS err %9.4f  spread %9.4f  mean sigma %8.4f  RMS err/sigma %7.2f\n",
          name.c_str(), unit.c_str(), mean(e.err), std::sqrt(rms / n), spread(e.err), mean(e.sigma),
          std::sqrt(z / n));
    }
  }
  Eigen::Vector3d a = Eigen::Vector3d::Zero(), g = Eigen::Vector3d::Zero();
  double sa = 0, sg = 0;
  for (const RunFigures& f : runs) {
    a += f.accel_rms / static_cast<double>(runs.size());
    g += f.gyro_rms / static_cast<double>(runs.size());
    sa = f.accel_sigma;
    sg = f.gyro_sigma;
  }
  std::printf(
      "  IMU residual RMS: accel %.5f %.5f %.5f m/s^2 (assumed white sigma %.5f), gyro %.6f %.6f %.6f rad/s "
      "(assumed %.6f)\n",
      a.x(), a.y(), a.z(), sa, g.x(), g.y(), g.z(), sg);
}

int run_compare(const Args& a) {
  Collector c_basic, c_ext;
  std::vector<RunFigures> r_basic, r_ext;
  for (int k = 0; k < a.seeds; ++k) {
    const int seed = a.first_seed + k;
    const auto synth = test::make_camimu_synth(synth_options(a, seed));
    for (const CamImuModelKind kind : {CamImuModelKind::kBasic, CamImuModelKind::kExtended}) {
      RunFigures f;
      f.seed = seed;
      auto r = calibrate(a, synth, kind, &f);
      if (!r.ok()) {
        std::fprintf(stderr, "seed %d %s: calibration failed: %s\n", seed, camimu_model_name(kind),
                     r.error().message.c_str());
        return 1;
      }
      collect(*r, synth, kind == CamImuModelKind::kBasic ? &c_basic : &c_ext);
      collect_gyro_frame(*r, synth, kind == CamImuModelKind::kBasic ? &c_basic : &c_ext);
      (kind == CamImuModelKind::kBasic ? r_basic : r_ext).push_back(f);
      progress_line(camimu_model_name(kind), seed, k + 1, a.seeds, f);
    }
  }
  print_header(a, "basic against extended model on the same recordings (Krebs 2012, 5.1.3)");
  std::printf(
      "errors = estimate - truth of the extrinsics and the offset. Each seed draws its own IMU (S, M, C_bg, "
      "B_g), so a model error biases each run its own way: it shows as RMS err/sigma well above 1 "
      "(R_cam_gyro: against R_cam_imu C_bg, with the sigma of R_cam_imu)\n");
  print_model_rows("basic", c_basic, r_basic);
  print_model_rows("extended", c_ext, r_ext);
  return 0;
}

}  // namespace
}  // namespace imucal

int main(int argc, char** argv) {
  imucal::Args a;
  CLI::App app{"Camera-IMU calibration against the truth over many synthetic recordings"};
  app.add_option("--seeds", a.seeds, "number of seeds")->check(CLI::Range(2, 100000));
  app.add_option("--first-seed", a.first_seed, "first seed");
  app.add_option("--duration", a.duration_s, "recording length, s")->check(CLI::Range(5.0, 3600.0));
  app.add_option("--imu-rate", a.imu_rate_hz, "IMU rate, Hz")->check(CLI::Range(10.0, 10000.0));
  app.add_option("--camera-rate", a.camera_rate_hz, "camera rate, Hz")->check(CLI::Range(1.0, 1000.0));
  app.add_option(
         "--corner-sigma", a.corner_sigma_px,
         "corner noise, px per coordinate (default: what the detector leaves on the rendered fixture)")
      ->check(CLI::Range(0.001, 10.0));
  app.add_option("--model", a.model, "IMU model")->check(CLI::IsMember({"basic", "extended"}));
  app.add_option("--threads", a.threads, "solver threads")->check(CLI::Range(1, 64));
  app.add_option("--timeshift", a.timeshift_s, "true time offset t_imu - t_cam, s")
      ->check(CLI::Range(-0.2, 0.2));
  app.add_option("--assumed-corner-sigma", a.assumed_corner_sigma_px,
                 "corner noise the estimator is given, px; 0: it estimates it (default)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--knot-spacing", a.knot_spacing_s,
                 "pose spline knot spacing, s (0: chosen from the motion)")
      ->check(CLI::Range(0.005, 0.5));
  app.add_option("--spline-order", a.spline_order, "pose spline order")->check(CLI::Range(4, 6));
  app.add_flag("--compare-models", a.compare, "run the basic and the extended model on the same seeds");
  CLI11_PARSE(app, argc, argv);
  return a.compare ? imucal::run_compare(a) : imucal::run_study(a);
}
