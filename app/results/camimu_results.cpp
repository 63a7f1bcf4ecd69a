// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/camimu_results.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/camimu_inputs.hpp"
#include "app/results/result_text.hpp"
#include "core/calibration_record.hpp"
#include "core/text_file.hpp"
#include "core/text_format.hpp"
#include "core/version.hpp"
#include "core/yaml_json.hpp"

namespace imucal::app {
namespace {

using nlohmann::json;

// ---- YAML pieces -------------------------------------------------------------------------------

YAML::Node flow_vec(const Eigen::VectorXd& v) {
  YAML::Node n(YAML::NodeType::Sequence);
  for (Eigen::Index i = 0; i < v.size(); ++i) n.push_back(v[i]);
  n.SetStyle(YAML::EmitterStyle::Flow);
  return n;
}

/// A matrix as rows in flow style (Kalibr's layout for T_cam_imu, M, A, C_gyro_i).
YAML::Node rows(const Eigen::MatrixXd& m) { return yaml_matrix_rows(m); }

std::string emit(const YAML::Node& root, const std::string& header) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << root;
  return header + std::string(out.c_str()) + "\n";
}

YAML::Node string_list(const std::vector<std::string>& items) {
  YAML::Node n(YAML::NodeType::Sequence);
  for (const auto& s : items) n.push_back(s);
  return n;
}

YAML::Node canonical_node(const CanonicalImuModel& c) {
  YAML::Node n(YAML::NodeType::Map);
  n["form"] = kCanonicalForm;
  n["A_a"] = rows(c.A_a);
  n["b_a"] = flow_vec(c.b_a);
  n["A_g"] = rows(c.A_g);
  n["b_g"] = flow_vec(c.b_g);
  n["G"] = rows(c.G);
  return n;
}

YAML::Node krebs_node(const KrebsImuModel& k, const KrebsImuSigma& s) {
  YAML::Node n(YAML::NodeType::Map);
  n["form"] = kKrebsForm;
  n["S_a"] = flow_vec(k.S_a);
  n["M_a"] = flow_vec(k.M_a);
  n["b_a"] = flow_vec(k.b_a);
  n["S_g"] = flow_vec(k.S_g);
  n["M_g"] = flow_vec(k.M_g);
  n["C_bg"] = rows(k.C_bg);
  n["B_g"] = rows(k.B_g);
  n["b_g"] = flow_vec(k.b_g);
  YAML::Node sigma(YAML::NodeType::Map);
  sigma["S_a"] = flow_vec(s.S_a);
  sigma["M_a"] = flow_vec(s.M_a);
  sigma["b_a"] = flow_vec(s.b_a);
  sigma["S_g"] = flow_vec(s.S_g);
  sigma["M_g"] = flow_vec(s.M_g);
  sigma["C_bg_rad"] = flow_vec(s.C_bg);
  sigma["B_g"] = rows(s.B_g);
  sigma["b_g"] = flow_vec(s.b_g);
  n["sigma"] = sigma;
  return n;
}

Eigen::Matrix4d matrix_of(const Eigen::Isometry3d& T) { return T.matrix(); }

// ---- JSON pieces -------------------------------------------------------------------------------

/// A figure for JSON: not finite (undetermined) as null.
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json vec_json(const Eigen::VectorXd& v) {
  json j = json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) j.push_back(num(v[i]));
  return j;
}

json mat_json(const Eigen::MatrixXd& m) {
  json j = json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) j.push_back(vec_json(m.row(r).transpose()));
  return j;
}

json canonical_json(const CanonicalImuModel& c) {
  return {{"A_a", mat_json(c.A_a)},
          {"b_a", vec_json(c.b_a)},
          {"A_g", mat_json(c.A_g)},
          {"b_g", vec_json(c.b_g)},
          {"G", mat_json(c.G)}};
}

json krebs_json(const KrebsImuModel& k) {
  return {{"S_a", vec_json(k.S_a)}, {"M_a", vec_json(k.M_a)}, {"b_a", vec_json(k.b_a)},
          {"S_g", vec_json(k.S_g)}, {"M_g", vec_json(k.M_g)}, {"C_bg", mat_json(k.C_bg)},
          {"B_g", mat_json(k.B_g)}, {"b_g", vec_json(k.b_g)}};
}

json krebs_sigma_json(const KrebsImuSigma& s) {
  return {{"S_a", vec_json(s.S_a)}, {"M_a", vec_json(s.M_a)}, {"b_a", vec_json(s.b_a)},
          {"S_g", vec_json(s.S_g)}, {"M_g", vec_json(s.M_g)}, {"C_bg_rad", vec_json(s.C_bg)},
          {"B_g", mat_json(s.B_g)}, {"b_g", vec_json(s.b_g)}};
}

/// A sigma for YAML: null where it is not determined (held, or NaN).
YAML::Node yaml_sigma(double v) {
  return std::isfinite(v) ? YAML::Node(v) : YAML::Node(YAML::NodeType::Null);
}

/// The intrinsics a camera-IMU solve held, as the stored record keeps them (Kalibr's keys
/// without the shutter, and the sigmas of the camera file; null where it gave none).
YAML::Node held_intrinsics_node(const CameraIntrinsicsRecord& k) {
  YAML::Node node(YAML::NodeType::Map);
  camera_to_yaml(k.camera, node);
  for (const auto& [key, values] : {std::pair{"intrinsics_sigma", &k.intrinsics_sigma},
                                    std::pair{"distortion_coeffs_sigma", &k.distortion_coeffs_sigma}}) {
    YAML::Node list(YAML::NodeType::Sequence);
    for (double v : *values) list.push_back(yaml_sigma(v));
    list.SetStyle(YAML::EmitterStyle::Flow);
    node[key] = list;
  }
  return node;
}

