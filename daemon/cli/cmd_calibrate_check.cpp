// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate check LOG: evaluates given IMU calibrations (imucal's result YAML, imu_tk's
// calib files) on one fixed set of static intervals and motions of a recording, with two figures
// that need no ground truth; see docs/static-calibration.md, "Checking a calibration".

#include <fmt/printf.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/calibration_check.hpp"
#include "app/initial_guess.hpp"
#include "app/results/output.hpp"
#include "app/streams.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct CheckCliOptions {
  std::string log_path;
  std::string stream;
  std::vector<std::string> yaml_paths;
  std::vector<std::string> imu_tk_pairs;
  GravityArgs grav;
  double multiplier = 6.0;
  double min_interval_s = 1.0;
  bool allow_damaged = false;
  bool cross = false;
  bool force = false;
  std::string json_path;
};

std::vector<app::NamedCalibration> load_calibrations(const CheckCliOptions& o) {
  std::vector<app::NamedCalibration> out;
  for (const auto& path : o.yaml_paths) {
    auto c = app::read_imucal_calibration(path);
    if (!c.ok()) fail(c.error(), "--calibration");
    out.push_back(std::move(*c));
  }
  for (const auto& pair : o.imu_tk_pairs) {
    const auto comma = pair.find(',');
    if (comma == std::string::npos || comma == 0 || comma + 1 == pair.size() ||
        pair.find(',', comma + 1) != std::string::npos) {
      throw CliExit{kExitUsage, "--imu-tk takes two files separated by a comma, ACC.calib,GYRO.calib (got '" +
                                    pair + "')"};
    }
    auto c = app::read_imu_tk_calibration(pair.substr(0, comma), pair.substr(comma + 1));
    if (!c.ok()) fail(c.error(), "--imu-tk");
    out.push_back(std::move(*c));
  }
  return out;
}

void print_set(const app::CheckSet& set) {
  auto rel = [&set](TimeNs t) { return ns_to_s(t - set.t_first_ns); };
  std::cout << "  fixed set: " << set.intervals.size() << " static intervals (at least "
            << fmt::sprintf("%.2f", set.options.min_interval_s) << " s, varsigma below "
            << fmt::sprintf("%g", set.options.multiplier) << " x the quiet floor "
            << fmt::sprintf("%.4g", std::sqrt(set.floor_sq)) << "), " << set.transfers.size()
            << " transfers of " << set.motions << " motions";
  if (set.motions_with_gap + set.motions_with_saturation > 0) {
    std::cout << " (not used: " << set.motions_with_gap << " with a gap or reset, "
              << set.motions_with_saturation << " with saturated samples)";
  }
  std::cout << "\n  static intervals (s from the start of the recording: first-last sample, samples):\n";
  for (std::size_t k = 0; k < set.intervals.size(); ++k) {
    const auto& iv = set.intervals[k];
    std::cout << fmt::sprintf("    %3zu  %9.3f-%9.3f  %6zu\n", k, rel(iv.t0_ns), rel(iv.t1_ns), iv.size());
  }
  std::cout << "  transfers (interval -> next, s, samples):\n";
  for (const auto& tr : set.transfers) {
    std::cout << fmt::sprintf("    %3zu -> %3zu  %9.3f-%9.3f  %6zu\n", tr.from, tr.from + 1,
                              rel(set.intervals[tr.from].t1_ns), rel(set.intervals[tr.from + 1].t0_ns),
                              tr.t_s.size());
  }
}

