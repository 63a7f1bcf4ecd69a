#include "app/result_writers.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/text_file.hpp"
#include "log/dataset_io.hpp"

namespace imucal::app {
namespace {

using nlohmann::json;

json mat_json(const Eigen::Matrix3d& m) {
  json j = json::array();
  for (int r = 0; r < 3; ++r) j.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return j;
}
json vec_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

json figures_json(const calib::ErrorFigures& f) {
  return {{"count", f.count},
          {"mean_mps2", f.mean_mps2},
          {"max_mps2", f.max_mps2},
          {"mean_rad", f.mean_rad},
          {"max_rad", f.max_rad}};
}

/// One triad in the JSON convention corrected = misalignment * diag(scale) * (raw - bias).
json triad_json(const TedaldiTriad& t, const calib::TriadSigma& s) {
  return {
      {"misalignment", mat_json(t.T)},
      {"scale", vec_json(t.scale)},
      {"bias", vec_json(-t.bias)},
      {"sigma", {{"misalignment", mat_json(s.T)}, {"scale", vec_json(s.scale)}, {"bias", vec_json(s.bias)}}}};
}

json intervals_json(const calib::StaticCalibrationResult& r) {
  json intervals = json::array();
  for (const auto& iv : r.intervals) {
    intervals.push_back({{"t0_s", ns_to_s(iv.t0_ns - r.intervals.front().t0_ns)},
                         {"t1_s", ns_to_s(iv.t1_ns - r.intervals.front().t0_ns)},
                         {"t0_ns", iv.t0_ns},
                         {"t1_ns", iv.t1_ns},
                         {"samples", iv.samples}});
  }
  return intervals;
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
void emit_figures(YAML::Emitter& y, const std::string& key, const calib::ErrorFigures& f) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "mean_mps2"
    << YAML::Value << f.mean_mps2 << YAML::Key << "max_mps2" << YAML::Value << f.max_mps2 << YAML::Key
    << "mean_rad" << YAML::Value << f.mean_rad << YAML::Key << "max_rad" << YAML::Value << f.max_rad
    << YAML::EndMap;
}

double worst(const std::vector<calib::AllanNoise>& f, double calib::AllanNoise::*m) {
  return std::max({f[0].*m, f[1].*m, f[2].*m});
}

json sensor_json(const calib::AllanCurve& curve, const std::vector<calib::AllanNoise>& fits,
                 const std::string& unit) {
  json j;
  j["unit"] = unit;
  json axes = json::array();
  for (int a = 0; a < 3; ++a) {
    const auto& f = fits[a];
    axes.push_back(
        {{"axis", std::string(1, "xyz"[a])},
         {"noise_density", f.noise_density},
         {"random_walk", f.random_walk},
         {"random_walk_is_upper_bound", f.random_walk_is_bound},
         {"bias_instability", f.bias_instability},
         {"bias_instability_tau_s", f.bias_instability_tau_s},
         {"bias_instability_is_upper_bound", f.bias_instability_is_bound},
         {"lines",
          {{"white_noise", {{"adev", "N / sqrt(tau)"}, {"tau_s", {f.white_tau_min_s, f.white_tau_max_s}}}},
           {"random_walk", {{"adev", "K * sqrt(tau / 3)"}, {"tau_s", {f.rw_tau_min_s, f.rw_tau_max_s}}}},
           {"bias_instability", {{"adev", "0.664 * B"}, {"tau_s", f.bias_instability_tau_s}}}}}});
  }
  j["axes"] = axes;
  json c;
  c["tau_s"] = curve.tau_s;
  for (int a = 0; a < 3; ++a) {
    std::vector<double> v;
    for (const auto& d : curve.adev) v.push_back(d[a]);
    c[std::string("adev_") + "xyz"[a]] = v;
  }
  c["clusters"] = curve.clusters;
  j["curve"] = c;
  return j;
}

}  // namespace

Result<Eigen::Matrix3d> read_gsens_matrix(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error();
  YAML::Node root;
  try {
    root = YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, path + ": not valid YAML (" + std::string(e.what()) + ")");
  }
  YAML::Node g = root.IsMap() && root["canonical"] && root["canonical"]["G"] ? root["canonical"]["G"]
                 : root.IsMap() && root["G"]                                 ? root["G"]
                                                                             : YAML::Node();
  if (!g) return make_error(Errc::kCorrupt, path + ": has neither canonical.G nor G");
  Eigen::Matrix3d G;
  try {
    if (!g.IsSequence() || g.size() != 3) throw YAML::Exception(YAML::Mark::null_mark(), "not 3 rows");
    for (int r = 0; r < 3; ++r) {
      if (!g[r].IsSequence() || g[r].size() != 3)
        throw YAML::Exception(YAML::Mark::null_mark(), "not 3 columns");
      for (int c = 0; c < 3; ++c) G(r, c) = g[r][c].as<double>();
    }
  } catch (const YAML::Exception&) {
    return make_error(Errc::kCorrupt, path + ": G must be 3 rows of 3 numbers (rad/s per m/s^2)");
  }
  if (!G.allFinite() || G.cwiseAbs().maxCoeff() > 0.1) {
    return make_error(
        Errc::kInvalidArgument,
        path + ": G must be finite and in rad/s per m/s^2 (MEMS gyros: below 1e-3; 0.1 at most)");
  }
  return G;
}