json camera_model_json(const CameraModel& c) {
  json j = {{"camera_model", projection_model_name(c.projection)},
            {"intrinsics", kalibr_intrinsics(c.projection, c.intrinsics, c.projection_params)},
            {"distortion_model", distortion_model_name(c.distortion_model)},
            {"distortion_coeffs", kalibr_distortion(c.distortion_model, c.distortion_coeffs)},
            {"resolution", {c.width, c.height}}};
  // The shutter's keys as camera_to_yaml writes them (read back by camera_from_yaml).
  if (c.shutter.rolling()) {
    j["shutter"] = shutter_kind_name(c.shutter.kind);
    j["line_delay_s"] = c.shutter.line_delay_s;
    j["readout_direction"] = readout_name(c.shutter.readout);
    j["stamp_row"] = stamp_row_name(c.shutter.stamp_row);
  }
  return j;
}

/// The rotation angle of a rotation matrix, rad.
double angle_of(const Eigen::Matrix3d& R) { return Eigen::AngleAxisd(R).angle(); }

json quality_json(const CamImuQuality& q) {
  json xcorr = json::array();
  for (const auto& curve : q.xcorr) {
    json lags = json::array(), values = json::array();
    for (const auto& [lag, value] : curve) {
      lags.push_back(lag);
      values.push_back(value);
    }
    xcorr.push_back({{"lag_s", lags}, {"value", values}});
  }
  return {{"accel_residual_rms_mps2", vec_json(q.accel_residual_rms)},
          {"gyro_residual_rms_radps", vec_json(q.gyro_residual_rms)},
          {"accel_sigma_mps2", q.accel_sigma},
          {"gyro_sigma_radps", q.gyro_sigma},
          {"accel_sigma_given_mps2", q.accel_sigma_given},
          {"gyro_sigma_given_radps", q.gyro_sigma_given},
          {"accel_noise_from_residuals", q.accel_noise_from_residuals},
          {"gyro_noise_from_residuals", q.gyro_noise_from_residuals},
          {"rotation_excitation_radps", vec_json(q.rotation_excitation_radps)},
          {"accel_excitation_mps2", vec_json(q.accel_excitation_mps2)},
          {"xcorr", xcorr},
          {"xcorr_peak_s", q.xcorr_peak_s},
          {"iterations", q.iterations},
          {"initial_cost", q.initial_cost},
          {"final_cost", q.final_cost},
          {"parameters", q.parameters},
          {"residuals", q.residuals},
          {"spline_knots", q.spline_knots},
          {"imu_samples_per_residual", q.imu_samples_per_residual},
          {"knot_spacing_s", q.knot_spacing_s},
          {"knot_spacing_chosen", q.knot_spacing_chosen},
          {"gyro_fit_sigma_radps",
           vec_json(Eigen::Map<const Eigen::VectorXd>(
               q.gyro_fit_sigma_radps.data(), static_cast<Eigen::Index>(q.gyro_fit_sigma_radps.size())))},
          {"imu_residuals", q.imu_residuals},
          {"covariance_cluster_s", q.covariance_cluster_s},
          {"covariance_clusters", q.covariance_clusters},
          {"timings_s",
           {{"init", q.init_s},
            {"solve", q.solve_s},
            {"jacobian", q.jacobian_s},
            {"linear_solver", q.linear_solver_s},
            {"covariance", q.covariance_s}}}};
}

json camera_json(const CamImuCameraResult& c, const CamImuCameraReport* in) {
  const Eigen::Quaterniond q(c.T_cam_imu.rotation());
  json j = {{"name", c.name},
            {"stream", c.stream},
            {"camera", camera_model_json(c.camera)},
            {"T_cam_imu", mat_json(matrix_of(c.T_cam_imu))},
            {"q_cam_imu_wxyz", {q.w(), q.x(), q.y(), q.z()}},
            {"t_cam_imu_m", vec_json(c.T_cam_imu.translation())},
            {"rotation_sigma_rad", vec_json(c.rotation_sigma_rad)},
            {"translation_sigma_m", vec_json(c.translation_sigma_m)},
            {"timeshift_cam_imu_s", c.timeshift_cam_imu_s},
            {"timeshift_sigma_s", num(c.timeshift_sigma_s)},
            {"line_delay_sigma_s", num(c.line_delay_sigma_s)},
            {"shutter_choice", c.shutter_choice},
            {"intrinsics_uncertainty", c.intrinsics_uncertainty},
            {"rotation_sigma_from_intrinsics_rad", vec_json(c.rotation_sigma_from_intrinsics_rad)},
            {"translation_sigma_from_intrinsics_m", vec_json(c.translation_sigma_from_intrinsics_m)},
            {"frames", c.frames},
            {"corners", c.corners},
            {"outlier_corners", c.outlier_corners},
            {"rejected_frames_t_ns", c.rejected_frames},
            {"reprojection_rms_px", c.reprojection_rms_px},
            {"corner_sigma_px", c.corner_sigma_px}};
  // Residuals as a flat [dx0, dy0, dx1, ...] list, to 1e-4 px (far below any corner's noise).
  json px = json::array();
  for (const auto& v : c.residuals_px) {
    px.push_back(std::round(v.x() * 1e4) / 1e4);
    px.push_back(std::round(v.y() * 1e4) / 1e4);
  }
  j["residuals"] = {{"px", std::move(px)}, {"outlier_px", c.outlier_px}, {"of_corners", c.corners}};
  if (in != nullptr) {
    j["rostopic"] = in->rostopic;
    j["source"] = in->source;
    j["detections"] = {{"key", in->detection_key},
                       {"frames", in->frames},
                       {"frames_with_target", in->frames_with_target},
                       {"reused", !in->detections_reused_from.empty()},
                       {"reused_from", in->detections_reused_from},
                       {"stored", !in->detections_stored_in.empty()},
                       {"stored_in", in->detections_stored_in},
                       {"wall_s", in->detection_wall_s}};
  }
  return j;
}

