// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/static_results.hpp"

#include <yaml-cpp/yaml.h>

#include <nlohmann/json.hpp>

#include "app/results/result_text.hpp"
#include "core/calibration_record.hpp"
#include "core/imu_model.hpp"
#include "core/text_file.hpp"
#include "core/yaml_json.hpp"

namespace imucal::app {

using nlohmann::json;
using namespace result_text;

Result<Eigen::Matrix3d> read_gsens_matrix(const std::string& path) {
  auto loaded = read_yaml_file(path);
  if (!loaded.ok()) return loaded.error();
  const YAML::Node root = *loaded;
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

namespace {

calib::TriadSigma read_triad_sigma(const json& j) {
  calib::TriadSigma s;
  s.T = read_mat<3, 3>(j.at("misalignment"));
  s.scale = read_vec<3>(j.at("scale"));
  s.bias = read_vec<3>(j.at("bias"));
  return s;
}

}  // namespace

Result<StaticResultFile> parse_static_result(const json& r, const std::string& origin) {
  try {
    StaticResultFile f;
    f.info.name = r.at("stream").get<std::string>();
    f.info.units = read_units(r.at("input_units"));
    calib::StaticCalibrationResult& res = f.result;
    res.canonical = read_canonical(r.at("canonical"));
    res.accel_sigma = read_triad_sigma(r.at("accel").at("sigma"));
    res.gyro_sigma = read_triad_sigma(r.at("gyro").at("sigma"));
    // G's sigma is a figure only where G was estimated; "off" reads as YAML's false.
    const json& gsens = r.value("gsens", json::object());
    const json mode = gsens.value("mode", json());
    res.gsens_mode = mode == json(gsens_mode_name(GSensitivityMode::kEstimate)) ? GSensitivityMode::kEstimate
                     : mode == json(gsens_mode_name(GSensitivityMode::kFixed))  ? GSensitivityMode::kFixed
                                                                                : GSensitivityMode::kOff;
    if (res.gsens_mode == GSensitivityMode::kEstimate) res.gsens_sigma = read_mat<3, 3>(gsens.at("G_sigma"));
    res.gravity_mps2 = r.at("gravity").get<double>();
    if (!(res.gravity_mps2 > 0.0)) throw std::runtime_error("gravity must be a positive number (m/s^2)");
    res.thermal = read_thermal(r);
    return f;
  } catch (const std::exception& e) {
    return make_error(Errc::kCorrupt, origin + ": a key the calibration needs is missing or malformed (" +
                                          std::string(e.what()) + ")");
  }
}

std::string static_result_yaml(const calib::StaticCalibrationResult& r, const ImuStreamInfo& info) {
  YAML::Emitter y;
  y.SetDoublePrecision(12);
  y << YAML::BeginMap;
  y << YAML::Key << "method" << YAML::Value << kStaticMethod;
  y << YAML::Key << "stream" << YAML::Value << info.name;
  y << YAML::Key << "input_units" << YAML::Value << imu_units_name(info.units);
  y << YAML::Key << "canonical" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "form" << YAML::Value << kCanonicalForm;
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
  y << YAML::Key << "convention" << YAML::Value << kTedaldiConvention;
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
  emit_thermal(y, r.thermal);
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

std::string static_result_json(const calib::StaticCalibrationResult& r, const ImuStreamInfo& info,
                               const std::string& gravity_source,
                               const std::map<std::string, std::string>& log_metadata) {
  json j;
  j["method"] = kStaticMethod;
  j["convention"] = kTedaldiConvention;
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
  if (r.thermal) {
    j["reference_temperature_c"] = r.thermal->reference_c;
    j["thermal"] = thermal_model_json(*r.thermal);
  }
  j["warnings"] = r.warnings;
  j["timings_s"] = {{"detector", r.timings.detector_s},
                    {"threshold_search", r.timings.threshold_search_s},
                    {"accel", r.timings.accel_s},
                    {"gyro", r.timings.gyro_s}};
  auto it = log_metadata.find("software_version");
  if (it != log_metadata.end()) j["log_software_version"] = it->second;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace imucal::app
