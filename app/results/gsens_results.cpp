// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/gsens_results.hpp"

#include <yaml-cpp/yaml.h>

#include <nlohmann/json.hpp>

#include "app/results/result_text.hpp"

namespace imucal::app {

using nlohmann::json;
using namespace result_text;

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

}  // namespace imucal::app
