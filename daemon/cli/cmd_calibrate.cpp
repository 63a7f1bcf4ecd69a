// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate static LOG: static multi-position IMU calibration (Tedaldi et al.), see
// docs/static-calibration.md.

#include <spdlog/spdlog.h>
#include <time.h>

#include <cmath>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "app/initial_guess.hpp"
#include "app/results/output_checks.hpp"
#include "app/results/static_results.hpp"
#include "app/results/thermal_results.hpp"
#include "app/solvers.hpp"
#include "app/streams.hpp"
#include "calib/static_calibration.hpp"
#include "daemon/cli/bag_input.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct StaticCliOptions {
  std::string log_path;
  std::vector<std::string> topics;  // LOG a ROS bag: the topics to import
  std::string stream;
  GravityArgs grav;
  double init_still_s = 0.0;
  std::string accel_scale_init, accel_offset_init, gyro_scale_init;
  bool estimate_gyro_bias = false;
  std::vector<std::string> gsens{"estimate"};
  std::string accel_model = "auto";
  std::string thermal_path;
  double window_s = 1.0;
  double min_interval_s = 0.5;
  bool allow_damaged = false;
  bool force = false;
  std::string yaml_path;
  std::string json_path;
};

/// The method's options from the command line (without the nominal guesses, which need the log).
calib::StaticCalibrationOptions method_options(const StaticCliOptions& o, double gravity_mps2) {
  calib::StaticCalibrationOptions opt;
  opt.gravity_mps2 = gravity_mps2;
  opt.init_still_s = o.init_still_s;
  opt.estimate_gyro_bias = o.estimate_gyro_bias;
  opt.latitude_deg = o.grav.latitude_deg;
  const std::string& mode = o.gsens.front();
  if (mode == "estimate" && o.gsens.size() == 1) {
    opt.gsens = GSensitivityMode::kEstimate;
  } else if (mode == "off" && o.gsens.size() == 1) {
    opt.gsens = GSensitivityMode::kOff;
  } else if (mode == "fix" && o.gsens.size() == 2) {
    opt.gsens = GSensitivityMode::kFixed;
    auto G = app::read_gsens_matrix(o.gsens[1]);
    if (!G.ok()) fail(G.error(), "--gsens fix");
    opt.gsens_fixed = *G;
  } else {
    throw CliExit{kExitUsage, "--gsens takes 'estimate', 'off' or 'fix FILE'"};
  }
  using Model = calib::StaticCalibrationOptions::AccelModel;
  static const std::map<std::string, Model> models = {{"auto", Model::kAuto},
                                                      {"full", Model::kFull},
                                                      {"faces", Model::kFaces},
                                                      {"scale-bias", Model::kScaleBias}};
  opt.accel_model = models.at(o.accel_model);
  opt.window_s = o.window_s;
  opt.min_interval_s = o.min_interval_s;

  return opt;
}

/// The command's summary on stdout.
void print_summary(const std::string& log_path, const ImuStreamInfo& info, std::size_t samples,
                   const StaticCalibrationResult& result) {
  const StaticCalibrationResult* res = &result;
  const auto& q = res->quality;
  std::cout << "static calibration of " << log_path << " (" << info.name << ", " << samples << " samples, "
            << imu_units_name(info.units) << ")\n"
            << "  still start " << res->init_still_s << " s, threshold multiplier "
            << res->threshold_multiplier << ", " << res->intervals.size() << " static intervals, "
            << res->distinct_attitudes << " distinct attitudes, " << res->gyro_transfers
            << " gyro transfers\n"
            << "  gravity magnitude error after: mean " << q.accel_after.mean_mps2 << " m/s^2, max "
            << q.accel_after.max_mps2 << " m/s^2";
  if (q.before_available) std::cout << " (before: mean " << q.accel_before.mean_mps2 << ")";
  std::cout << "\n  gravity direction error after: mean " << q.gyro_after.mean_rad << " rad, max "
            << q.gyro_after.max_rad << " rad";
  if (q.before_available) std::cout << " (before: mean " << q.gyro_before.mean_rad << ")";
  std::cout << "\n";
  std::cout << "  accelerometer: " << static_accel_model_name(res->accel_model) << " form ("
            << res->accel_model_reason << ")\n";
  const auto list = [](const std::vector<std::string>& v) {
    std::string out;
    for (const auto& s : v) out += (out.empty() ? "" : ", ") + s;
    return out.empty() ? std::string("none") : out;
  };
  std::cout << "  not determined, held at nominal: accelerometer " << list(res->accel_fixed) << "; gyroscope "
            << list(res->gyro_fixed) << "\n";
  if (res->gsens_mode == GSensitivityMode::kOff && std::isfinite(res->gsens_wald)) {
    std::cout << "  gyro g-sensitivity: not distinguishable from zero (Wald statistic " << res->gsens_wald
              << " of its 9 entries, below the chi-square 95 % point " << kGsensWaldLimit << "), neglected\n";
  }
  if (res->gsens_mode != GSensitivityMode::kOff) {
    const Eigen::Matrix3d& G = res->canonical.G;
    std::cout << "  gyro g-sensitivity (" << gsens_mode_name(res->gsens_mode) << ", deg/s per g): ";
    const double k = 180.0 / M_PI * res->gravity_mps2;
    for (int r = 0; r < 3; ++r) {
      std::cout << (r ? "; " : "[");
      for (int c = 0; c < 3; ++c) std::cout << (c ? " " : "") << G(r, c) * k;
    }
    std::cout << "]\n";
  }
  if (res->thermal) {
    std::cout << "  biases at " << res->thermal->reference_c
              << " deg C: the samples were corrected to the thermal model's reference temperature\n";
  }
  if (res->warnings.empty()) std::cout << "  no warnings\n";
}