json inputs_json(const CamImuReport& r) {
  const auto& o = r.options;
  json cameras = json::array();
  for (const auto& c : r.cameras) cameras.push_back(c.source);
  return {{"log", r.log_path},
          {"log_software_version", r.log_software_version},
          {"imu_stream",
           {{"name", r.imu_stream.name},
            {"input_units", imu_units_name(r.imu_stream.units)},
            {"rate_hz", r.imu_stream.rate_hz},
            {"samples", r.imu_samples},
            {"rostopic", r.imu_rostopic}}},
          {"cameras", cameras},
          {"target_yaml", target_to_yaml(r.target)},
          {"target_source", r.target_source},
          {"noise_source", r.noise_source},
          {"noise",
           {{"accelerometer_noise_density", o.noise.accel_noise_density},
            {"accelerometer_random_walk", o.noise.accel_random_walk},
            {"gyroscope_noise_density", o.noise.gyro_noise_density},
            {"gyroscope_random_walk", o.noise.gyro_random_walk}}},
          {"imu_intrinsics", r.imu_intrinsics_source},
          {"gsens", r.gsens_source},
          {"thermal", r.thermal_source},
          {"gravity_mps2", o.gravity_mps2},
          {"gravity_source", r.gravity_source},
          {"options",
           {{"model", camimu_model_name(o.model)},
            {"spline_order", o.spline_order},
            {"knot_spacing_s", o.knot_spacing_s},
            {"bias_knot_spacing_s", o.bias_knot_spacing_s},
            {"corner_sigma_px", o.corner_sigma_px},
            {"reprojection_loss_sigmas", o.reprojection_loss_sigmas},
            {"max_timeshift_s", o.max_timeshift_s},
            {"max_iterations", o.max_iterations},
            {"imu_max_rate_hz", o.imu_max_rate_hz},
            {"imu_noise_from_residuals", o.imu_noise_from_residuals},
            {"prior", o.prior.enabled ? json(o.prior.source) : json(nullptr)},
            {"threads", o.threads},
            {"covariance", o.covariance}}}};
}

// ---- reading result.json -----------------------------------------------------------------------

using result_text::read_canonical;
using result_text::read_list;
using result_text::read_mat;
using result_text::read_thermal;
using result_text::read_units;
using result_text::read_vec;

KrebsImuModel read_krebs(const json& j) {
  KrebsImuModel k;
  k.S_a = read_vec<3>(j.at("S_a"));
  k.M_a = read_vec<3>(j.at("M_a"));
  k.b_a = read_vec<3>(j.at("b_a"));
  k.S_g = read_vec<3>(j.at("S_g"));
  k.M_g = read_vec<3>(j.at("M_g"));
  k.C_bg = read_mat<3, 3>(j.at("C_bg"));
  k.B_g = read_mat<3, 3>(j.at("B_g"));
  k.b_g = read_vec<3>(j.at("b_g"));
  return k;
}

KrebsImuSigma read_krebs_sigma(const json& j) {
  KrebsImuSigma s;
  s.S_a = read_vec<3>(j.at("S_a"));
  s.M_a = read_vec<3>(j.at("M_a"));
  s.b_a = read_vec<3>(j.at("b_a"));
  s.S_g = read_vec<3>(j.at("S_g"));
  s.M_g = read_vec<3>(j.at("M_g"));
  s.C_bg = read_vec<3>(j.at("C_bg_rad"));
  s.B_g = read_mat<3, 3>(j.at("B_g"));
  s.b_g = read_vec<3>(j.at("b_g"));
  return s;
}

