// imucal calibrate static LOG: static multi-position IMU calibration (Tedaldi et al.), see
// docs/static-calibration.md.

#include <spdlog/spdlog.h>
#include <time.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>

#include "calib/gravity.hpp"
#include "calib/static_calibration.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

struct StaticCliOptions {
  std::string log_path;
  std::string stream;
  std::optional<double> gravity;
  std::optional<double> latitude_deg;
  double height_m = 0.0;
  double init_still_s = 0.0;
  std::string accel_scale_init, accel_offset_init, gyro_scale_init;
  bool estimate_gyro_bias = false;
  double window_s = 1.0;
  double min_interval_s = 0.5;
  bool allow_damaged = false;
  std::string yaml_path;
  std::string json_path;
};

/// "v" -> (v, v, v); "a,b,c" -> (a, b, c).
Eigen::Vector3d parse_triple(const std::string& text, const std::string& option) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size() || !std::isfinite(v.back())) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      throw CliExit{kExitUsage, option + ": '" + item + "' is not a number"};
    }
  }
  if (v.size() == 1) return Eigen::Vector3d::Constant(v[0]);
  if (v.size() == 3) return {v[0], v[1], v[2]};
  throw CliExit{kExitUsage, option + " takes one value for all three axes or three comma-separated values"};
}

nlohmann::json mat_json(const Eigen::Matrix3d& m) {
  nlohmann::json j = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) j.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return j;
}
nlohmann::json vec_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

nlohmann::json figures_json(const calib::ErrorFigures& f) {
  return {{"count", f.count},
          {"mean_mps2", f.mean_mps2},
          {"max_mps2", f.max_mps2},
          {"mean_rad", f.mean_rad},
          {"max_rad", f.max_rad}};
}

/// One triad in the JSON convention corrected = misalignment * diag(scale) * (raw - bias).
nlohmann::json triad_json(const TedaldiTriad& t, const calib::TriadSigma& s) {
  return {
      {"misalignment", mat_json(t.T)},
      {"scale", vec_json(t.scale)},
      {"bias", vec_json(-t.bias)},
      {"sigma", {{"misalignment", mat_json(s.T)}, {"scale", vec_json(s.scale)}, {"bias", vec_json(s.bias)}}}};
}

nlohmann::json result_json(const calib::StaticCalibrationResult& r, const log::SessionLogReader& log,
                           const ImuStreamInfo& info, const std::string& gravity_source) {
  using nlohmann::json;
  json j;
  j["method"] = "static multi-position (Tedaldi 2013)";
  j["convention"] = "corrected = misalignment * diag(scale) * (raw - bias)";
  j["input_units"] = imu_units_name(info.units);
  j["stream"] = info.name;
  j["accel"] = triad_json(r.model.accel, r.accel_sigma);
  j["accel"]["tedaldi_angles"] = {{"alpha_yz", -r.model.accel.T(0, 1)},
                                  {"alpha_zy", r.model.accel.T(0, 2)},
                                  {"alpha_zx", -r.model.accel.T(1, 2)}};
  j["accel"]["residual_rms_m2ps4"] = r.accel_residual_rms;
  j["gyro"] = triad_json(r.model.gyro, r.gyro_sigma);
  const auto g = gyro_angles(r.model.gyro.T);
  j["gyro"]["tedaldi_angles"] = {{"gamma_yz", g[0]}, {"gamma_zy", g[1]}, {"gamma_xz", g[2]},
                                 {"gamma_zx", g[3]}, {"gamma_xy", g[4]}, {"gamma_yx", g[5]}};
  j["gyro"]["residual_rms"] = r.gyro_residual_rms;
  j["gyro"]["bias_source"] = r.gyro_covariance.rows() == 12 ? "estimated" : "initial still period mean";
  j["canonical"] = {{"A_a", mat_json(r.canonical.A_a)},
                    {"b_a", vec_json(r.canonical.b_a)},
                    {"A_g", mat_json(r.canonical.A_g)},
                    {"b_g", vec_json(r.canonical.b_g)},
                    {"G", mat_json(r.canonical.G)}};
  j["gravity"] = r.gravity_mps2;
  j["gravity_source"] = gravity_source;
  j["init_still_s"] = r.init_still_s;
  j["init_still_source"] = r.init_still_from_allan ? "gyro Allan deviation" : "given";
  j["threshold_multiplier"] = r.threshold_multiplier;
  j["threshold"] = r.threshold;
  j["distinct_attitudes"] = r.distinct_attitudes;
  j["gyro_transfers"] = r.gyro_transfers;
  json intervals = json::array();
  for (const auto& iv : r.intervals) {
    intervals.push_back({{"t0_s", ns_to_s(iv.t0_ns - r.intervals.front().t0_ns)},
                         {"t1_s", ns_to_s(iv.t1_ns - r.intervals.front().t0_ns)},
                         {"t0_ns", iv.t0_ns},
                         {"t1_ns", iv.t1_ns},
                         {"samples", iv.samples}});
  }
  j["static_intervals"] = intervals;
  j["quality"]["accel_gravity_magnitude"] = {
      {"before", r.quality.before_available ? figures_json(r.quality.accel_before) : json(nullptr)},
      {"after", figures_json(r.quality.accel_after)}};
  j["quality"]["gyro_gravity_direction"] = {
      {"before", r.quality.before_available ? figures_json(r.quality.gyro_before) : json(nullptr)},
      {"after", figures_json(r.quality.gyro_after)}};
  j["warnings"] = r.warnings;
  j["timings_s"] = {{"detector", r.timings.detector_s},
                    {"threshold_search", r.timings.threshold_search_s},
                    {"accel", r.timings.accel_s},
                    {"gyro", r.timings.gyro_s}};
  auto it = log.metadata().find("software_version");
  if (it != log.metadata().end()) j["log_software_version"] = it->second;
  return j;
}