void run(const StaticCliOptions& as_given) {
  // Outputs are checked before the work: never an input (the log or bag, the thermal model, the
  // fixed g-sensitivity), never each other, never an existing file without --force.
  app::OutputPolicy outputs{as_given.force, {as_given.log_path}};
  if (!as_given.thermal_path.empty()) outputs.inputs.push_back(as_given.thermal_path);
  if (as_given.gsens.size() == 2) outputs.inputs.push_back(as_given.gsens[1]);
  if (auto s = app::check_outputs({{"-o", as_given.yaml_path}, {"--json", as_given.json_path}}, outputs);
      !s.ok())
    fail(s.error());
  const StaticCliOptions o = with_log_of_input(as_given);
  // The options are checked before the log is read.
  const app::GravityChoice gravity = resolve_gravity(o.grav);
  calib::StaticCalibrationOptions opt = method_options(o, gravity.mps2);

  // CPU time of this thread, like the timings of calibrate_static.
  auto cpu_now = [] {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  };
  std::future<void> solver = app::load_static_solver_meanwhile();
  const double t0 = cpu_now();
  auto loaded = app::load_imu_stream(
      o.log_path, o.stream, o.allow_damaged ? app::DamagePolicy::kAllow : app::DamagePolicy::kRefuse);
  if (!loaded.ok()) fail(loaded.error());
  const ImuStreamInfo& info = loaded->info;
  // With --thermal the fit sees a copy corrected to the model's reference temperature.
  std::vector<ImuSample> corrected;
  std::optional<app::AppliedThermal> thermal;
  if (!o.thermal_path.empty()) {
    corrected = loaded->samples;
    auto file = app::read_thermal_file(o.thermal_path);
    if (!file.ok()) fail(file.error(), "--thermal");
    auto applied = app::apply_thermal_file(*file, corrected, info);
    if (!applied.ok()) fail(applied.error(), "--thermal");
    thermal = std::move(*applied);
  }
  const std::vector<ImuSample>& samples = thermal ? corrected : loaded->samples;
  const double import_s = cpu_now() - t0;

  app::NominalOverrides given;
  if (!o.accel_scale_init.empty()) given.accel_scale = parse_triple(o.accel_scale_init, "--accel-scale-init");
  if (!o.accel_offset_init.empty())
    given.accel_offset = parse_triple(o.accel_offset_init, "--accel-offset-init");
  if (!o.gyro_scale_init.empty()) given.gyro_scale = parse_triple(o.gyro_scale_init, "--gyro-scale-init");
  auto guess = app::nominal_guess(info, given);
  if (!guess.ok()) {
    throw CliExit{kExitUsage,
                  guess.error().message +
                      ": give --gyro-scale-init in rad/s per count (e.g. 1.3323e-4 for +-250 deg/s)"};
  }
  opt.accel_init = guess->accel;
  opt.gyro_init = guess->gyro;
  if (auto valid = opt.validate(); !valid.ok()) throw CliExit{kExitUsage, valid.error().message};

  auto res = app::calibrate_static(samples, opt);
  if (!res.ok()) fail(res.error(), "static calibration of " + as_given.log_path);
  if (loaded->damaged()) {
    res->warnings.insert(res->warnings.begin(),
                         loaded->damage_warning() + ": calibrated from its readable part only");
  }
  if (thermal) {
    res->thermal = thermal->model;
    res->warnings.insert(res->warnings.end(), thermal->warnings.begin(), thermal->warnings.end());
  }
  for (const auto& w : res->warnings) spdlog::warn("{}", w);
  spdlog::info(
      "CPU time: import {:.4f} s, detector {:.4f} s, threshold search {:.4f} s, accel {:.4f} s, gyro {:.4f} "
      "s",
      import_s, res->timings.detector_s, res->timings.threshold_search_s, res->timings.accel_s,
      res->timings.gyro_s);

  if (!o.yaml_path.empty()) {
    if (auto s = app::write_text_file(o.yaml_path, app::static_result_yaml(*res, info), outputs); !s.ok())
      fail(s.error());
  }
  if (!o.json_path.empty()) {
    const std::string json = app::static_result_json(*res, info, gravity.source, loaded->reader->metadata());
    if (auto s = app::write_text_file(o.json_path, json, outputs); !s.ok()) fail(s.error());
  }

  print_summary(as_given.log_path, info, samples.size(), *res);
}