CamImuCameraResult read_camera(const json& j, const std::string& path) {
  CamImuCameraResult c;
  c.name = j.at("name").get<std::string>();
  c.stream = j.at("stream").get<std::string>();
  // JSON is YAML: the camera map reads with the camchain reader.
  auto camera = camera_from_yaml(
      YAML::Load(j.at("camera").dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)),
      path + " " + c.name);
  if (!camera.ok()) throw std::runtime_error(camera.error().message);
  c.camera = *camera;
  c.T_cam_imu.matrix() = read_mat<4, 4>(j.at("T_cam_imu"));
  c.rotation_sigma_rad = read_vec<3>(j.at("rotation_sigma_rad"));
  c.translation_sigma_m = read_vec<3>(j.at("translation_sigma_m"));
  c.timeshift_cam_imu_s = j.at("timeshift_cam_imu_s").get<double>();
  c.timeshift_sigma_s =
      j.at("timeshift_sigma_s").is_null() ? std::nan("") : j.at("timeshift_sigma_s").get<double>();
  // Results written before the shutter was solved have neither.
  if (j.contains("line_delay_sigma_s") && !j.at("line_delay_sigma_s").is_null())
    c.line_delay_sigma_s = j.at("line_delay_sigma_s").get<double>();
  c.shutter_choice = j.value("shutter_choice", std::string());
  // Results written before the held intrinsics were propagated have none of these.
  c.intrinsics_uncertainty = j.value("intrinsics_uncertainty", std::string());
  if (j.contains("rotation_sigma_from_intrinsics_rad"))
    c.rotation_sigma_from_intrinsics_rad = read_vec<3>(j.at("rotation_sigma_from_intrinsics_rad"));
  if (j.contains("translation_sigma_from_intrinsics_m"))
    c.translation_sigma_from_intrinsics_m = read_vec<3>(j.at("translation_sigma_from_intrinsics_m"));
  c.frames = j.at("frames").get<int>();
  c.corners = j.at("corners").get<int>();
  c.outlier_corners = j.at("outlier_corners").get<int>();
  // Results written before frames were checked against the gyro have none.
  if (j.contains("rejected_frames_t_ns"))
    c.rejected_frames = j.at("rejected_frames_t_ns").get<std::vector<TimeNs>>();
  c.reprojection_rms_px = j.at("reprojection_rms_px").get<double>();
  c.corner_sigma_px = j.at("corner_sigma_px").get<double>();
  // Results written before the residuals were stored have none.
  if (j.contains("residuals")) {
    const json& px = j["residuals"].at("px");
    for (std::size_t i = 0; i + 1 < px.size(); i += 2)
      c.residuals_px.emplace_back(px[i].get<float>(), px[i + 1].get<float>());
    c.outlier_px = j["residuals"].value("outlier_px", 0.0);
  }
  return c;
}

CamImuQuality read_quality(const json& j) {
  CamImuQuality q;
  q.accel_residual_rms = read_vec<3>(j.at("accel_residual_rms_mps2"));
  q.gyro_residual_rms = read_vec<3>(j.at("gyro_residual_rms_radps"));
  q.accel_sigma = j.at("accel_sigma_mps2").get<double>();
  q.gyro_sigma = j.at("gyro_sigma_radps").get<double>();
  // Results written before the noise check hold only the sigmas used.
  q.accel_sigma_given = j.value("accel_sigma_given_mps2", q.accel_sigma);
  q.gyro_sigma_given = j.value("gyro_sigma_given_radps", q.gyro_sigma);
  q.accel_noise_from_residuals = j.value("accel_noise_from_residuals", false);
  q.gyro_noise_from_residuals = j.value("gyro_noise_from_residuals", false);
  q.rotation_excitation_radps = read_vec<3>(j.at("rotation_excitation_radps"));
  q.accel_excitation_mps2 = read_vec<3>(j.at("accel_excitation_mps2"));
  for (const auto& curve : j.at("xcorr")) {
    const auto lags = curve.at("lag_s").get<std::vector<double>>();
    const auto values = curve.at("value").get<std::vector<double>>();
    if (lags.size() != values.size()) throw std::runtime_error("xcorr lag_s and value differ in length");
    std::vector<std::pair<double, double>> c;
    for (std::size_t i = 0; i < lags.size(); ++i) c.emplace_back(lags[i], values[i]);
    q.xcorr.push_back(std::move(c));
  }
  q.xcorr_peak_s = j.at("xcorr_peak_s").get<std::vector<double>>();
  q.iterations = j.at("iterations").get<int>();
  q.initial_cost = j.at("initial_cost").get<double>();
  q.final_cost = j.at("final_cost").get<double>();
  q.parameters = j.at("parameters").get<int>();
  q.residuals = j.at("residuals").get<int>();
  q.spline_knots = j.at("spline_knots").get<int>();
  q.imu_samples_per_residual = j.value("imu_samples_per_residual", 1);
  q.knot_spacing_s = j.value("knot_spacing_s", 0.0);
  q.knot_spacing_chosen = j.value("knot_spacing_chosen", false);
  q.imu_residuals = j.value("imu_residuals", 0);
  q.covariance_cluster_s = j.value("covariance_cluster_s", 0.0);
  q.covariance_clusters = j.value("covariance_clusters", 0);
  const json& t = j.at("timings_s");
  q.init_s = t.at("init").get<double>();
  q.solve_s = t.at("solve").get<double>();
  q.jacobian_s = t.at("jacobian").get<double>();
  q.linear_solver_s = t.at("linear_solver").get<double>();
  q.covariance_s = t.at("covariance").get<double>();
  return q;
}

/// One row per stored sample: t_s (from the first bias sample), then measured and predicted
/// accel and gyro, rounded far below the sensor's noise (1e-6 m/s^2, 1e-7 rad/s).
constexpr const char* kSignalColumns[] = {"t_s",          "accel_meas_x", "accel_meas_y", "accel_meas_z",
                                          "accel_pred_x", "accel_pred_y", "accel_pred_z", "gyro_meas_x",
                                          "gyro_meas_y",  "gyro_meas_z",  "gyro_pred_x",  "gyro_pred_y",
                                          "gyro_pred_z"};

