// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/camera_results.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "app/camimu_inputs.hpp"
#include "core/version.hpp"
#include "core/yaml_json.hpp"

namespace imucal::app {
namespace {

using nlohmann::json;

/// Bumped when the detector's output for the same image and options can change (a detector
/// fix) or the stored text changes shape: stored detections with another key are not reused.
constexpr int kDetectionFormat = 1;

/// FNV-1a, 64 bits: a fingerprint, not a security measure.
std::uint64_t fnv1a(const std::string& text) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (unsigned char c : text) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}

Result<TargetDescription> parse_target_node(const YAML::Node& node, const std::string& source) {
  YAML::Emitter out;
  out << node;
  auto t = parse_target_yaml(out.c_str(), source);
  if (!t.ok()) return make_error(Errc::kCorrupt, t.error().message);
  return t;
}

/// A sigma for JSON: infinite (undetermined) as null.
json finite_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

/// A sigma list for YAML: infinite (undetermined) as null.
YAML::Node flow_sigmas(const std::vector<double>& v) {
  YAML::Node n(YAML::NodeType::Sequence);
  for (double x : v) n.push_back(std::isfinite(x) ? YAML::Node(x) : YAML::Node(YAML::NodeType::Null));
  n.SetStyle(YAML::EmitterStyle::Flow);
  return n;
}

json sigma_vec(const std::vector<double>& v) {
  json out = json::array();
  for (double x : v) out.push_back(finite_or_null(x));
  return out;
}

/// The sigmas of the model's intrinsics and distortion_coeffs, in Kalibr's order.
std::vector<double> intrinsics_sigmas(const calib::CameraIntrinsicsResult& r) {
  return kalibr_intrinsics(r.camera.projection, r.intrinsics_sigma, r.projection_sigma);
}
std::vector<double> distortion_sigmas(const calib::CameraIntrinsicsResult& r) {
  return kalibr_distortion(r.camera.distortion_model, r.distortion_sigma);
}
/// The covariance of the model's parameters in Kalibr's order (kalibr_parameter_indices).
Eigen::MatrixXd kalibr_covariance(const calib::CameraIntrinsicsResult& r) {
  const std::vector<int> order = kalibr_parameter_indices(r.camera.kind());
  const auto n = static_cast<Eigen::Index>(order.size());
  Eigen::MatrixXd out(n, n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j) out(i, j) = r.covariance(order[i], order[j]);
  return out;
}

/// The choice of `--model auto`: the chosen model, the reason and every candidate's figures.
json model_choice_json(const std::optional<calib::CameraModelChoice>& c) {
  if (!c) return nullptr;
  json fits = json::array();
  for (const auto& f : c->fits) {
    json jf = {{"model", camera_model_name(f.model)},
               {"compared", f.compared},
               {"views_used", f.views_used},
               {"rms_px", f.rms_px}};
    if (f.compared) {
      jf["rss_px2"] = f.rss_px2;
      jf["params"] = f.params;
      jf["bic"] = f.bic;
      jf["delta_bic"] = f.delta_bic;
    } else {
      jf["why_not"] = f.why_not;
    }
    fits.push_back(jf);
  }
  return {{"chosen", camera_model_name(c->chosen)},
          {"criterion", "BIC"},
          {"reason", c->reason},
          {"common_views", c->common_views},
          {"common_corners", c->common_corners},
          {"candidates", fits}};
}

/// Each used view's corner residuals as a flat dx, dy list (px, to 1e-4) and which the corner
/// test rejected, for the report's scatter.
json residuals_json(const calib::CameraIntrinsicsResult& res) {
  json px = json::array(), rejected = json::array();
  for (std::size_t i = 0; i < res.residuals_px.size(); ++i) {
    px.push_back(std::round(res.residuals_px[i].x() * 1e4) / 1e4);
    px.push_back(std::round(res.residuals_px[i].y() * 1e4) / 1e4);
    rejected.push_back(i < res.residual_rejected.size() ? res.residual_rejected[i] : 0);
  }
  return {{"px", std::move(px)},
          {"rejected", std::move(rejected)},
          {"of_corners", res.points_used + res.corners_rejected}};
}

int views_rejected(const CameraCalibrationReport& r) {
  return r.intrinsics.views_total - r.intrinsics.views_used;
}

}  // namespace