void setup(CLI::App& root) {
  CLI::App* cmd = calibrate_group(root)->add_subcommand(
      "static",
      "Static multi-position IMU calibration (Tedaldi et al.): accel and gyro scale, misalignment, bias");
  auto o = std::make_shared<StaticCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) of the static protocol, or a ROS 1 bag")
      ->required();
  add_bag_topics_option(cmd, &o->topics);
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  add_gravity_options(cmd, &o->grav);
  cmd->add_option("--init-still", o->init_still_s,
                  "Length of the initial still period, s (default: found, then chosen by Allan deviation)")
      ->check(kNonNegative);
  cmd->add_option("--accel-scale-init", o->accel_scale_init,
                  "Nominal accel scale, m/s^2 per input unit: one value or 'x,y,z'");
  cmd->add_option("--accel-offset-init", o->accel_offset_init,
                  "Nominal accel offset, input units: one value or 'x,y,z'");
  cmd->add_option("--gyro-scale-init", o->gyro_scale_init,
                  "Nominal gyro scale, rad/s per input unit: one value or 'x,y,z'");
  cmd->add_flag("--estimate-gyro-bias", o->estimate_gyro_bias,
                "Estimate the gyro bias in the gyro solve (default: fitted to the still poses with the "
                "g-sensitivity, or the still start's mean with --gsens off)");
  cmd->add_option("--gsens", o->gsens,
                  "Gyro g-sensitivity: 'estimate' (default: with the gyro bias, from the still poses), 'off' "
                  "(Tedaldi's model: none, bias from the still start) or 'fix FILE' (G from a result YAML's "
                  "canonical.G or a file with G: 3 rows of 3, rad/s per m/s^2)")
      ->expected(1, 2)
      ->type_name("MODE [FILE]");
  cmd->add_option("--accel-model", o->accel_model,
                  "Accelerometer model: auto (the full model with 9 or more distinct attitudes, else the "
                  "known-orientation form when the poses lie on all six faces, else scales and biases alone "
                  "from 6), full, faces (each pose taken as lying flat on one of the six faces, as PX4 and "
                  "ArduPilot do), scale-bias (misalignment held at zero) (default auto)")
      ->check(CLI::IsMember({"auto", "full", "faces", "scale-bias"}));
  cmd->add_option("--window", o->window_s, "Static detector window t_w, s")->check(CLI::Range(0.05, 10.0));
  cmd->add_option("--min-interval", o->min_interval_s, "Shortest static interval used, s")
      ->check(CLI::Range(0.05, 60.0));
  cmd->add_option("--thermal", o->thermal_path,
                  "Correct the samples to the reference temperature of this thermal model (calibrate thermal "
                  "-o) before fitting: the biases are then those at that temperature, and the result and a "
                  "stored record carry the model")
      ->check(CLI::ExistingFile);
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path, "Write the result as YAML");
  cmd->add_option("--json", o->json_path, "Write the result as JSON");
  cmd->add_flag("--force", o->force, "Replace result files that exist (never the log)");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(30, setup);

}  // namespace
}  // namespace imucal::cli