void print_table(const std::vector<app::NamedCalibration>& cals,
                 const std::vector<app::CheckFiguresPair>& figs) {
  std::size_t width = std::string("calibration").size();
  for (const auto& c : cals) width = std::max(width, c.name.size());
  const int w = static_cast<int>(width);
  std::cout << fmt::sprintf("  %-*s  %-27s  %-27s\n", w, "", "gravity magnitude (m/s^2)",
                            "gravity direction (mrad)");
  std::cout << fmt::sprintf("  %-*s  %8s %8s %9s  %8s %8s %9s\n", w, "calibration", "mean", "rms", "max",
                            "mean", "rms", "max");
  for (std::size_t i = 0; i < cals.size(); ++i) {
    const auto& m = figs[i].gravity_magnitude_mps2;
    const auto& d = figs[i].gravity_direction_rad;
    std::cout << fmt::sprintf("  %-*s  %8.5f %8.5f %9.5f  %8.3f %8.3f %9.3f\n", w, cals[i].name.c_str(),
                              m.mean, m.rms, m.max, 1e3 * d.mean, 1e3 * d.rms, 1e3 * d.max);
  }
  const auto crossed = std::find_if(
      cals.begin(), cals.end(), [](const app::NamedCalibration& c) { return !c.accelerometer_of.empty(); });
  if (crossed != cals.end()) {
    std::cout << "  [gyro] NAME: the gyroscope (and G) of NAME with the accelerometer of "
              << crossed->accelerometer_of << "\n";
  }
  if (cals.size() < 2) return;
  // Each against the first, paired over the same intervals and transfers: is the difference of
  // the RMS more than the spread of the per-item differences makes likely by chance?
  const auto verdict = [](const app::RmsDifference& r) {
    // Equal to rounding (the same accelerometer in two files, say).
    if (std::abs(r.difference) <= 1e-9 * r.reference) return "the same";
    if (!(r.sigma > 0.0)) return "undetermined";
    if (std::abs(r.difference) <= 2.0 * r.sigma) return "no clear difference";
    return r.difference < 0.0 ? "better" : "worse";
  };
  std::cout << "  RMS against " << cals[0].name
            << " (paired over the same intervals and transfers, +- one standard "
            << "error; beyond 2 standard errors is a clear difference):\n";
  for (std::size_t i = 1; i < cals.size(); ++i) {
    const app::CheckComparison c = app::compare_checks(figs[0], figs[i]);
    const auto& m = c.gravity_magnitude_mps2;
    const auto& d = c.gravity_direction_rad;
    std::cout << fmt::sprintf(
        "  %-*s  magnitude %+.5f +- %.5f m/s^2 (%s), direction %+.3f +- %.3f mrad (%s)\n", w,
        cals[i].name.c_str(), m.difference, m.sigma, verdict(m), 1e3 * d.difference, 1e3 * d.sigma,
        verdict(d));
  }
}

void run(const CheckCliOptions& o) {
  app::OutputPolicy outputs{o.force, {o.log_path}};
  for (const auto& y : o.yaml_paths) outputs.inputs.push_back(y);
  for (const auto& pair : o.imu_tk_pairs) {
    const auto comma = pair.find(',');
    outputs.inputs.push_back(pair.substr(0, comma));
    if (comma != std::string::npos) outputs.inputs.push_back(pair.substr(comma + 1));
  }
  if (!o.json_path.empty()) {
    if (auto s = app::check_output(o.json_path, outputs); !s.ok()) fail(s.error());
  }
  if (o.yaml_paths.empty() && o.imu_tk_pairs.empty()) {
    throw CliExit{
        kExitUsage,
        "give at least one calibration to check: --calibration RESULT.yaml or --imu-tk ACC.calib,GYRO.calib"};
  }
  app::CheckSetOptions set_opt;
  set_opt.multiplier = o.multiplier;
  set_opt.min_interval_s = o.min_interval_s;
  if (auto valid = set_opt.validate(); !valid.ok()) fail(valid.error());
  // Read the calibrations first: a wrong file is found before the log is loaded.
  std::vector<app::NamedCalibration> cals = load_calibrations(o);
  if (o.cross) {
    if (cals.size() < 2) {
      throw CliExit{kExitUsage,
                    "--cross needs at least two calibrations: it checks each later one's gyroscope with the "
                    "first one's accelerometer"};
    }
    for (auto& c : app::gyro_with_first_accelerometer(cals)) cals.push_back(std::move(c));
  }

  auto loaded = app::load_imu_stream(
      o.log_path, o.stream, o.allow_damaged ? app::DamagePolicy::kAllow : app::DamagePolicy::kRefuse);
  if (!loaded.ok()) fail(loaded.error());
  const ImuStreamInfo& info = loaded->info;
  if (loaded->damaged()) spdlog::warn("{}: checked on its readable part only", loaded->damage_warning());
  for (const auto& c : cals) {
    if (c.input_units && *c.input_units != info.units) {
      throw CliExit{kExitData, c.path + " was estimated on a stream in " + imu_units_name(*c.input_units) +
                                   " units, but stream '" + info.name + "' of " + o.log_path + " is in " +
                                   imu_units_name(info.units) + " units: it cannot be applied to it"};
    }
  }

  const app::GravityChoice gravity = resolve_gravity(o.grav);

  auto set = app::build_check_set(loaded->samples, set_opt);
  if (!set.ok()) fail(set.error(), "check of " + o.log_path);
  if (set->gaps > 0 || set->accel_saturated + set->gyro_saturated > 0) {
    spdlog::warn(
        "the log has {} gap(s) or reset(s) and {} saturated accelerometer, {} gyroscope samples: no interval "
        "or transfer contains them",
        set->gaps, set->accel_saturated, set->gyro_saturated);
  }

  std::vector<app::CheckFiguresPair> figs;
  for (const auto& c : cals) {
    figs.push_back(app::check_calibration(*set, c.model, gravity.mps2));
    if (figs.back().gravity_magnitude_mps2.mean > 0.1 * gravity.mps2) {
      spdlog::warn(
          "{}: the calibrated gravity is off by {:.3g} m/s^2 on average: it does not fit this stream "
          "(other units, offsets or device?)",
          c.name, figs.back().gravity_magnitude_mps2.mean);
    }
  }

  if (!o.json_path.empty()) {
    const std::string json =
        app::calibration_check_json(o.log_path, info, *set, gravity.mps2, gravity.source, cals, figs);
    if (auto s = app::write_text_file(o.json_path, json, outputs); !s.ok()) fail(s.error());
  }

  std::cout << "calibration check on " << o.log_path << " (" << info.name << ", " << loaded->samples.size()
            << " samples, " << imu_units_name(info.units) << ", " << fmt::sprintf("%.1f", set->rate_hz)
            << " Hz), gravity " << fmt::sprintf("%.5f", gravity.mps2) << " m/s^2 (" << gravity.source
            << ")\n";
  print_set(*set);
  print_table(cals, figs);
}