Result<TargetChoice> target_from_log_metadata(const std::map<std::string, std::string>& metadata) {
  if (auto it = metadata.find("rig_config"); it != metadata.end()) {
    YAML::Node root;
    try {
      root = YAML::Load(it->second);  // JSON is YAML
    } catch (const YAML::Exception& e) {
      return make_error(Errc::kCorrupt,
                        std::string("the log's rig_config metadata is not valid JSON: ") + e.what());
    }
    if (root.IsMap() && root["target"]) {
      auto t = parse_target_node(root["target"], "the log's rig_config metadata");
      if (!t.ok()) return make_error(Errc::kCorrupt, t.error().message);
      return TargetChoice{*t, "rig_config metadata"};
    }
  }
  if (auto it = metadata.find("target"); it != metadata.end()) {
    auto t = parse_target_yaml(it->second, "the log's target metadata");
    if (!t.ok()) return make_error(Errc::kCorrupt, t.error().message);
    return TargetChoice{*t, "target metadata"};
  }
  return make_error(Errc::kNotFound,
                    "the log names no calibration target (no target in its rig_config or target "
                    "metadata): give the target's Kalibr YAML")
      .with_remedy("target");
}

std::string detection_key(const TargetDescription& target, const calib::DetectionOptions& options) {
  const std::string what =
      target_to_yaml(target) + "|subpixel=" + std::to_string(options.subpixel) +
      "|partial=" + std::to_string(options.partial) + "|min_tags=" + std::to_string(options.min_tags) +
      "|checkerboard_method=" + std::to_string(static_cast<int>(options.checkerboard_method)) +
      "|aprilgrid_decimate=" + std::to_string(options.aprilgrid_decimate) + "|imucal=" + kVersion +
      "|detector=" + std::to_string(calib::kTargetDetectorRevision) +
      "|format=" + std::to_string(kDetectionFormat);
  char text[40];
  std::snprintf(text, sizeof text, "v%d-%016llx", kDetectionFormat,
                static_cast<unsigned long long>(fnv1a(what)));
  return text;
}

std::string encode_detection(const calib::TargetObservation& o) {
  json px = json::array();
  for (const auto& p : o.px) {
    px.push_back(p.x());
    px.push_back(p.y());
  }
  return json{{"width", o.width}, {"height", o.height}, {"ids", o.ids}, {"px", px}}.dump(
      -1, ' ', false, nlohmann::json::error_handler_t::replace);
}

Result<calib::TargetObservation> decode_detection(const std::string& text, TimeNs t_ns) {
  calib::TargetObservation o;
  o.t_ns = t_ns;
  try {
    const json j = json::parse(text);
    o.width = j.at("width").get<int>();
    o.height = j.at("height").get<int>();
    o.ids = j.at("ids").get<std::vector<int>>();
    const auto px = j.at("px").get<std::vector<double>>();
    if (px.size() != 2 * o.ids.size()) throw std::runtime_error("px and ids differ in length");
    for (std::size_t i = 0; i < o.ids.size(); ++i) o.px.emplace_back(px[2 * i], px[2 * i + 1]);
  } catch (const std::exception& e) {
    return make_error(Errc::kCorrupt,
                      "a stored detection (t_ns " + std::to_string(t_ns) + ") is malformed: " + e.what());
  }
  return o;
}

namespace {

/// A number, or null where it is not determined (NaN, infinite).
YAML::Node number_or_null(double v) {
  return std::isfinite(v) ? YAML::Node(v) : YAML::Node(YAML::NodeType::Null);
}

/// A covariance matrix row by row (flow style), null where not determined.
YAML::Node covariance_rows(const Eigen::MatrixXd& m) {
  YAML::Node rows(YAML::NodeType::Sequence);
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    YAML::Node row(YAML::NodeType::Sequence);
    for (Eigen::Index j = 0; j < m.cols(); ++j) row.push_back(number_or_null(m(i, j)));
    row.SetStyle(YAML::EmitterStyle::Flow);
    rows.push_back(row);
  }
  return rows;
}