void emit_matrix(YAML::Emitter& y, const std::string& key, const Eigen::Matrix3d& m) {
  y << YAML::Key << key << YAML::Value << YAML::BeginSeq;
  for (int r = 0; r < 3; ++r)
    y << YAML::Flow << YAML::BeginSeq << m(r, 0) << m(r, 1) << m(r, 2) << YAML::EndSeq;
  y << YAML::EndSeq;
}
void emit_vector(YAML::Emitter& y, const std::string& key, const Eigen::Vector3d& v) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq << v[0] << v[1] << v[2]
    << YAML::EndSeq;
}
void emit_triad(YAML::Emitter& y, const std::string& key, const TedaldiTriad& t, const calib::TriadSigma& s) {
  y << YAML::Key << key << YAML::Value << YAML::BeginMap;
  emit_matrix(y, "misalignment", t.T);
  emit_vector(y, "scale", t.scale);
  emit_vector(y, "bias", -t.bias);
  y << YAML::Key << "sigma" << YAML::Value << YAML::BeginMap;
  emit_matrix(y, "misalignment", s.T);
  emit_vector(y, "scale", s.scale);
  emit_vector(y, "bias", s.bias);
  y << YAML::EndMap << YAML::EndMap;
}

std::string result_yaml(const calib::StaticCalibrationResult& r, const ImuStreamInfo& info) {
  YAML::Emitter y;
  y.SetDoublePrecision(12);
  y << YAML::BeginMap;
  y << YAML::Key << "method" << YAML::Value << "static multi-position (Tedaldi 2013)";
  y << YAML::Key << "stream" << YAML::Value << info.name;
  y << YAML::Key << "input_units" << YAML::Value << imu_units_name(info.units);
  y << YAML::Key << "canonical" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "form" << YAML::Value << "a = A_a (a_raw - b_a); w = A_g (w_raw - b_g) - G a";
  emit_matrix(y, "A_a", r.canonical.A_a);
  emit_vector(y, "b_a", r.canonical.b_a);
  emit_matrix(y, "A_g", r.canonical.A_g);
  emit_vector(y, "b_g", r.canonical.b_g);
  emit_matrix(y, "G", r.canonical.G);
  y << YAML::EndMap;
  y << YAML::Key << "convention" << YAML::Value << "corrected = misalignment * diag(scale) * (raw - bias)";
  emit_triad(y, "accel", r.model.accel, r.accel_sigma);
  emit_triad(y, "gyro", r.model.gyro, r.gyro_sigma);
  y << YAML::Key << "gravity" << YAML::Value << r.gravity_mps2;
  y << YAML::Key << "init_still_s" << YAML::Value << r.init_still_s;
  y << YAML::Key << "threshold_multiplier" << YAML::Value << r.threshold_multiplier;
  y << YAML::Key << "static_intervals" << YAML::Value << static_cast<int>(r.intervals.size());
  y << YAML::Key << "distinct_attitudes" << YAML::Value << r.distinct_attitudes;
  y << YAML::Key << "quality" << YAML::Value << YAML::BeginMap;
  auto fig = [&](const std::string& key, const calib::ErrorFigures& f) {
    y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "mean_mps2"
      << YAML::Value << f.mean_mps2 << YAML::Key << "max_mps2" << YAML::Value << f.max_mps2 << YAML::Key
      << "mean_rad" << YAML::Value << f.mean_rad << YAML::Key << "max_rad" << YAML::Value << f.max_rad
      << YAML::EndMap;
  };
  if (r.quality.before_available) fig("accel_gravity_magnitude_before", r.quality.accel_before);
  fig("accel_gravity_magnitude_after", r.quality.accel_after);
  if (r.quality.before_available) fig("gyro_gravity_direction_before", r.quality.gyro_before);
  fig("gyro_gravity_direction_after", r.quality.gyro_after);
  y << YAML::EndMap;
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw CliExit{kExitIo, "could not write " + path + ": check the folder exists and is writable"};
}