json signals_json(const std::vector<ImuSignalFit>& fits, TimeNs t0) {
  json out = json::array();
  auto round_to = [](double v, double q) { return std::round(v / q) * q; };
  for (const auto& f : fits) {
    json rows = json::array();
    for (std::size_t i = 0; i < f.t_ns.size(); ++i) {
      json row = {round_to(ns_to_s(f.t_ns[i] - t0), 1e-6)};
      for (const auto* v : {&f.accel_measured[i], &f.accel_predicted[i]})
        for (int a = 0; a < 3; ++a) row.push_back(round_to((*v)[a], 1e-6));
      for (const auto* v : {&f.gyro_measured[i], &f.gyro_predicted[i]})
        for (int a = 0; a < 3; ++a) row.push_back(round_to((*v)[a], 1e-7));
      rows.push_back(std::move(row));
    }
    out.push_back({{"model", f.model},
                   {"accel_residual_rms_mps2", vec_json(f.accel_residual_rms)},
                   {"gyro_residual_rms_radps", vec_json(f.gyro_residual_rms)},
                   {"t0_ns", t0},
                   {"columns", kSignalColumns},
                   {"rows", std::move(rows)}});
  }
  return out;
}

std::vector<ImuSignalFit> read_signals(const json& j) {
  std::vector<ImuSignalFit> fits;
  for (const auto& s : j) {
    ImuSignalFit f;
    f.model = s.at("model").get<std::string>();
    f.accel_residual_rms = read_vec<3>(s.at("accel_residual_rms_mps2"));
    f.gyro_residual_rms = read_vec<3>(s.at("gyro_residual_rms_radps"));
    const TimeNs t0 = s.at("t0_ns").get<TimeNs>();
    for (const auto& row : s.at("rows")) {
      if (row.size() != std::size(kSignalColumns))
        throw std::runtime_error("imu_signals: a row is not 13 numbers");
      auto v3 = [&](std::size_t i) {
        return Eigen::Vector3f(row[i].get<float>(), row[i + 1].get<float>(), row[i + 2].get<float>());
      };
      f.t_ns.push_back(t0 + static_cast<TimeNs>(std::llround(row[0].get<double>() * 1e9)));
      f.accel_measured.push_back(v3(1));
      f.accel_predicted.push_back(v3(4));
      f.gyro_measured.push_back(v3(7));
      f.gyro_predicted.push_back(v3(10));
    }
    fits.push_back(std::move(f));
  }
  return fits;
}

CamImuCalibrationResult read_result_json(const json& j, const std::string& path) {
  CamImuCalibrationResult r;
  const std::string model = j.at("model").get<std::string>();
  if (model != "basic" && model != "extended") throw std::runtime_error("model '" + model + "' is unknown");
  r.model = model == "basic" ? CamImuModelKind::kBasic : CamImuModelKind::kExtended;
  for (const auto& c : j.at("cameras")) r.cameras.push_back(read_camera(c, path));
  const json& imu = j.at("imu");
  r.imu = read_krebs(imu.at("krebs"));
  r.imu_sigma = read_krebs_sigma(imu.at("krebs_sigma"));
  r.canonical = read_canonical(imu.at("canonical_nominal_si"));
  r.fixed = j.at("fixed").get<std::vector<std::string>>();
  r.gravity_w = read_vec<3>(j.at("gravity_w_mps2"));
  r.gravity_sigma_rad = read_vec<2>(j.at("gravity_sigma_rad"));
  for (const auto& b : j.at("biases")) {
    r.biases.push_back({b.at("t_ns").get<TimeNs>(), read_vec<3>(b.at("b_a")), read_vec<3>(b.at("b_g"))});
  }
  // Results written before the signals were stored have none.
  if (j.contains("imu_signals")) r.signal_fits = read_signals(j["imu_signals"]);
  r.quality = read_quality(j.at("quality"));
  // Results written before the self-check have none (not run).
  if (j.contains("self_check") && j["self_check"].is_object())
    r.self_check = read_split_check(j["self_check"]);
  r.warnings = j.at("warnings").get<std::vector<std::string>>();
  r.model_choice = j.value("model_choice", std::string());
  r.undetermined = j.value("undetermined", std::vector<std::string>());
  if (j.contains("prior") && j["prior"].is_object()) {
    const json& p = j["prior"];
    r.prior_source = p.value("source", std::string());
    if (p.contains("sigma")) r.prior_sigma = read_krebs_sigma(p["sigma"]);
    r.prior_dominated = p.value("dominated", std::vector<std::string>());
  }
  return r;
}

}  // namespace

KalibrImuIntrinsics kalibr_from_krebs(const KrebsImuModel& k) {
  KalibrImuIntrinsics out;
  out.M_accel = k.S_a.asDiagonal() * krebs_misalignment(k.M_a);
  out.M_gyro = k.S_g.asDiagonal() * krebs_misalignment(k.M_g);
  out.C_gyro_i = k.C_bg.transpose();
  out.A = k.B_g;
  return out;
}

CameraIntrinsicsRecord held_intrinsics(const CamImuReport& report, std::size_t i) {
  CameraIntrinsicsRecord k;
  k.camera = report.result.cameras.at(i).camera;
  k.camera.shutter = Shutter{};
  if (i < report.cameras.size()) {
    k.intrinsics_sigma = report.cameras[i].intrinsics_sigma;
    k.distortion_coeffs_sigma = report.cameras[i].distortion_coeffs_sigma;
  }
  // A report made without the camera files' covariance: as many sigmas, none known.
  const auto none = Eigen::Vector4d::Constant(kNotDetermined);
  if (k.intrinsics_sigma.empty())
    k.intrinsics_sigma =
        kalibr_intrinsics(k.camera.projection, none, Eigen::Vector2d::Constant(kNotDetermined));
  if (k.distortion_coeffs_sigma.empty())
    k.distortion_coeffs_sigma = kalibr_distortion(k.camera.distortion_model, none);
  return k;
}