/// One camera's camchain entry: Kalibr's keys and imucal's figures under `imucal`.
YAML::Node camera_node(const CameraCalibrationReport& r) {
  const auto& res = r.intrinsics;
  YAML::Node cam(YAML::NodeType::Map);
  camera_to_yaml(res.camera, cam);
  cam["rostopic"] = camera_rostopic(r.stream);
  YAML::Node q(YAML::NodeType::Map);
  q["intrinsics_sigma"] = flow_sigmas(intrinsics_sigmas(res));
  q["distortion_coeffs_sigma"] = flow_sigmas(distortion_sigmas(res));
  if (r.model_choice) q["model_choice"] = r.model_choice->reason;
  // The covariance of the model's parameters in Kalibr's order (intrinsics, then
  // distortion_coeffs); calibrate camimu propagates it into its sigmas
  // (docs/camimu-calibration.md, "Uncertainty").
  if (res.covariance_ok) q["intrinsics_covariance"] = covariance_rows(kalibr_covariance(res));
  q["reprojection_rms_px"] = res.rms_px;
  q["residual_sigma_px"] = res.residual_sigma_px;
  q["focal_well_determined"] = res.focal_well_determined;
  if (std::isfinite(res.profile_chi2)) {
    q["profile_chi2"] = res.profile_chi2;
    q["profile_sigma_stretch"] = res.profile_stretch;
  }
  if (res.camera.shutter.rolling()) q["line_delay_sigma_s"] = number_or_null(r.line_delay_sigma_s);
  if (!r.shutter_choice.empty()) q["shutter_choice"] = r.shutter_choice;
  q["coverage"] = res.coverage;
  YAML::Node grid(YAML::NodeType::Sequence);
  grid.push_back(res.coverage_cols);
  grid.push_back(res.coverage_rows);
  grid.SetStyle(YAML::EmitterStyle::Flow);
  q["coverage_grid"] = grid;
  q["frames"] = r.frames;
  q["frames_with_target"] = r.frames_with_target;
  q["views_used"] = res.views_used;
  q["views_rejected"] = views_rejected(r);
  q["views_not_chosen"] = r.views_not_chosen;
  q["corners_used"] = res.points_used;
  q["corners_rejected"] = res.corners_rejected;
  q["log"] = r.log_path;
  q["camera_stream"] = r.stream.name;
  q["target"] = YAML::Load(target_to_yaml(r.target));
  q["target_source"] = r.target_source;
  q["software_version"] = kVersion;
  YAML::Node warnings(YAML::NodeType::Sequence);
  for (const auto& w : r.warnings) warnings.push_back(w);
  q["warnings"] = warnings;
  cam["imucal"] = q;
  return cam;
}

YAML::Node flow3(const Eigen::Vector3d& v) {
  YAML::Node n(YAML::NodeType::Sequence);
  for (int i = 0; i < 3; ++i) n.push_back(number_or_null(v[i]));
  n.SetStyle(YAML::EmitterStyle::Flow);
  return n;
}

/// The cameras each camera shares at least `min_shared` views with (Kalibr's cam_overlaps).
std::vector<int> overlaps(const calib::CameraChainCameraResult& c, int min_shared) {
  std::vector<int> out;
  for (std::size_t j = 0; j < c.shared_views.size(); ++j)
    if (c.shared_views[j] >= min_shared) out.push_back(static_cast<int>(j));
  return out;
}

}  // namespace

std::string camera_result_yaml(const CameraCalibrationReport& r) {
  YAML::Node root(YAML::NodeType::Map);
  root["cam0"] = camera_node(r);
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << root;
  return "# Camera intrinsics (imucal calibrate camera); Kalibr camchain format, imucal's figures under "
         "cam0.imucal\n# (docs/camera-calibration.md)\n" +
         std::string(out.c_str()) + "\n";
}

