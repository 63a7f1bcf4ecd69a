// SPDX-License-Identifier: BSD-3-Clause
// The static calibration against the virtual rig's truth over many seeds: for every parameter the
// mean error, the spread of the errors and the RMS of the reported sigmas, so that bias (mean
// error against spread) and honesty (reported sigma against spread) can be read off. Each seed
// draws an MPU-6000 (with its g-sensitivity), records the 40-pose static protocol through the
// register emulator, driver and acquisition loop, and calibrates the log as `imucal calibrate
// static` does.
//
//   static_study [SEEDS] [SCRATCH_DIR] [--gsens estimate|off] [--first-seed N]
//   (defaults: 50, /tmp, estimate, 1)
//
// docs/static-calibration.md ("On the virtual rig") records its output.

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "app/initial_guess.hpp"
#include "app/streams.hpp"
#include "calib/static_calibration.hpp"
#include "core/imu_model.hpp"
#include "sim/motion.hpp"
#include "sim/session.hpp"
#include "sim/truth.hpp"

namespace imucal {
namespace {

struct Stat {
  std::vector<double> err, sigma;
};

struct Row {
  std::string name;
  double mean = 0, spread = 0, sigma_rms = 0;
};

Row summarize(const std::string& name, const Stat& s) {
  Row r;
  r.name = name;
  const double n = static_cast<double>(s.err.size());
  for (double e : s.err) r.mean += e / n;
  double ss = 0, sg = 0;
  for (double e : s.err) ss += (e - r.mean) * (e - r.mean);
  for (double g : s.sigma) sg += g * g / n;
  r.spread = std::sqrt(ss / std::max(1.0, n - 1));
  r.sigma_rms = std::sqrt(sg);
  return r;
}

int run(int first_seed, int seeds, const std::string& scratch, GSensitivityMode mode) {
  std::map<std::string, Stat> stats;
  std::vector<std::string> order;
  auto add = [&](const std::string& name, double err, double sigma) {
    if (!stats.count(name)) order.push_back(name);
    stats[name].err.push_back(err);
    stats[name].sigma.push_back(sigma);
  };
  double dir_sum = 0;
  int done = 0;
  const std::string log = scratch + "/static_study_" + std::to_string(getpid()) + ".imulog";
  for (int seed = first_seed; seed < first_seed + seeds; ++seed) {
    sim::SimImuSessionOptions so;
    so.seed = static_cast<std::uint64_t>(seed);
    so.imu = sim::ImuModelParams::draw(so.seed);
    so.imu.accel_full_scale_g = 4;
    so.imu.gyro_full_scale_dps = 500;
    so.overwrite = true;
    sim::StaticProtocolOptions po;
    so.poses = po.poses;
    auto traj = sim::make_static_protocol(po, so.seed);
    if (!traj.ok()) return std::fprintf(stderr, "%s\n", traj.error().message.c_str()), 1;
    auto truth = sim::write_sim_imu_session(so, **traj, log, "");
    if (!truth.ok()) return std::fprintf(stderr, "%s\n", truth.error().message.c_str()), 1;
    auto loaded = app::load_imu_stream(log, "", app::DamagePolicy::kRefuse);
    if (!loaded.ok()) return std::fprintf(stderr, "%s\n", loaded.error().message.c_str()), 1;
    auto guess = app::nominal_guess(loaded->info, {});
    if (!guess.ok()) return std::fprintf(stderr, "%s\n", guess.error().message.c_str()), 1;
    calib::StaticCalibrationOptions opt;
    opt.gravity_mps2 = so.imu.gravity_mps2;
    opt.accel_init = guess->accel;
    opt.gyro_init = guess->gyro;
    opt.gsens = mode;
    auto res = calib::calibrate_static(loaded->samples, opt);
    if (!res.ok()) {
      std::fprintf(stderr, "seed %d: %s\n", seed, res.error().message.c_str());
      continue;
    }
    ++done;
    dir_sum += res->quality.gyro_after.mean_rad;
    // The truth in Tedaldi's frame and form, in counts; the biases wander, so their truth is their
    // mean over the recording (converted with the nominal sensitivity, as the log's counts are).
    const TedaldiImuModel t = sim::tedaldi_form(truth->imu, true).model;
    const CanonicalImuModel tc = sim::canonical_in_tedaldi_frame(truth->imu, true);
    const Eigen::Vector3d lsb_a = loaded->info.accel.scale, lsb_g = loaded->info.gyro.scale;
    const Eigen::Vector3d b_a = truth->recording.accel_bias_mean.cwiseQuotient(lsb_a);
    const Eigen::Vector3d b_g = truth->recording.gyro_bias_mean.cwiseQuotient(lsb_g);
    const char* ax = "xyz";
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        if (i == j) continue;
        if (i < j) {
          add(std::string("accel T") + ax[i] + ax[j], res->model.accel.T(i, j) - t.accel.T(i, j),
              res->accel_sigma.T(i, j));
        }
        add(std::string("gyro T") + ax[i] + ax[j], res->model.gyro.T(i, j) - t.gyro.T(i, j),
            res->gyro_sigma.T(i, j));
      }
    }
    for (int i = 0; i < 3; ++i) {
      add(std::string("accel scale ") + ax[i], res->model.accel.scale[i] / t.accel.scale[i] - 1.0,
          res->accel_sigma.scale[i] / t.accel.scale[i]);
      add(std::string("accel bias ") + ax[i], -res->model.accel.bias[i] - b_a[i], res->accel_sigma.bias[i]);
      add(std::string("gyro scale ") + ax[i], res->model.gyro.scale[i] / t.gyro.scale[i] - 1.0,
          res->gyro_sigma.scale[i] / t.gyro.scale[i]);
      add(std::string("gyro bias ") + ax[i], -res->model.gyro.bias[i] - b_g[i], res->gyro_sigma.bias[i]);
    }
    if (mode == GSensitivityMode::kEstimate) {
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          add(std::string("G ") + ax[i] + ax[j], res->canonical.G(i, j) - tc.G(i, j), res->gsens_sigma(i, j));
        }
      }
    }
    std::fprintf(stderr, "\rseed %d", seed);
  }
  std::filesystem::remove(log);
  std::fprintf(stderr, "\n");
  std::printf("static calibration on the virtual rig: %d of %d seeds (from %d) calibrated, --gsens %s\n",
              done, seeds, first_seed, gsens_mode_name(mode));
  std::printf("gravity direction error after (mean over seeds of the per-session mean): %.3f mrad\n",
              1e3 * dir_sum / std::max(1, done));
  std::printf("units: T and G as stored, scale as a ratio to the truth, bias in counts\n");
  std::printf("%-16s %12s %12s %12s %8s %8s\n", "parameter", "mean err", "spread", "sigma rms", "mean/sd",
              "sig/sd");
  int bias_fail = 0, sigma_fail = 0;
  for (const auto& name : order) {
    const Row r = summarize(name, stats[name]);
    const double ms = r.spread > 0 ? std::abs(r.mean) / r.spread : 0.0;
    const double ss = r.spread > 0 ? r.sigma_rms / r.spread : 0.0;
    bias_fail += ms > 0.3 ? 1 : 0;
    sigma_fail += (ss > 1.5 || ss < 1.0 / 1.5) ? 1 : 0;
    std::printf("%-16s %12.4g %12.4g %12.4g %8.2f %8.2f%s\n", r.name.c_str(), r.mean, r.spread, r.sigma_rms,
                ms, ss, (ms > 0.3 || ss > 1.5 || ss < 1.0 / 1.5) ? "  <-" : "");
  }
  std::printf(
      "parameters with |mean error| > 0.3 spread: %d; with sigma outside spread/1.5..1.5 spread: %d\n",
      bias_fail, sigma_fail);
  return 0;
}

}  // namespace
}  // namespace imucal

int main(int argc, char** argv) {
  int seeds = 50;
  int first_seed = 1;
  std::string scratch = "/tmp";
  auto mode = imucal::GSensitivityMode::kEstimate;
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--gsens" && i + 1 < argc) {
      const std::string m = argv[++i];
      mode = m == "off" ? imucal::GSensitivityMode::kOff : imucal::GSensitivityMode::kEstimate;
    } else if (a == "--first-seed" && i + 1 < argc) {
      first_seed = std::atoi(argv[++i]);
    } else if (a == "-h" || a == "--help") {
      std::printf("usage: static_study [SEEDS] [SCRATCH_DIR] [--gsens estimate|off] [--first-seed N]\n");
      return 0;
    } else {
      positional.push_back(a);
    }
  }
  if (!positional.empty()) seeds = std::atoi(positional[0].c_str());
  if (positional.size() > 1) scratch = positional[1];
  if (seeds < 2) {
    std::fprintf(stderr, "static_study: SEEDS must be at least 2\n");
    return 2;
  }
  return imucal::run(first_seed, seeds, scratch, mode);
}