std::string camimu_camchain_yaml(const CamImuReport& r) {
  YAML::Node root(YAML::NodeType::Map);
  const auto& cams = r.result.cameras;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const CamImuCameraResult& c = cams[i];
    const CamImuCameraReport* in = i < r.cameras.size() ? &r.cameras[i] : nullptr;
    YAML::Node cam(YAML::NodeType::Map);
    camera_to_yaml(c.camera, cam);
    cam["rostopic"] = in != nullptr ? in->rostopic : "/" + c.stream + "/image_raw";
    // Kalibr's cam_overlaps as the camera files gave them; one camera overlaps none.
    if (in != nullptr && in->cam_overlaps) {
      cam["cam_overlaps"] = *in->cam_overlaps;
      cam["cam_overlaps"].SetStyle(YAML::EmitterStyle::Flow);
    } else if (cams.size() == 1) {
      cam["cam_overlaps"] = YAML::Node(YAML::NodeType::Sequence);
      cam["cam_overlaps"].SetStyle(YAML::EmitterStyle::Flow);
    }
    cam["T_cam_imu"] = rows(matrix_of(c.T_cam_imu));
    cam["timeshift_cam_imu"] = c.timeshift_cam_imu_s;
    // Kalibr's chain: each camera from the one before it.
    if (i > 0) cam["T_cn_cnm1"] = rows(matrix_of(c.T_cam_imu * cams[i - 1].T_cam_imu.inverse()));
    YAML::Node q(YAML::NodeType::Map);
    q["rotation_sigma_rad"] = flow_vec(c.rotation_sigma_rad);
    q["translation_sigma_m"] = flow_vec(c.translation_sigma_m);
    q["timeshift_sigma_s"] = c.timeshift_sigma_s;
    if (c.camera.shutter.rolling()) q["line_delay_sigma_s"] = yaml_sigma(c.line_delay_sigma_s);
    if (!c.shutter_choice.empty()) q["shutter_choice"] = c.shutter_choice;
    if (!c.intrinsics_uncertainty.empty()) q["intrinsics_uncertainty"] = c.intrinsics_uncertainty;
    q["reprojection_rms_px"] = c.reprojection_rms_px;
    q["corner_sigma_px"] = c.corner_sigma_px;
    q["frames"] = c.frames;
    q["corners"] = c.corners;
    q["outlier_corners"] = c.outlier_corners;
    q["rejected_frames"] = static_cast<int>(c.rejected_frames.size());
    q["camera_stream"] = c.stream;
    if (in != nullptr) q["intrinsics_from"] = in->source;
    q["log"] = r.log_path;
    q["convention"] =
        "T_cam_imu maps IMU body points into the camera frame; t_imu = t_cam + timeshift_cam_imu";
    cam["imucal"] = q;
    root["cam" + std::to_string(i)] = cam;
  }
  return emit(root,
              "# Camera-IMU calibration (imucal calibrate camimu); Kalibr camchain-imucam format, imucal's "
              "figures under camN.imucal\n# (docs/camimu-calibration.md)\n");
}

namespace {
double six_significant(double v) { return std::strtod(format_number("%.6g", v).c_str(), nullptr); }

double update_rate_of(const CamImuReport& r) {
  // As the --imu file gave it; else the stream's rate to six digits (a rate measured from stamps
  // carries the jitter of its intervals).
  return r.imu_update_rate > 0.0 ? r.imu_update_rate : six_significant(r.imu_stream.rate_hz);
}
}  // namespace

std::string camimu_imu_input_yaml(const CamImuReport& r) {
  const auto& n = r.options.noise;
  YAML::Node imu(YAML::NodeType::Map);
  imu["accelerometer_noise_density"] = n.accel_noise_density;
  imu["accelerometer_random_walk"] = n.accel_random_walk;
  imu["gyroscope_noise_density"] = n.gyro_noise_density;
  imu["gyroscope_random_walk"] = n.gyro_random_walk;
  imu["rostopic"] = r.imu_rostopic;
  imu["update_rate"] = update_rate_of(r);
  return emit(
      imu, std::string("# IMU noise model (Kalibr's --imu form) the camera-IMU calibration used; from ") +
               r.noise_source + "\n# (imucal calibrate camimu; its result: " + kCamImuImuResultFile + ")\n");
}