namespace {

json camera_json(const CameraCalibrationReport& r) {
  const auto& res = r.intrinsics;
  json views = json::array();
  for (const auto& v : res.views) {
    json jv = {{"t_ns", v.t_ns}, {"points", v.points}, {"used", v.used}, {"rms_px", v.rms_px}};
    if (v.used) {
      jv["points_used"] = v.points_used;
      jv["q_cam_target_wxyz"] = {v.q_cam_target.w(), v.q_cam_target.x(), v.q_cam_target.y(),
                                 v.q_cam_target.z()};
      jv["t_cam_target_m"] = {v.t_cam_target.x(), v.t_cam_target.y(), v.t_cam_target.z()};
    } else {
      jv["rejected_because"] = v.rejected_because;
    }
    views.push_back(jv);
  }
  // The covariance of the model's parameters in Kalibr's order (covariance_order).
  json cov = json::array();
  const Eigen::MatrixXd kalibr_cov = kalibr_covariance(res);
  for (Eigen::Index i = 0; i < kalibr_cov.rows(); ++i) {
    json row = json::array();
    for (Eigen::Index j = 0; j < kalibr_cov.cols(); ++j)
      row.push_back(res.covariance_ok ? finite_or_null(kalibr_cov(i, j)) : json(nullptr));
    cov.push_back(row);
  }
  json j = {
      {"camera_model", projection_model_name(res.camera.projection)},
      {"distortion_model", distortion_model_name(res.camera.distortion_model)},
      {"model", camera_model_name(res.camera.kind())},
      {"intrinsics",
       kalibr_intrinsics(res.camera.projection, res.camera.intrinsics, res.camera.projection_params)},
      {"distortion_coeffs", kalibr_distortion(res.camera.distortion_model, res.camera.distortion_coeffs)},
      {"resolution", {res.camera.width, res.camera.height}},
      {"intrinsics_sigma", sigma_vec(intrinsics_sigmas(res))},
      {"distortion_coeffs_sigma", sigma_vec(distortion_sigmas(res))},
      {"covariance", cov},
      {"covariance_order", kalibr_parameter_names(res.camera.kind())},
      {"model_choice", model_choice_json(r.model_choice)},
      {"reprojection_rms_px", res.rms_px},
      {"residual_sigma_px", res.residual_sigma_px},
      {"focal_well_determined", res.focal_well_determined},
      {"profile_check",
       {{"chi2", finite_or_null(res.profile_chi2)},
        {"sigma_stretch", res.profile_stretch},
        {"ambiguity", res.ambiguity.empty() ? json(nullptr) : json(res.ambiguity)}}},
      {"shutter", shutter_kind_name(res.camera.shutter.kind)},
      {"line_delay_s", res.camera.shutter.rolling() ? json(res.camera.shutter.line_delay_s) : json(nullptr)},
      {"line_delay_sigma_s", finite_or_null(r.line_delay_sigma_s)},
      {"readout_direction", readout_name(res.camera.shutter.readout)},
      {"stamp_row", stamp_row_name(res.camera.shutter.stamp_row)},
      {"shutter_choice", r.shutter_choice},
      {"coverage", res.coverage},
      {"coverage_grid",
       {{"cols", res.coverage_cols}, {"rows", res.coverage_rows}, {"counts", res.coverage_counts}}},
      {"frames", r.frames},
      {"frames_with_target", r.frames_with_target},
      {"frames_failed", r.frames_failed},
      {"views_total", res.views_total},
      {"views_used", res.views_used},
      {"views_rejected", views_rejected(r)},
      {"views_not_chosen", r.views_not_chosen},
      {"corners_used", res.points_used},
      {"corners_rejected", res.corners_rejected},
      {"residuals", residuals_json(res)},
      {"views", views},
      {"log", r.log_path},
      {"log_software_version", r.software_version},
      {"camera_stream", r.stream.name},
      {"target_yaml", target_to_yaml(r.target)},
      {"target_source", r.target_source},
      {"detections",
       {{"key", r.detection_key},
        {"reused", !r.detections_reused_from.empty()},
        {"reused_from", r.detections_reused_from},
        {"stored", !r.detections_stored_in.empty()},
        {"stored_in", r.detections_stored_in},
        {"threads", r.detection_threads},
        {"wall_s", r.detection_wall_s}}},
      {"solver", {{"iterations", res.iterations}, {"cpu_s", res.solve_cpu_s}}},
      {"warnings", r.warnings},
      {"software_version", kVersion},
  };
  return j;
}

}  // namespace

