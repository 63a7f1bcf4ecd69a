// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate gsens LOG: the static six-orientation g-sensitivity experiment (Krebs 2012,
// section 5.2.3), see docs/gsens.md.

#include <fmt/printf.h>
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>
#include <string>

#include "app/calibration_check.hpp"
#include "app/initial_guess.hpp"
#include "app/results/gsens_results.hpp"
#include "app/results/output_checks.hpp"
#include "app/streams.hpp"
#include "calib/gsens_calibration.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct GsensCliOptions {
  std::string log_path;
  std::string stream;
  GravityArgs grav;
  std::string intrinsics_path;
  double min_hold_s = 10.0;
  double window_s = 1.0;
  bool allow_damaged = false;
  bool force = false;
  std::string yaml_path;
  std::string json_path;
};

/// The models the holds are read through: a prior calibration of the same stream, or the log's
/// nominal conversion with the MPU-6000's sensitivity tolerance in the sigmas. Returns where they
/// come from.
std::string set_models(const GsensCliOptions& o, const ImuStreamInfo& info, calib::GSensitivityOptions* opt) {
  if (!o.intrinsics_path.empty()) {
    auto prior = app::read_imucal_calibration(o.intrinsics_path);
    if (!prior.ok()) fail(prior.error(), "--imu-intrinsics");
    if (prior->input_units && *prior->input_units != info.units) {
      throw CliExit{kExitUsage, "--imu-intrinsics " + o.intrinsics_path + " is for " +
                                    imu_units_name(*prior->input_units) + " input, but stream " + info.name +
                                    " is " + imu_units_name(info.units) +
                                    ": give the calibration of this stream (imucal calibrate static -o)"};
    }
    opt->A_a = prior->model.A_a;
    opt->b_a = prior->model.b_a;
    opt->A_g = prior->model.A_g;
    return o.intrinsics_path;
  }
  auto guess = app::nominal_guess(info, {});
  if (!guess.ok() || !guess->accel) {
    throw CliExit{kExitUsage, "stream " + info.name +
                                  " is in raw counts and the log gives no full-scale range to convert them: "
                                  "give --imu-intrinsics RESULT.yaml (imucal calibrate static -o)"};
  }
  opt->A_a = guess->accel->scale.asDiagonal();
  opt->b_a = guess->accel->offset;
  opt->A_g = guess->gyro.scale.asDiagonal();
  opt->accel_model_rel_sigma = calib::kNominalModelRelSigma;
  opt->gyro_model_rel_sigma = calib::kNominalModelRelSigma;
  opt->accel_offset_sigma_mps2 = calib::kNominalAccelOffsetSigma;
  return "nominal conversion";
}

std::string sci(double v) { return fmt::sprintf("%10.3e", v); }

void print_summary(const std::string& log_path, const ImuStreamInfo& info, std::size_t samples,
                   const std::string& models, const GSensitivityResult& r) {
  std::cout << "g-sensitivity of " << log_path << " (" << info.name << ", " << samples << " samples, "
            << imu_units_name(info.units) << "): " << r.holds.size() << " holds (";
  for (std::size_t k = 0; k < r.holds.size(); ++k) {
    const auto& h = r.holds[k];
    std::cout << (k ? ", " : "") << (h.face.empty() ? "tilted" : h.face) << " "
              << fmt::sprintf("%.1f s", ns_to_s(h.t1_ns - h.t0_ns));
  }
  std::cout << ")\n  models: " << models;
  if (r.gyro_model_rel_sigma > 0.0)
    std::cout << " (in the sigmas: scales uncertain by " << 100.0 * r.gyro_model_rel_sigma
              << " %, accelerometer offsets by " << r.accel_offset_sigma_mps2 << " m/s^2)";
  std::cout << "\n  G, rad/s per m/s^2 (+- 1 sigma):\n";
  for (int row = 0; row < 3; ++row) {
    std::cout << "   ";
    for (int c = 0; c < 3; ++c) std::cout << " " << sci(r.G(row, c)) << " +- " << sci(r.G_sigma(row, c));
    std::cout << "\n";
  }
  std::cout << "  b_g, input units: [" << r.b_g[0] << ", " << r.b_g[1] << ", " << r.b_g[2] << "] +- ["
            << r.b_g_sigma[0] << ", " << r.b_g_sigma[1] << ", " << r.b_g_sigma[2] << "]\n"
            << "  residual RMS " << r.residual_rms_radps << " rad/s, chi2/dof " << r.chi2_per_dof << " ("
            << r.dof.residuals << " residuals, " << r.dof.parameters << " parameters)";
  if (r.earth_rate_removed != 0.0) std::cout << ", Earth rate removed " << r.earth_rate_removed;
  std::cout << "\n";
  if (r.warnings.empty()) std::cout << "  no warnings\n";
}