std::string camimu_imu_yaml(const CamImuReport& r) {
  const auto& res = r.result;
  const auto& n = r.options.noise;
  YAML::Node imu(YAML::NodeType::Map);
  imu["T_i_b"] = rows(Eigen::Matrix4d::Identity());
  imu["accelerometer_noise_density"] = n.accel_noise_density;
  imu["accelerometer_random_walk"] = n.accel_random_walk;
  imu["gyroscope_noise_density"] = n.gyro_noise_density;
  imu["gyroscope_random_walk"] = n.gyro_random_walk;
  imu["model"] = res.model == CamImuModelKind::kBasic ? "calibrated" : "scale-misalignment";
  imu["rostopic"] = r.imu_rostopic;
  imu["time_offset"] = 0.0;
  imu["update_rate"] = update_rate_of(r);
  if (res.model == CamImuModelKind::kExtended) {
    const KalibrImuIntrinsics k = kalibr_from_krebs(res.imu);
    YAML::Node accel(YAML::NodeType::Map), gyro(YAML::NodeType::Map);
    accel["M"] = rows(k.M_accel);
    gyro["M"] = rows(k.M_gyro);
    gyro["A"] = rows(k.A);
    gyro["C_gyro_i"] = rows(k.C_gyro_i);
    imu["accelerometers"] = accel;
    imu["gyroscopes"] = gyro;
  }
  YAML::Node q(YAML::NodeType::Map);
  q["form"] = "a_raw = M_accel a + b_a; w_raw = M_gyro C_gyro_i w + A C_gyro_i a + b_g (nominal SI)";
  q["b_a"] = flow_vec(res.imu.b_a);
  q["b_g"] = flow_vec(res.imu.b_g);
  q["biases_at"] = "start of the recording (result.json holds them over time)";
  q["krebs"] = krebs_node(res.imu, res.imu_sigma);
  q["stream"] = r.imu_stream.name;
  q["input_units"] = imu_units_name(r.imu_stream.units);
  q["noise_source"] = r.noise_source;
  q["fixed"] = string_list(res.fixed);
  imu["imucal"] = q;
  YAML::Node root(YAML::NodeType::Map);
  root["imu0"] = imu;
  return emit(
      root,
      "# IMU of the camera-IMU calibration (imucal calibrate camimu); Kalibr's IMU result format, on the "
      "stream's\n# nominal SI values; imucal's figures under imu0.imucal (docs/camimu-calibration.md)\n");
}

std::string camimu_calibration_yaml(const CamImuReport& r) {
  const auto& res = r.result;
  YAML::Node root(YAML::NodeType::Map);
  root["method"] = kCamImuMethod;
  root["model"] = camimu_model_name(res.model);
  root["model_choice"] = res.model_choice;
  root["stream"] = r.imu_stream.name;
  root["input_units"] = imu_units_name(r.imu_stream.units);
  root["canonical"] = canonical_node(canonical_on_input_units(res.canonical, r.imu_stream));
  root["canonical_nominal_si"] = canonical_node(res.canonical);
  root["krebs"] = krebs_node(res.imu, res.imu_sigma);
  root["gravity"] = r.options.gravity_mps2;
  root["gravity_w"] = flow_vec(res.gravity_w);
  root["gravity_sigma_rad"] = flow_vec(res.gravity_sigma_rad);
  root["fixed"] = string_list(res.fixed);
  root["undetermined"] = string_list(res.undetermined);
  if (!res.prior_source.empty()) root["prior_source"] = res.prior_source;
  if (r.thermal) {
    root["reference_temperature_c"] = r.thermal->reference_c;
    root["thermal"] =
        YAML::Load(thermal_model_json(*r.thermal).dump(-1, ' ', false, json::error_handler_t::replace));
  }
  YAML::Node cams(YAML::NodeType::Map);
  for (std::size_t i = 0; i < res.cameras.size(); ++i) {
    const auto& c = res.cameras[i];
    YAML::Node cam(YAML::NodeType::Map);
    cam["stream"] = c.stream;
    cam["T_cam_imu"] = rows(matrix_of(c.T_cam_imu));
    cam["rotation_sigma_rad"] = flow_vec(c.rotation_sigma_rad);
    cam["translation_sigma_m"] = flow_vec(c.translation_sigma_m);
    cam["timeshift_cam_imu"] = c.timeshift_cam_imu_s;
    cam["timeshift_sigma_s"] = c.timeshift_sigma_s;
    cam["shutter"] = shutter_kind_name(c.camera.shutter.kind);
    if (c.camera.shutter.rolling()) {
      cam["line_delay_s"] = c.camera.shutter.line_delay_s;
      cam["line_delay_sigma_s"] = yaml_sigma(c.line_delay_sigma_s);
    }
    cam["camera"] = held_intrinsics_node(held_intrinsics(r, i));
    cams["cam" + std::to_string(i)] = cam;
  }
  root["cameras"] = cams;
  root["log"] = r.log_path;
  root["software_version"] = kVersion;
  root["warnings"] = string_list(r.warnings);
  return emit(
      root,
      "# Camera-IMU calibration (imucal calibrate camimu): the canonical record for the stream's input "
      "values\n# (docs/camimu-calibration.md)\n");
}