std::string static_result_yaml(const calib::StaticCalibrationResult& r, const ImuStreamInfo& info) {
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
  y << YAML::Key << "gsens" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "mode" << YAML::Value << gsens_mode_name(r.gsens_mode);
  emit_matrix(y, "G_sigma", r.gsens_sigma);
  y << YAML::Key << "earth_rate_removed" << YAML::Value << r.earth_rate_removed;
  y << YAML::EndMap;
  y << YAML::Key << "convention" << YAML::Value << "corrected = misalignment * diag(scale) * (raw - bias)";
  emit_triad(y, "accel", r.model.accel, r.accel_sigma);
  emit_triad(y, "gyro", r.model.gyro, r.gyro_sigma);
  // What the recording determined: the accelerometer form used and why, and the parameters held
  // at nominal instead of fitted (their sigmas are .nan).
  y << YAML::Key << "accel_model" << YAML::Value << static_accel_model_name(r.accel_model);
  y << YAML::Key << "accel_model_reason" << YAML::Value << r.accel_model_reason;
  y << YAML::Key << "accel_fixed" << YAML::Value << YAML::Flow << r.accel_fixed;
  y << YAML::Key << "gyro_fixed" << YAML::Value << YAML::Flow << r.gyro_fixed;
  y << YAML::Key << "gravity" << YAML::Value << r.gravity_mps2;
  y << YAML::Key << "init_still_s" << YAML::Value << r.init_still_s;
  y << YAML::Key << "threshold_multiplier" << YAML::Value << r.threshold_multiplier;
  y << YAML::Key << "static_intervals" << YAML::Value << static_cast<int>(r.intervals.size());
  y << YAML::Key << "distinct_attitudes" << YAML::Value << r.distinct_attitudes;
  y << YAML::Key << "quality" << YAML::Value << YAML::BeginMap;
  if (r.quality.before_available) emit_figures(y, "accel_gravity_magnitude_before", r.quality.accel_before);
  emit_figures(y, "accel_gravity_magnitude_after", r.quality.accel_after);
  if (r.quality.before_available) emit_figures(y, "gyro_gravity_direction_before", r.quality.gyro_before);
  emit_figures(y, "gyro_gravity_direction_after", r.quality.gyro_after);
  y << YAML::EndMap;
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

std::string static_result_json(const calib::StaticCalibrationResult& r, const ImuStreamInfo& info,
                               const std::string& gravity_source,
                               const std::map<std::string, std::string>& log_metadata) {
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
  j["accel_model"] = {{"form", static_accel_model_name(r.accel_model)}, {"reason", r.accel_model_reason}};
  if (r.accel_model == StaticAccelModel::kFaces) {
    j["accel_model"]["faces_direction_rms_rad"] = r.faces_direction_rms_rad;
    j["accel_model"]["faces_rotation_rad"] = r.faces_rotation_rad;
    j["accel_model"]["poses_off_faces"] = r.poses_off_faces;
  }
  j["accel_fixed"] = r.accel_fixed;
  j["gyro_fixed"] = r.gyro_fixed;
  // The gyro covariance has 12 parameters only when the bias was estimated in the gyro solve.
  j["gyro"]["bias_source"] = r.gyro_covariance.rows() == 12 ? "estimated in the gyro solve"
                             : r.gyro_bias_from_poses && r.gsens_mode == GSensitivityMode::kOff
                                 ? "still poses, with its drift (G neglected: not distinguishable from zero)"
                             : r.gsens_mode == GSensitivityMode::kOff ? "initial still period mean"
                                                                      : "still poses, with the g-sensitivity";
  j["gsens"] = {{"mode", gsens_mode_name(r.gsens_mode)},
                {"G", mat_json(r.canonical.G)},
                {"G_sigma", mat_json(r.gsens_sigma)},
                {"earth_rate_removed", r.earth_rate_removed},
                {"wald_statistic", std::isfinite(r.gsens_wald) ? json(r.gsens_wald) : json(nullptr)},
                {"pose_residual_rms_radps", r.gsens_residual_rms}};
  auto dof_json = [](const FitDof& d) {
    return json{{"residuals", d.residuals}, {"parameters", d.parameters}, {"dof", d.dof()}};
  };
  j["degrees_of_freedom"] = {
      {"accel", dof_json(r.accel_dof)}, {"gyro", dof_json(r.gyro_dof)}, {"gsens", dof_json(r.gsens_dof)}};
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
  json candidates = json::array();
  for (const auto& c : r.threshold_candidates) {
    candidates.push_back({{"multiplier", c.multiplier},
                          {"intervals", c.intervals},
                          {"distinct_attitudes", c.distinct_attitudes},
                          {"dropped_for_rotation", c.dropped_for_rotation},
                          {"accel_rms_m2ps4", c.accel_rms},
                          {"gyro_pose_rms", c.gyro_rms},
                          {"score", c.score}});
  }
  j["threshold_search"] = candidates;
  j["distinct_attitudes"] = r.distinct_attitudes;
  j["gyro_transfers"] = r.gyro_transfers;
  j["static_intervals"] = intervals_json(r);
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
  auto it = log_metadata.find("software_version");
  if (it != log_metadata.end()) j["log_software_version"] = it->second;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

double AllanReport::accel_noise_density() const {
  return worst(accel_fits, &calib::AllanNoise::noise_density);
}
double AllanReport::accel_random_walk() const { return worst(accel_fits, &calib::AllanNoise::random_walk); }
double AllanReport::gyro_noise_density() const { return worst(gyro_fits, &calib::AllanNoise::noise_density); }
double AllanReport::gyro_random_walk() const { return worst(gyro_fits, &calib::AllanNoise::random_walk); }

bool AllanReport::random_walk_is_upper_bound() const {
  for (int a = 0; a < 3; ++a) {
    if (accel_fits[a].random_walk_is_bound || gyro_fits[a].random_walk_is_bound) return true;
  }
  return false;
}

Result<AllanReport> analyse_allan(const std::vector<Eigen::Vector3d>& accel,
                                  const std::vector<Eigen::Vector3d>& gyro, double rate_hz) {
  AllanReport report;
  report.rate_hz = rate_hz;
  report.duration_s = static_cast<double>(accel.size()) / rate_hz;
  auto ca = calib::allan_deviation(accel, rate_hz);
  if (!ca.ok()) return ca.error().context("accelerometer Allan deviation");
  auto cg = calib::allan_deviation(gyro, rate_hz);
  if (!cg.ok()) return cg.error().context("gyroscope Allan deviation");
  report.accel_curve = std::move(*ca);
  report.gyro_curve = std::move(*cg);
  for (int a = 0; a < 3; ++a) {
    report.accel_fits.push_back(calib::fit_allan_noise(report.accel_curve, a));
    report.gyro_fits.push_back(calib::fit_allan_noise(report.gyro_curve, a));
  }
  return report;
}

std::string allan_kalibr_yaml(const AllanReport& r) {
  YAML::Emitter y;
  y.SetDoublePrecision(8);
  y << YAML::Comment("Kalibr IMU noise model: worst axis, from imucal allan " + r.log_path);
  y << YAML::BeginMap;
  y << YAML::Key << "accelerometer_noise_density" << YAML::Value << r.accel_noise_density();
  y << YAML::Key << "accelerometer_random_walk" << YAML::Value << r.accel_random_walk();
  y << YAML::Key << "gyroscope_noise_density" << YAML::Value << r.gyro_noise_density();
  y << YAML::Key << "gyroscope_random_walk" << YAML::Value << r.gyro_random_walk();
  y << YAML::Key << "rostopic" << YAML::Value << r.rostopic;
  y << YAML::Key << "update_rate" << YAML::Value << r.rate_hz;
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

std::string allan_json(const AllanReport& r) {
  json j;
  j["log"] = r.log_path;
  j["stream"] = r.stream;
  j["rate_hz"] = r.rate_hz;
  j["duration_s"] = r.duration_s;
  j["accelerometer"] = sensor_json(r.accel_curve, r.accel_fits, "m/s^2");
  j["gyroscope"] = sensor_json(r.gyro_curve, r.gyro_fits, "rad/s");
  j["kalibr"] = {{"accelerometer_noise_density", r.accel_noise_density()},
                 {"accelerometer_random_walk", r.accel_random_walk()},
                 {"gyroscope_noise_density", r.gyro_noise_density()},
                 {"gyroscope_random_walk", r.gyro_random_walk()},
                 {"rostopic", r.rostopic},
                 {"update_rate", r.rate_hz}};
  j["random_walk_is_upper_bound"] = r.random_walk_is_upper_bound();
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

namespace {

constexpr const char* kGsensMethod = "six-orientation g-sensitivity (Krebs 2012, 5.2.3)";
constexpr const char* kGsensForm = "w = A_g (w_raw - b_g) - G a; G in rad/s per m/s^2, b_g in input units";

json gsens_hold_json(const GSensitivityHold& h, TimeNs t_first) {
  return {{"face", h.face},
          {"face_angle_deg", h.face_angle_deg},
          {"t0_s", ns_to_s(h.t0_ns - t_first)},
          {"t1_s", ns_to_s(h.t1_ns - t_first)},
          {"samples", h.samples},
          {"accel_mps2", vec_json(h.accel_mps2)},
          {"gyro_mean_raw", vec_json(h.gyro_mean_raw)},
          {"residual_radps", vec_json(h.residual_radps)},
          {"tilt_deg", h.tilt_deg},
          {"rotation_deg", h.rotation_deg}};
}

}  // namespace

std::string gsens_result_yaml(const GSensitivityResult& r, const ImuStreamInfo& info,
                              const GSensProvenance& p) {
  YAML::Emitter y;
  y.SetDoublePrecision(12);
  y << YAML::BeginMap;
  y << YAML::Key << "method" << YAML::Value << kGsensMethod;
  y << YAML::Key << "stream" << YAML::Value << info.name;
  y << YAML::Key << "input_units" << YAML::Value << imu_units_name(info.units);
  y << YAML::Key << "form" << YAML::Value << kGsensForm;
  emit_matrix(y, "G", r.G);
  emit_matrix(y, "G_sigma", r.G_sigma);
  emit_vector(y, "b_g", r.b_g);
  emit_vector(y, "b_g_sigma", r.b_g_sigma);
  y << YAML::Key << "b_g_t_ns" << YAML::Value << r.b_g_t_ns;
  y << YAML::Key << "earth_rate_removed" << YAML::Value << r.earth_rate_removed;
  y << YAML::Key << "gravity" << YAML::Value << r.gravity_mps2;
  y << YAML::Key << "models" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "source" << YAML::Value << p.models;
  emit_matrix(y, "A_a", r.A_a);
  emit_vector(y, "b_a", r.b_a);
  emit_matrix(y, "A_g", r.A_g);
  y << YAML::Key << "accel_rel_sigma" << YAML::Value << r.accel_model_rel_sigma;
  y << YAML::Key << "gyro_rel_sigma" << YAML::Value << r.gyro_model_rel_sigma;
  y << YAML::Key << "accel_offset_sigma_mps2" << YAML::Value << r.accel_offset_sigma_mps2;
  y << YAML::EndMap;
  y << YAML::Key << "noise" << YAML::Value << YAML::BeginMap;
  emit_vector(y, "gyro_noise_density", r.gyro_noise_density);
  emit_vector(y, "gyro_random_walk", r.gyro_random_walk);
  y << YAML::EndMap;
  y << YAML::Key << "residual_rms_radps" << YAML::Value << r.residual_rms_radps;
  y << YAML::Key << "chi2_per_dof" << YAML::Value << r.chi2_per_dof;
  y << YAML::Key << "degrees_of_freedom" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key
    << "residuals" << YAML::Value << r.dof.residuals << YAML::Key << "parameters" << YAML::Value
    << r.dof.parameters << YAML::EndMap;
  y << YAML::Key << "holds" << YAML::Value << YAML::BeginSeq;
  for (const auto& h : r.holds) {
    y << YAML::Flow << YAML::BeginMap << YAML::Key << "face" << YAML::Value << h.face << YAML::Key << "t0_ns"
      << YAML::Value << h.t0_ns << YAML::Key << "t1_ns" << YAML::Value << h.t1_ns << YAML::Key << "samples"
      << YAML::Value << h.samples << YAML::Key << "tilt_deg" << YAML::Value << h.tilt_deg << YAML::Key
      << "rotation_deg" << YAML::Value << h.rotation_deg << YAML::EndMap;
  }
  y << YAML::EndSeq;
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

std::string gsens_result_json(const GSensitivityResult& r, const ImuStreamInfo& info,
                              const GSensProvenance& p) {
  json j;
  j["method"] = kGsensMethod;
  j["stream"] = info.name;
  j["input_units"] = imu_units_name(info.units);
  j["form"] = kGsensForm;
  j["G"] = mat_json(r.G);
  j["G_sigma"] = mat_json(r.G_sigma);
  j["b_g"] = vec_json(r.b_g);
  j["b_g_sigma"] = vec_json(r.b_g_sigma);
  j["b_g_t_ns"] = r.b_g_t_ns;
  json cov = json::array();
  for (int row = 0; row < 12; ++row) {
    json line = json::array();
    for (int col = 0; col < 12; ++col) line.push_back(r.covariance(row, col));
    cov.push_back(line);
  }
  j["covariance"] = {{"order", "G row by row (9), b_g (3)"}, {"matrix", cov}};
  j["earth_rate_removed"] = r.earth_rate_removed;
  j["gravity"] = r.gravity_mps2;
  j["gravity_source"] = p.gravity_source;
  j["models"] = {{"source", p.models},
                 {"A_a", mat_json(r.A_a)},
                 {"b_a", vec_json(r.b_a)},
                 {"A_g", mat_json(r.A_g)},
                 {"accel_rel_sigma", r.accel_model_rel_sigma},
                 {"gyro_rel_sigma", r.gyro_model_rel_sigma},
                 {"accel_offset_sigma_mps2", r.accel_offset_sigma_mps2}};
  j["noise"] = {{"gyro_noise_density", vec_json(r.gyro_noise_density)},
                {"gyro_random_walk", vec_json(r.gyro_random_walk)}};
  j["residual_rms_radps"] = r.residual_rms_radps;
  j["chi2_per_dof"] = r.chi2_per_dof;
  j["degrees_of_freedom"] = {
      {"residuals", r.dof.residuals}, {"parameters", r.dof.parameters}, {"dof", r.dof.dof()}};
  json holds = json::array();
  for (const auto& h : r.holds) holds.push_back(gsens_hold_json(h, r.holds.front().t0_ns));
  j["holds"] = holds;
  j["warnings"] = r.warnings;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

Status check_output(const std::string& path, const OutputPolicy& policy) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (const auto& input : policy.inputs) {
    if (fs::exists(path, ec) && fs::equivalent(path, input, ec)) {
      return make_error(Errc::kInvalidArgument,
                        path + " is an input of this command; write the result to another file");
    }
  }
  if (fs::is_directory(path, ec))
    return make_error(Errc::kInvalidArgument, path + " is a folder, not a file");
  IMUCAL_TRY(log::check_replaceable(path));
  if (!policy.overwrite && fs::exists(path, ec)) return make_error(Errc::kAlreadyExists, path + " exists");
  return {};
}

Status write_text_file(const std::string& path, const std::string& text, const OutputPolicy& policy) {
  IMUCAL_TRY(check_output(path, policy));
  const std::string temp = path + ".tmp-" + std::to_string(::getpid());
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    return make_error(Errc::kIo, "could not write " + path + ": " + std::strerror(errno) +
                                     " (check the folder exists and is writable)");
  }
  std::size_t done = 0;
  int err = 0;
  while (done < text.size()) {
    const ssize_t w = ::write(fd, text.data() + done, text.size() - done);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0) {
      err = errno;
      break;
    }
    done += static_cast<std::size_t>(w);
  }
  if (err == 0 && ::fsync(fd) != 0) err = errno;
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0) {
    if (Status moved = log::rename_into_place(temp, path, policy.overwrite); !moved.ok()) {
      ::unlink(temp.c_str());
      return moved.error();
    }
  }
  if (err != 0) {
    ::unlink(temp.c_str());
    return make_error(Errc::kIo, "could not write " + path + ": " + std::strerror(err) +
                                     (err == ENOSPC ? " (the disk is full)" : "") + "; nothing was replaced");
  }
  return {};
}

}  // namespace imucal::app