void run(const GsensCliOptions& o) {
  // Outputs are checked before the work: never the log or the prior, never each other, never an
  // existing file without --force.
  app::OutputPolicy outputs{o.force, {o.log_path}};
  if (!o.intrinsics_path.empty()) outputs.inputs.push_back(o.intrinsics_path);
  if (auto s = app::check_outputs({{"-o", o.yaml_path}, {"--json", o.json_path}}, outputs); !s.ok())
    fail(s.error());
  const app::GravityChoice gravity = resolve_gravity(o.grav);
  calib::GSensitivityOptions opt;
  opt.gravity_mps2 = gravity.mps2;
  opt.latitude_deg = o.grav.latitude_deg;
  opt.min_hold_s = o.min_hold_s;
  opt.window_s = o.window_s;

  auto loaded = app::load_imu_stream(
      o.log_path, o.stream, o.allow_damaged ? app::DamagePolicy::kAllow : app::DamagePolicy::kRefuse);
  if (!loaded.ok()) fail(loaded.error());
  const ImuStreamInfo& info = loaded->info;
  const std::string models = set_models(o, info, &opt);
  if (auto valid = opt.validate(); !valid.ok()) throw CliExit{kExitUsage, valid.error().message};

  auto res = calib::calibrate_gsens(loaded->samples, opt);
  if (!res.ok()) fail(res.error(), "g-sensitivity of " + o.log_path);
  if (loaded->damaged()) {
    res->warnings.insert(res->warnings.begin(),
                         loaded->damage_warning() + ": calibrated from its readable part only");
  }
  for (const auto& w : res->warnings) spdlog::warn("{}", w);

  const app::GSensProvenance provenance{models, gravity.source};
  if (!o.yaml_path.empty()) {
    if (auto s = app::write_text_file(o.yaml_path, app::gsens_result_yaml(*res, info, provenance), outputs);
        !s.ok())
      fail(s.error());
  }
  if (!o.json_path.empty()) {
    if (auto s = app::write_text_file(o.json_path, app::gsens_result_json(*res, info, provenance), outputs);
        !s.ok())
      fail(s.error());
  }
  print_summary(o.log_path, info, loaded->samples.size(), models, *res);
}

void setup(CLI::App& root) {
  CLI::App* cmd = calibrate_group(root)->add_subcommand(
      "gsens", "Gyro g-sensitivity from still holds with each of the six faces up (Krebs 2012, 5.2.3)");
  auto o = std::make_shared<GsensCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) of the six-face holds")->required();
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  add_gravity_options(cmd, &o->grav);
  cmd->add_option("--imu-intrinsics", o->intrinsics_path,
                  "Accelerometer and gyro calibration of the same stream (result YAML of calibrate static); "
                  "default: the log's nominal conversion");
  cmd->add_option("--min-hold", o->min_hold_s,
                  "Shortest hold used, s (after trimming one window at each end)")
      ->check(CLI::Range(1.0, 3600.0));
  cmd->add_option("--window", o->window_s, "Static detector window t_w, s")->check(CLI::Range(0.05, 10.0));
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path,
                  "Write the result as YAML (readable by calibrate static --gsens fix)");
  cmd->add_option("--json", o->json_path, "Write the result as JSON");
  cmd->add_flag("--force", o->force, "Replace result files that exist (never the log)");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(34, setup);

}  // namespace
}  // namespace imucal::cli