void run(const StaticCliOptions& o) {
  // CPU time of this thread, like the timings of calibrate_static.
  auto cpu_now = [] {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  };
  const double t0 = cpu_now();
  auto log = log::SessionLogReader::open(o.log_path);
  if (!log.ok()) fail(log.error(), "cannot read " + o.log_path);
  const auto& reader = **log;
  if (reader.health().damaged && !o.allow_damaged) {
    throw CliExit{kExitInput, o.log_path + " is damaged (" + reader.health().damage_message +
                                  "); pass --allow-damaged to calibrate from what is readable"};
  }
  auto stream_id = reader.find_imu_stream(o.stream);
  if (!stream_id.ok()) fail(stream_id.error(), "no IMU stream in " + o.log_path);
  const ImuStreamInfo info = reader.imu_streams().at(*stream_id);
  auto samples = reader.read_imu(*stream_id);
  if (!samples.ok()) fail(samples.error(), "cannot read the IMU samples of " + o.log_path);
  const double import_s = cpu_now() - t0;

  calib::StaticCalibrationOptions opt;
  std::string gravity_source = "standard gravity";
  opt.gravity_mps2 = kStandardGravity;
  if (o.gravity) {
    opt.gravity_mps2 = *o.gravity;
    gravity_source = "given";
  } else if (o.latitude_deg) {
    opt.gravity_mps2 = calib::wgs84_gravity(*o.latitude_deg, o.height_m);
    gravity_source = "WGS-84 normal gravity at latitude " + std::to_string(*o.latitude_deg) +
                     " deg, height " + std::to_string(o.height_m) + " m";
  } else {
    spdlog::warn("no --gravity or --latitude given: using standard gravity 9.80665 m/s^2 (up to 0.3% off)");
  }
  opt.init_still_s = o.init_still_s;
  opt.estimate_gyro_bias = o.estimate_gyro_bias;
  opt.window_s = o.window_s;
  opt.min_interval_s = o.min_interval_s;

  const bool raw = info.units == ImuUnits::kRaw;
  const bool accel_known = !raw || info.accel_full_scale_g != 0 || !info.accel.scale.isOnes();
  const bool gyro_known = !raw || info.gyro_full_scale_dps != 0 || !info.gyro.scale.isOnes();
  if (!o.accel_scale_init.empty() || !o.accel_offset_init.empty()) {
    AxisConversion c = info.accel;
    if (!o.accel_scale_init.empty()) c.scale = parse_triple(o.accel_scale_init, "--accel-scale-init");
    if (!o.accel_offset_init.empty()) c.offset = parse_triple(o.accel_offset_init, "--accel-offset-init");
    opt.accel_init = c;
  } else if (accel_known) {
    opt.accel_init = info.accel;
  }  // else: the ellipsoid fit provides the guess
  if (!o.gyro_scale_init.empty()) {
    AxisConversion c = info.gyro;
    c.scale = parse_triple(o.gyro_scale_init, "--gyro-scale-init");
    opt.gyro_init = c;
  } else if (gyro_known) {
    opt.gyro_init = info.gyro;
  } else {
    throw CliExit{kExitUsage,
                  "the gyro stream is in raw counts and the log does not give its full-scale range: "
                  "give --gyro-scale-init in rad/s per count (e.g. 1.3323e-4 for +-250 deg/s)"};
  }
  if (auto valid = opt.validate(); !valid.ok()) throw CliExit{kExitUsage, valid.error().message};

  auto res = calib::calibrate_static(*samples, opt);
  if (!res.ok()) fail(res.error(), "static calibration of " + o.log_path);
  if (reader.health().damaged) {
    res->warnings.insert(res->warnings.begin(), "the log is damaged (" + reader.health().damage_message +
                                                    "): calibrated from its readable part only");
  }
  for (const auto& w : res->warnings) spdlog::warn("{}", w);
  spdlog::info(
      "CPU time: import {:.4f} s, detector {:.4f} s, threshold search {:.4f} s, accel {:.4f} s, gyro {:.4f} "
      "s",
      import_s, res->timings.detector_s, res->timings.threshold_search_s, res->timings.accel_s,
      res->timings.gyro_s);

  if (!o.yaml_path.empty()) write_text(o.yaml_path, result_yaml(*res, info));
  if (!o.json_path.empty())
    write_text(o.json_path, result_json(*res, reader, info, gravity_source).dump(2) + "\n");

  const auto& q = res->quality;
  std::cout << "static calibration of " << o.log_path << " (" << info.name << ", " << samples->size()
            << " samples, " << imu_units_name(info.units) << ")\n"
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
  if (res->warnings.empty()) std::cout << "  no warnings\n";
}

