// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate thermal LOG: bias against die temperature from a still recording over a
// temperature range (docs/thermal.md).

#include <fmt/printf.h>
#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/initial_guess.hpp"
#include "app/results/output.hpp"
#include "app/results/thermal_results.hpp"
#include "app/streams.hpp"
#include "calib/thermal_calibration.hpp"
#include "core/text_format.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct ThermalCliOptions {
  std::string log_path;
  std::string stream;
  std::string yaml_path;
  double min_span_c = 3.0;
  double bin_s = 20.0;
  int max_order = 3;
  std::optional<double> reference_c;
  std::vector<std::string> scale_from;  // static pose recordings at other die temperatures
  bool allow_damaged = false;
  bool force = false;
};

void print_summary(const calib::ThermalResult& r, const std::string& log_path, const ImuStreamInfo& info) {
  std::cout << "thermal model of " << log_path << " (" << info.name << ", " << r.samples << " samples, "
            << fixed(r.duration_s, 0) << " s, " << r.bins << " bins of " << fixed(r.bin_s, 1) << " s)\n"
            << "  die temperature " << fixed(r.temp_min_c, 2) << " to " << fixed(r.temp_max_c, 2)
            << " deg C, reference " << fixed(r.reference_c, 2) << " deg C\n";
  constexpr double kDegPerRad = 180.0 / 3.14159265358979323846;
  for (int a = 0; a < 3; ++a) {
    const auto& g = r.gyro[a];
    std::cout << "  gyro "
              << "xyz"[a] << ": order " << g.order << ", drift over the range "
              << fmt::sprintf("%.4f", g.uncompensated_drift * kDegPerRad) << " deg/s, residual RMS "
              << fmt::sprintf("%.4f", g.residual_rms * kDegPerRad) << " deg/s, model sigma "
              << fmt::sprintf("%.4f", g.model_sigma_rms * kDegPerRad) << " deg/s\n";
  }
  for (int a = 0; a < 3; ++a) {
    const auto& c = r.accel[a];
    std::cout << "  accel "
              << "xyz"[a] << ": order " << c.order << ", drift over the range "
              << fmt::sprintf("%.2f", c.uncompensated_drift / kStandardGravity * 1e3) << " mg, residual RMS "
              << fmt::sprintf("%.2f", c.residual_rms / kStandardGravity * 1e3) << " mg, model sigma "
              << fmt::sprintf("%.2f", c.model_sigma_rms / kStandardGravity * 1e3) << " mg\n";
  }
  const auto& s = r.scale;
  if (!s.determined) {
    std::cout << "  scale against temperature: not determined: " << s.reason << "\n";
    return;
  }
  std::cout << "  scale against temperature from " << s.points.size() << " static calibrations at";
  for (const auto& p : s.points) std::cout << " " << fixed(p.temperature_c, 2);
  std::cout << " deg C (k: relative change of the sensitivity per K, ppm/K):\n";
  const auto ppm = [](double v) {
    return std::isfinite(v) ? fmt::sprintf("%.1f", v * 1e6) : "not determined";
  };
  for (int a = 0; a < 3; ++a) {
    std::cout << "  gyro "
              << "xyz"[a] << ": k " << ppm(s.model.gyro_k[a]) << " +- " << ppm(s.model.gyro_sigma[a])
              << "   accel "
              << "xyz"[a] << ": k " << ppm(s.model.accel_k[a]) << " +- " << ppm(s.model.accel_sigma[a])
              << "\n";
  }
}