std::string camimu_result_json(const CamImuReport& r) {
  const auto& res = r.result;
  json cameras = json::array();
  for (std::size_t i = 0; i < res.cameras.size(); ++i)
    cameras.push_back(camera_json(res.cameras[i], i < r.cameras.size() ? &r.cameras[i] : nullptr));
  const KalibrImuIntrinsics k = kalibr_from_krebs(res.imu);
  json biases = json::array();
  const TimeNs t0 = res.biases.empty() ? 0 : res.biases.front().t_ns;
  for (const auto& b : res.biases) {
    biases.push_back({{"t_s", ns_to_s(b.t_ns - t0)},
                      {"t_ns", b.t_ns},
                      {"b_a", vec_json(b.b_a)},
                      {"b_g", vec_json(b.b_g)}});
  }
  json j;
  j["method"] = kCamImuMethod;
  j["software_version"] = kVersion;
  j["model"] = camimu_model_name(res.model);
  j["model_choice"] = res.model_choice;
  j["fixed"] = res.fixed;
  j["undetermined"] = res.undetermined;
  j["prior"] =
      res.prior_source.empty()
          ? json(nullptr)
          : json{{"source", res.prior_source},
                 {"centre", "the starting model (S = 1, M = 0, C_bg = I, B_g = 0 without a prior file)"},
                 {"sigma", krebs_sigma_json(res.prior_sigma)},
                 {"dominated", res.prior_dominated}};
  j["cameras"] = cameras;
  j["imu"] = {{"krebs", krebs_json(res.imu)},
              {"krebs_sigma", krebs_sigma_json(res.imu_sigma)},
              {"C_bg_angle_rad", angle_of(res.imu.C_bg)},
              {"canonical_nominal_si", canonical_json(res.canonical)},
              {"canonical", canonical_json(canonical_on_input_units(res.canonical, r.imu_stream))},
              {"input_units", imu_units_name(r.imu_stream.units)},
              {"kalibr",
               {{"accelerometers", {{"M", mat_json(k.M_accel)}}},
                {"gyroscopes",
                 {{"M", mat_json(k.M_gyro)}, {"A", mat_json(k.A)}, {"C_gyro_i", mat_json(k.C_gyro_i)}}}}}};
  j["gravity_w_mps2"] = vec_json(res.gravity_w);
  j["gravity_sigma_rad"] = vec_json(res.gravity_sigma_rad);
  if (r.thermal) {
    j["reference_temperature_c"] = r.thermal->reference_c;
    j["thermal"] = thermal_model_json(*r.thermal);
  }
  j["biases"] = biases;
  j["imu_signals"] = signals_json(res.signal_fits, t0);
  j["quality"] = quality_json(res.quality);
  j["self_check"] = split_check_json(res.self_check);
  j["inputs"] = inputs_json(r);
  j["notes"] = r.notes;
  j["warnings"] = r.warnings;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

Result<CamImuCalibrationResult> read_camimu_result(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error();
  try {
    return read_result_json(json::parse(*text), path);
  } catch (const std::exception& e) {
    return make_error(Errc::kCorrupt,
                      path + ": not a camera-IMU result.json (" + std::string(e.what()) + ")");
  }
}

namespace {

CamImuCameraResult read_calibration_camera(const json& c, CamImuCameraReport& held,
                                           const std::string& where) {
  CamImuCameraResult cam;
  cam.stream = c.at("stream").get<std::string>();
  cam.T_cam_imu.matrix() = read_mat<4, 4>(c.at("T_cam_imu"));
  if (!cam.T_cam_imu.matrix().allFinite())
    throw std::runtime_error(where + "T_cam_imu must be finite numbers");
  cam.rotation_sigma_rad = read_vec<3>(c.at("rotation_sigma_rad"));
  cam.translation_sigma_m = read_vec<3>(c.at("translation_sigma_m"));
  cam.timeshift_cam_imu_s = c.at("timeshift_cam_imu").get<double>();
  const json& ts = c.at("timeshift_sigma_s");
  cam.timeshift_sigma_s = ts.is_null() ? std::nan("") : ts.get<double>();
  // The held intrinsics as held_intrinsics_node wrote them (a global shutter), with their sigmas.
  const json& k = c.at("camera");
  auto camera = camera_from_yaml(YAML::Load(k.dump(-1, ' ', false, json::error_handler_t::replace)), where);
  if (!camera.ok()) throw std::runtime_error(camera.error().message);
  cam.camera = *camera;
  held.intrinsics_sigma = read_list(k.at("intrinsics_sigma"));
  held.distortion_coeffs_sigma = read_list(k.at("distortion_coeffs_sigma"));
  if (c.value("shutter", std::string()) == shutter_kind_name(Shutter::Kind::kRolling)) {
    cam.camera.shutter.kind = Shutter::Kind::kRolling;
    cam.camera.shutter.line_delay_s = c.at("line_delay_s").get<double>();
    if (!std::isfinite(cam.camera.shutter.line_delay_s))
      throw std::runtime_error(where + "line_delay_s must be a number (s per row)");
    const json& s = c.at("line_delay_sigma_s");
    cam.line_delay_sigma_s = s.is_null() ? std::nan("") : s.get<double>();
  }
  return cam;
}

}  // namespace

Result<CamImuCalibrationFile> parse_camimu_calibration(const json& r, const std::string& origin) {
  try {
    CamImuCalibrationFile f;
    CamImuReport& report = f.report;
    report.imu_stream.name = r.at("stream").get<std::string>();
    report.imu_stream.units = read_units(r.at("input_units"));
    f.canonical_input = read_canonical(r.at("canonical"));
    report.result.imu_sigma = read_krebs_sigma(r.at("krebs").at("sigma"));
    // cam0, cam1, ... in their order (the typed record names them so).
    const json& cams = r.at("cameras");
    if (!cams.is_object()) throw std::runtime_error("cameras must be a mapping of cam0, cam1, ...");
    for (std::size_t i = 0; i < cams.size(); ++i) {
      const std::string name = "cam" + std::to_string(i);
      if (!cams.contains(name)) throw std::runtime_error("cameras: " + name + " is missing");
      report.cameras.emplace_back();
      report.result.cameras.push_back(read_calibration_camera(cams[name], report.cameras.back(), name + " "));
    }
    report.options.gravity_mps2 = r.at("gravity").get<double>();
    if (!(report.options.gravity_mps2 > 0.0))
      throw std::runtime_error("gravity must be a positive number (m/s^2)");
    report.thermal = read_thermal(r);
    report.result.fixed = r.value("fixed", std::vector<std::string>());
    return f;
  } catch (const std::exception& e) {
    return make_error(Errc::kCorrupt, origin + ": a key the calibration needs is missing or malformed (" +
                                          std::string(e.what()) + ")");
  }
}

}  // namespace imucal::app