void setup(CLI::App& root) {
  CLI::App* cmd = calibrate_group(root)->add_subcommand(
      "static",
      "Static multi-position IMU calibration (Tedaldi et al.): accel and gyro scale, misalignment, bias");
  auto o = std::make_shared<StaticCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) of the static protocol")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--stream", o->stream, "IMU stream name (default: the first)");
  auto* g =
      cmd->add_option("--gravity", o->gravity, "Local gravity magnitude, m/s^2")->check(CLI::Range(9.7, 9.9));
  auto* lat = cmd->add_option("--latitude", o->latitude_deg, "Geodetic latitude, deg (WGS-84 normal gravity)")
                  ->check(CLI::Range(-90.0, 90.0));
  cmd->add_option("--height", o->height_m, "Ellipsoidal height, m (with --latitude)")
      ->check(CLI::Range(-1000.0, 10000.0))
      ->needs(lat);
  g->excludes(lat);
  cmd->add_option("--init-still", o->init_still_s,
                  "Length of the initial still period, s (default: found, then chosen by Allan deviation)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--accel-scale-init", o->accel_scale_init,
                  "Nominal accel scale, m/s^2 per input unit: one value or 'x,y,z'");
  cmd->add_option("--accel-offset-init", o->accel_offset_init,
                  "Nominal accel offset, input units: one value or 'x,y,z'");
  cmd->add_option("--gyro-scale-init", o->gyro_scale_init,
                  "Nominal gyro scale, rad/s per input unit: one value or 'x,y,z'");
  cmd->add_flag("--estimate-gyro-bias", o->estimate_gyro_bias,
                "Estimate the gyro bias in the gyro solve (default: mean of the still period)");
  cmd->add_option("--window", o->window_s, "Static detector window t_w, s")->check(CLI::Range(0.05, 10.0));
  cmd->add_option("--min-interval", o->min_interval_s, "Shortest static interval used, s")
      ->check(CLI::Range(0.05, 60.0));
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path, "Write the result as YAML");
  cmd->add_option("--json", o->json_path, "Write the result as JSON");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(30, setup);

}  // namespace
}  // namespace imucal::cli