void run(const ThermalCliOptions& o) {
  // Never an input (the log, the static pose recordings), whatever --force says.
  app::OutputPolicy outputs{o.force, {o.log_path}};
  outputs.inputs.insert(outputs.inputs.end(), o.scale_from.begin(), o.scale_from.end());
  if (auto s = app::check_output(o.yaml_path, outputs); !s.ok()) fail(s.error());

  Progress progress("thermal calibration", 2.0 + static_cast<double>(o.scale_from.size()));
  auto loaded = app::load_imu_stream(
      o.log_path, o.stream, o.allow_damaged ? app::DamagePolicy::kAllow : app::DamagePolicy::kRefuse);
  if (!loaded.ok()) {
    if (loaded.error().code == Errc::kCorrupt) {
      throw CliExit{kExitInput, loaded.error().message + "; pass --allow-damaged to use what is readable"};
    }
    fail(loaded.error());
  }
  progress.update(1.0);
  const ImuStreamInfo& info = loaded->info;

  calib::ThermalOptions opt;
  auto guess = app::nominal_guess(info, {});
  // An SI stream needs no conversion; a raw one needs its full-scale ranges (the accelerometer's
  // offset does not matter: c0 takes it).
  const bool si = info.units == ImuUnits::kSi;
  if (!si && (!guess.ok() || !guess->accel)) {
    throw CliExit{kExitUsage,
                  "stream " + info.name +
                      " is in raw counts and the log gives no full-scale range to convert them to "
                      "SI: record with the ranges in the log (imucal record writes them)"};
  }
  if (!si) {
    opt.accel = *guess->accel;
    opt.gyro = guess->gyro;
  }
  opt.temperature_scale = info.temperature_scale;
  opt.temperature_offset = info.temperature_offset;
  opt.min_span_c = o.min_span_c;
  opt.bin_s = o.bin_s;
  opt.max_order = o.max_order;
  opt.reference_c = o.reference_c;
  if (auto valid = opt.validate(); !valid.ok()) throw CliExit{kExitUsage, valid.error().message};

  auto res = calib::calibrate_thermal(loaded->samples, opt);
  progress.update(2.0);
  if (!res.ok()) fail(res.error(), "thermal calibration of " + o.log_path);
  if (!res->determined) {
    throw CliExit{kExitData, "thermal calibration of " + o.log_path + ": not determined: " + res->reason};
  }
  if (o.scale_from.empty()) {
    res->scale.reason += " (static pose recordings at two or more die temperatures do: --scale-from)";
  } else {
    // Scale against temperature: each recording of static poses calibrated on its own.
    std::vector<calib::ThermalScalePoint> points;
    for (std::size_t i = 0; i < o.scale_from.size(); ++i) {
      auto p = app::scale_point_from_log(o.scale_from[i], o.stream, res->warnings);
      if (!p.ok()) fail(p.error());
      points.push_back(std::move(*p));
      progress.update(2.0 + static_cast<double>(i + 1));
    }
    res->scale = calib::fit_scale_against_temperature(std::move(points), res->reference_c, o.min_span_c);
  }
  progress.finish();
  if (loaded->damaged()) {
    res->warnings.insert(res->warnings.begin(),
                         loaded->damage_warning() + ": calibrated from its readable part only");
  }
  for (const auto& w : res->warnings) spdlog::warn("{}", w);
  if (auto s = app::write_text_file(o.yaml_path, app::thermal_result_yaml(*res, info, o.log_path), outputs);
      !s.ok()) {
    fail(s.error());
  }
  print_summary(*res, o.log_path, info);
  std::cout << "wrote " << o.yaml_path << "\n";
}

void setup(CLI::App& root) {
  CLI::App* cmd = calibrate_group(root)->add_subcommand(
      "thermal",
      "Gyro and accelerometer bias against die temperature (polynomial, order 0..3 chosen by the data) from "
      "a "
      "still "
      "recording over a temperature range: a warm-up from cold, a heat soak, holds at several temperatures");
  auto o = std::make_shared<ThermalCliOptions>();
  cmd->add_option(
         "LOG", o->log_path,
         "Session log (.imulog) of the rig standing still, untouched, while its die temperature moves")
      ->required();
  cmd->add_option("-o,--output", o->yaml_path, "Write the thermal model as YAML")->required();
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  cmd->add_option("--min-span", o->min_span_c,
                  "Smallest span of die temperature (deg C) that determines a model (default 3)")
      ->check(CLI::Range(0.5, 100.0));
  cmd->add_option("--bin", o->bin_s,
                  "Length of the time bins the samples are averaged in, s (default 20; longer for long "
                  "recordings, at most 200 bins)")
      ->check(CLI::Range(1.0, 3600.0));
  cmd->add_option("--max-order", o->max_order, "Highest polynomial order tried, 0..3 (default 3)")
      ->check(CLI::Range(0, 3));
  cmd->add_option("--reference", o->reference_c,
                  "Reference temperature, deg C (default: the middle of the range covered)")
      ->check(CLI::Range(-60.0, 150.0));
  cmd->add_option("--scale-from", o->scale_from,
                  "A recording of static poses (as calibrate static takes) at one die temperature; two or "
                  "more at different temperatures give the scale factors against temperature (repeat the "
                  "option)")
      ->check(CLI::ExistingFile);
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_flag("--force", o->force, "Replace the output if it exists (never the log)");
  cmd->footer(
      "The rig must not move: a step between 1 s means above 0.01 rad/s (gyro) or 0.1 m/s^2 (accelerometer) "
      "is refused. Exit 4 when the log has no temperature, the rig moved, or the span is below --min-span. "
      "Scale against temperature is not determined from one attitude: give --scale-from recordings of static "
      "poses at two or more die temperatures (their span at least --min-span).");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(35, setup);

}  // namespace
}  // namespace imucal::cli