void setup(CLI::App& root) {
  CLI::App* cmd = calibrate_group(root)->add_subcommand(
      "check",
      "Compare IMU calibrations (imucal, imu_tk) on one recording of static poses: gravity magnitude "
      "residual "
      "and gyro-carried gravity direction error, no ground truth needed");
  cmd->footer(
      "The static intervals and motions are found once, from the recording alone, so every calibration is\n"
      "scored on the same data: variance detector on the raw accelerometer (1 s window), static where\n"
      "varsigma < K x its 10th percentile over the recording (the quiet floor), intervals of at least\n"
      "--min-interval s, none across a gap, reset or saturated sample. Figures per calibration, mean, RMS\n"
      "and max: | |a| - g | of the interval means (m/s^2), and the angle (mrad) between the gravity\n"
      "direction measured at the start of each interval and the one the corrected gyro carries there\n"
      "through the motion from the end of the interval before. With several calibrations, each later one is\n"
      "compared with the first over the same intervals and transfers: the difference of the RMS and its\n"
      "standard error from the per-item differences (beyond 2 standard errors: a clear difference).\n"
      "The direction figure depends on both sensors' calibrations; --cross adds, for each later\n"
      "calibration, its gyroscope with the first one's accelerometer ('[gyro] NAME'), whose difference\n"
      "to the first is then the gyroscopes' alone.\n"
      "Example: imucal calibrate check rec.imulog --calibration imucal.yaml --imu-tk acc.calib,gyro.calib "
      "--gravity 9.81");
  auto o = std::make_shared<CheckCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) of static poses")->required();
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  cmd->add_option("--calibration", o->yaml_paths,
                  "imucal result YAML (calibrate static -o) to check; repeat for several")
      ->allow_extra_args(false)
      ->type_name("FILE.yaml");
  cmd->add_option(
         "--imu-tk", o->imu_tk_pairs,
         "imu_tk calib files, accelerometer and gyroscope (calibrated = T K (raw - B)); repeat for several")
      ->allow_extra_args(false)
      ->type_name("ACC.calib,GYRO.calib");
  add_gravity_options(cmd, &o->grav);
  cmd->add_option("--multiplier", o->multiplier,
                  "Static where varsigma < K x the quiet floor (its 10th percentile)")
      ->capture_default_str()
      ->check(CLI::Range(1.5, 100.0));
  cmd->add_option("--min-interval", o->min_interval_s, "Shortest static interval, s")
      ->capture_default_str()
      ->check(CLI::Range(0.05, 60.0));
  cmd->add_flag("--cross", o->cross,
                "Also check each later calibration's gyroscope with the first one's accelerometer, to tell "
                "the gyroscopes apart");
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Check on what is readable in a damaged log");
  cmd->add_option("--json", o->json_path, "Write the fixed set and the figures as JSON");
  cmd->add_flag("--force", o->force, "Replace the JSON file if it exists (never an input)");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(31, setup);

}  // namespace
}  // namespace imucal::cli