std::string camera_result_json(const CameraCalibrationReport& r) {
  json j = camera_json(r);
  j["self_check"] = split_check_json(r.self_check);
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

/// The self-check as comment lines of the camchain file (a key of its own would be counted as a
/// camera by Kalibr's reader, which takes every top-level key for one); empty when not run.
static std::string self_check_comment(const SplitCheck& check) {
  if (check.verdict == SplitCheck::Verdict::kNotRun) return "";
  std::string text = "# self-check: " + check.summary + "\n";
  for (const auto& [who, k] : check.scaled) {
    char line[160];
    std::snprintf(line, sizeof line, "# self-check: %s's sigmas scaled by %.2f\n", who.c_str(), k);
    text += line;
  }
  return text;
}

std::string camera_chain_yaml(const CameraChainReport& r, int min_shared_views) {
  YAML::Node root(YAML::NodeType::Map);
  for (std::size_t c = 0; c < r.cameras.size(); ++c) {
    const auto& cc = r.chain.cameras[c];
    YAML::Node cam = camera_node(r.cameras[c]);
    if (c > 0) cam["T_cn_cnm1"] = yaml_matrix_rows(cc.T_cn_cnm1.matrix());
    YAML::Node ov(YAML::NodeType::Sequence);
    for (int j : overlaps(cc, min_shared_views)) ov.push_back(j);
    ov.SetStyle(YAML::EmitterStyle::Flow);
    cam["cam_overlaps"] = ov;
    YAML::Node q = cam["imucal"];
    q["timeshift_cam_cam0"] = cc.timeshift_cam0_s;
    q["timeshift_cam_cam0_sigma"] = c == 0 ? YAML::Node(0.0) : number_or_null(cc.timeshift_sigma_s);
    q["timeshift_estimated"] = cc.timeshift_estimated;
    if (c > 0) {
      q["T_cn_cnm1_rotation_sigma_rad"] = flow3(cc.T_cn_cnm1_rotation_sigma_rad);
      q["T_cn_cnm1_translation_sigma_m"] = flow3(cc.T_cn_cnm1_translation_sigma_m);
      q["T_cn_cnm1_covariance"] = covariance_rows(cc.T_cn_cnm1_covariance);
      q["baseline_m"] = cc.baseline_m;
      q["baseline_sigma_m"] = number_or_null(cc.baseline_sigma_m);
      q["T_cam_cam0"] = yaml_matrix_rows(cc.T_cam_cam0.matrix());
      q["linked_to"] = "cam" + std::to_string(cc.linked_to);
    }
    YAML::Node shared(YAML::NodeType::Sequence);
    for (int n : cc.shared_views) shared.push_back(n);
    shared.SetStyle(YAML::EmitterStyle::Flow);
    q["shared_views"] = shared;
    q["views_stamped_with_cam0"] = cc.views_stamped_with_cam0;
    q["chain_rms_px"] = cc.rms_px;
    cam["imucal"] = q;
    root["cam" + std::to_string(c)] = cam;
  }
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << root;
  return "# Camera chain (imucal calibrate camera, " + std::to_string(r.cameras.size()) +
         " cameras in one solve); Kalibr camchain format (T_cn_cnm1, cam_overlaps), imucal's figures under\n"
         "# camN.imucal; t_cam0 = t_camN + timeshift_cam_cam0 (docs/camera-calibration.md)\n" +
         self_check_comment(r.self_check) + std::string(out.c_str()) + "\n";
}

std::string camera_chain_json(const CameraChainReport& r, int min_shared_views) {
  json cams = json::array();
  for (std::size_t c = 0; c < r.cameras.size(); ++c) {
    const auto& cc = r.chain.cameras[c];
    json j = camera_json(r.cameras[c]);
    j["name"] = "cam" + std::to_string(c);
    j["cam_overlaps"] = overlaps(cc, min_shared_views);
    j["shared_views"] = cc.shared_views;
    j["timeshift_cam_cam0_s"] = cc.timeshift_cam0_s;
    j["timeshift_cam_cam0_sigma_s"] = c == 0 ? json(0.0) : finite_or_null(cc.timeshift_sigma_s);
    j["timeshift_estimated"] = cc.timeshift_estimated;
    j["views_stamped_with_cam0"] = cc.views_stamped_with_cam0;
    j["chain_rms_px"] = finite_or_null(cc.rms_px);
    if (c > 0) {
      const Eigen::Matrix4d T = cc.T_cn_cnm1.matrix();
      json rows = json::array();
      for (int i = 0; i < 4; ++i) rows.push_back({T(i, 0), T(i, 1), T(i, 2), T(i, 3)});
      j["T_cn_cnm1"] = rows;
      const auto& rs = cc.T_cn_cnm1_rotation_sigma_rad;
      const auto& ts = cc.T_cn_cnm1_translation_sigma_m;
      j["T_cn_cnm1_rotation_sigma_rad"] = {finite_or_null(rs.x()), finite_or_null(rs.y()),
                                           finite_or_null(rs.z())};
      j["T_cn_cnm1_translation_sigma_m"] = {finite_or_null(ts.x()), finite_or_null(ts.y()),
                                            finite_or_null(ts.z())};
      j["baseline_m"] = cc.baseline_m;
      j["baseline_sigma_m"] = finite_or_null(cc.baseline_sigma_m);
      j["linked_to"] = "cam" + std::to_string(cc.linked_to);
    }
    cams.push_back(std::move(j));
  }
  const json out = {{"cameras", cams},
                    {"knot_spacing_s", r.chain.knot_spacing_s},
                    {"reprojection_rms_px", finite_or_null(r.chain.rms_px)},
                    {"solver", {{"iterations", r.chain.iterations}, {"cpu_s", r.chain.solve_cpu_s}}},
                    {"self_check", split_check_json(r.self_check)},
                    {"warnings", r.warnings},
                    {"software_version", kVersion}};
  return out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace imucal::app
