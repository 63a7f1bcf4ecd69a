// SPDX-License-Identifier: BSD-3-Clause
// The report of a camera intrinsics calibration (imucal calibrate camera --json): intrinsics and
// distortion with their sigmas, the target's coverage of the image and the reprojection error of
// each view. The JSON has the coverage grid and per-view RMS, not per-corner residuals, so there
// is no reprojection scatter.

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "app/report/builders.hpp"
#include "core/camera_model.hpp"
#include "core/yaml_json.hpp"

namespace imucal::app::report {
namespace {

/// " of cam1" for the figure id suffix "-cam1"; nothing for a single camera's report.
std::string title_of(const std::string& suffix) { return suffix.empty() ? "" : " of " + suffix.substr(1); }

std::string parameters_html(const nlohmann::json& r) {
  const auto& k = at(r, "intrinsics");
  const auto& ks = at(r, "intrinsics_sigma");
  const auto& d = at(r, "distortion_coeffs");
  const auto& ds = at(r, "distortion_coeffs_sigma");
  auto value = [](const nlohmann::json& v) { return v.is_null() ? std::nan("") : v.get<double>(); };
  // The parameters in Kalibr's order, named by covariance_order (omni xi; eucm alpha beta; ds xi
  // alpha; then fu fv pu pv; then the distortion's coefficients).
  std::vector<std::string> names;
  if (r.contains("covariance_order")) {
    for (const auto& n : r["covariance_order"]) names.push_back(n.get<std::string>());
  }
  auto name_of = [&](std::size_t i, const std::string& fallback) {
    return i < names.size() ? names[i] : fallback;
  };
  Table t{{"parameter", "value"}, {}};
  const std::size_t extra = k.size() > 4 ? k.size() - 4 : 0;
  const char* pinhole[] = {"fu (px)", "fv (px)", "pu (px)", "pv (px)"};
  for (std::size_t i = 0; i < k.size(); ++i) {
    const std::string label =
        i < extra ? name_of(i, "e" + std::to_string(i)) : std::string(pinhole[i - extra]);
    t.rows.push_back({label, with_sigma(value(k[i]), i < ks.size() ? value(ks[i]) : std::nan(""))});
  }
  for (std::size_t i = 0; i < d.size(); ++i)
    t.rows.push_back({name_of(k.size() + i, "k" + std::to_string(i + 1)),
                      with_sigma(value(d[i]), i < ds.size() ? value(ds[i]) : std::nan(""))});
  const auto& res = at(r, "resolution");
  Table q{{"", ""}, {}};
  q.rows.push_back(
      {"model",
       escape(at(r, "camera_model").get<std::string>() + "-" + at(r, "distortion_model").get<std::string>()) +
           ", " + std::to_string(res[0].get<int>()) + " x " + std::to_string(res[1].get<int>())});
  q.rows.push_back({"reprojection RMS", num(number(r, "reprojection_rms_px"), 4) + " px"});
  const int not_chosen = r.value("views_not_chosen", 0);
  q.rows.push_back({"views", std::to_string(at(r, "views_used").get<int>()) + " used of " +
                                 std::to_string(at(r, "views_total").get<int>()) +
                                 (not_chosen > 0 ? " (spread evenly; " + std::to_string(not_chosen) +
                                                       " more views with the target not chosen)"
                                                 : std::string())});
  q.rows.push_back({"coverage", num(number(r, "coverage") * 100.0, 3) + " % of the image grid"});
  q.rows.push_back({"focal length well determined", r.value("focal_well_determined", false) ? "yes" : "no"});
  return q.to_html() + t.to_html() + "<p class=\"note\">Distortion coefficients are unitless.</p>\n";
}

Figure coverage_figure(const nlohmann::json& r, const std::string& suffix = "") {
  const auto& g = at(r, "coverage_grid");
  const int cols = at(g, "cols").get<int>(), rows = at(g, "rows").get<int>();
  const auto& counts = at(g, "counts");
  const auto& res = at(r, "resolution");
  const double w = res[0].get<double>(), h = res[1].get<double>();
  Figure f;
  f.id = "camera-coverage" + suffix;
  f.title = "Target coverage of the image" + title_of(suffix);
  f.caption = "Target corners of the used views in each cell of a " + std::to_string(cols) + " x " +
              std::to_string(rows) + " grid over the image (pixel coordinates, origin top left).";
  f.height_px = static_cast<int>(960.0 * h / w) + 60;
  std::vector<std::vector<double>> data;
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) {
      const std::size_t i = static_cast<std::size_t>(y * cols + x);
      data.push_back(
          {(x + 0.5) * w / cols, (y + 0.5) * h / rows, i < counts.size() ? counts[i].get<double>() : 0.0});
    }
  }
  f.script = datablock("c", data) + "set xrange [0:" + num(w, 8) + "]\nset yrange [" + num(h, 8) +
             ":0]\nset size ratio -1\nset xlabel 'u (px)'\nset ylabel 'v (px)'\nset cblabel 'corners'\n"
             "set palette defined (0 '#ffffff', 1 '#9ecae1', 2 '#08519c')\n"
             "plot $c using 1:2:(" +
             num(w / cols / 2, 8) + "):(" + num(h / rows / 2, 8) +
             "):3 with boxxyerror fillstyle solid 1.0 noborder lc palette notitle\n";
  return f;
}

Figure views_figure(const nlohmann::json& r, const std::string& suffix = "") {
  Figure f;
  f.id = "camera-view-rms" + suffix;
  f.title = "Reprojection error per view" + title_of(suffix);
  f.caption =
      "RMS reprojection error of each view with the target, in frame order: used views and rejected "
      "ones (as an outlier or for too few corners).";
  f.height_px = 360;
  std::vector<std::vector<double>> used, rejected;
  int i = 0;
  for (const auto& v : at(r, "views")) {
    const double rms = v.value("rms_px", std::nan(""));
    (v.value("used", false) ? used : rejected).push_back({static_cast<double>(++i), rms});
  }
  if (used.empty()) used.push_back({0.0, std::nan("")});
  if (rejected.empty()) rejected.push_back({0.0, std::nan("")});
  f.script =
      datablock("u", used) + datablock("x", rejected) +
      "set grid\nset xlabel 'view'\nset ylabel 'RMS reprojection error (px)'\nset key outside right top\n"
      "set yrange [0:*]\nplot $u using 1:2 with points pt 7 ps 0.5 lc rgb '#0072b2' title 'used', "
      "$x using 1:2 with points pt 2 lc rgb '#d55e00' title 'rejected'\n";
  return f;
}

/// Each used view's corner residuals: the corners used and those the corner test rejected.
Figure camera_reprojection_figure(const nlohmann::json& r) {
  if (!r.contains("residuals")) return {};
  const auto& res = r["residuals"];
  const auto px = at(res, "px").get<std::vector<double>>();
  const auto rejected = at(res, "rejected").get<std::vector<int>>();
  ResidualSeries used{"used", {}, 0.0, kAxisColour[0]}, dropped{"rejected", {}, 0.0, kAxisColour[1]};
  for (std::size_t i = 0; 2 * i + 1 < px.size(); ++i) {
    auto& to = i < rejected.size() && rejected[i] ? dropped : used;
    to.px.push_back(px[2 * i]);
    to.px.push_back(px[2 * i + 1]);
  }
  return reprojection_figure("camera-reprojection", {used, dropped},
                             "The corners of the used views at the solution; " +
                                 std::to_string(px.size() / 2) + " of " +
                                 std::to_string(res.value("of_corners", 0)) + " stored;");
}

constexpr double kDeg = 180.0 / M_PI;

double or_nan(const nlohmann::json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : std::nan("");
}

/// Each camera after cam0 against the camera it is linked to (T_cn_cnm1), its baseline and its
/// time offset to cam0, all with their sigmas.
std::string chain_html(const nlohmann::json& cams) {
  Table t{{"camera", "relative to", "translation (mm)", "rotation angle (deg)", "baseline (mm)",
           "time offset to cam0 (ms)", "chain RMS (px)"},
          {}};
  for (const auto& c : cams) {
    const std::string name = escape(at(c, "name").get<std::string>());
    const double dt = or_nan(c, "timeshift_cam_cam0_s") * 1e3;
    const bool estimated = c.value("timeshift_estimated", false);
    const std::string offset =
        estimated ? with_sigma(dt, or_nan(c, "timeshift_cam_cam0_sigma_s") * 1e3) : num(dt) + " (held)";
    if (!c.contains("T_cn_cnm1")) {
      t.rows.push_back(
          {name, "(reference)", "-", "-", "-", "0 (reference)", num(or_nan(c, "chain_rms_px"), 4)});
      continue;
    }
    Eigen::Matrix4d T;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) T(i, j) = at(c, "T_cn_cnm1")[i][j].get<double>();
    const Eigen::Vector3d ts = c.contains("T_cn_cnm1_translation_sigma_m")
                                   ? vec3(c["T_cn_cnm1_translation_sigma_m"])
                                   : Eigen::Vector3d::Constant(std::nan(""));
    const Eigen::Vector3d rs = c.contains("T_cn_cnm1_rotation_sigma_rad")
                                   ? vec3(c["T_cn_cnm1_rotation_sigma_rad"])
                                   : Eigen::Vector3d::Constant(std::nan(""));
    std::string tr, rot;
    for (int a = 0; a < 3; ++a)
      tr += std::string(a ? "<br>" : "") + "xyz"[a] + ": " + with_sigma(1e3 * T(a, 3), 1e3 * ts[a]);
    const double angle = std::acos(std::clamp((T.topLeftCorner<3, 3>().trace() - 1.0) / 2.0, -1.0, 1.0));
    rot = num(angle * kDeg, 5) + "; sigma";
    for (int a = 0; a < 3; ++a) rot += std::string(" ") + "xyz"[a] + " " + num(rs[a] * kDeg, 2);
    t.rows.push_back({name, escape(c.value("linked_to", std::string("cam0"))), tr, rot,
                      with_sigma(1e3 * or_nan(c, "baseline_m"), 1e3 * or_nan(c, "baseline_sigma_m")), offset,
                      num(or_nan(c, "chain_rms_px"), 4)});
  }
  return t.to_html() +
         "<p class=\"note\">T_cn_cnm1 maps a point from the camera before to this camera (Kalibr's "
         "camchain). The time offset is added to the camera's stamps to give cam0's time; held: the "
         "cameras were taken as triggered together.</p>\n";
}

/// The views each pair of cameras shares (the chain is built through them).
std::string covisibility_html(const nlohmann::json& cams) {
  std::vector<std::string> head{"views shared"};
  for (const auto& c : cams) head.push_back(escape(at(c, "name").get<std::string>()));
  Table t{head, {}};
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const auto& c = cams[i];
    std::vector<std::string> row{escape(at(c, "name").get<std::string>())};
    const auto shared = c.contains("shared_views") ? c["shared_views"] : nlohmann::json::array();
    for (std::size_t j = 0; j < cams.size(); ++j)
      row.push_back(j == i || j >= shared.size() ? "-" : std::to_string(shared[j].get<int>()));
    t.rows.push_back(std::move(row));
  }
  return t.to_html();
}

}  // namespace

nlohmann::json camera_chain_from_yaml(const YAML::Node& y) {
  nlohmann::json cams = nlohmann::json::array(), warnings = nlohmann::json::array();
  for (int c = 0;; ++c) {
    const std::string name = "cam" + std::to_string(c);
    const YAML::Node cam = y[name];
    if (!cam) break;
    nlohmann::json j = yaml_to_json(cam);
    nlohmann::json q = j.contains("imucal") ? j["imucal"] : nlohmann::json::object();
    j.erase("imucal");
    for (auto it = q.begin(); it != q.end(); ++it) j[it.key()] = it.value();
    j["name"] = name;
    // The figures the YAML keeps under other names (it keeps no views).
    if (j.contains("timeshift_cam_cam0")) j["timeshift_cam_cam0_s"] = j["timeshift_cam_cam0"];
    if (j.contains("timeshift_cam_cam0_sigma"))
      j["timeshift_cam_cam0_sigma_s"] = j["timeshift_cam_cam0_sigma"];
    j["views_total"] = j.value("views_used", 0) + j.value("views_rejected", 0);
    // Its coverage_grid is the grid's size only, without the counts the figure draws.
    j.erase("coverage_grid");
    const auto projection = parse_projection_name(j.value("camera_model", std::string()));
    const auto distortion = parse_distortion_name(j.value("distortion_model", std::string()));
    if (projection && distortion) j["covariance_order"] = kalibr_parameter_names({*projection, *distortion});
    if (j.contains("warnings"))
      for (const auto& w : j["warnings"])
        if (std::find(warnings.begin(), warnings.end(), w) == warnings.end()) warnings.push_back(w);
    cams.push_back(std::move(j));
  }
  return {{"cameras", cams}, {"warnings", warnings}, {"from_camchain_yaml", true}};
}

Result<Document> camera_chain_document(const nlohmann::json& r, BuildContext& ctx) {
  const auto& cams = at(r, "cameras");
  Document doc;
  doc.title = cams.size() > 1 ? "Camera chain calibration" : "Camera intrinsics calibration";
  doc.subtitle = "Report of " + ctx.result_path + " (" + std::to_string(cams.size()) + " camera" +
                 (cams.size() == 1 ? ")" : "s)");
  for (const auto& w : at(r, "warnings")) doc.warnings.push_back(w.get<std::string>());
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress, ctx.log_name);
    if (!session.ok()) return session.error();
    doc.sections.push_back(std::move(*session));
  }
  const bool from_yaml = r.value("from_camchain_yaml", false);
  if (from_yaml)
    ctx.notes.push_back(
        "drawn from the camchain YAML, which keeps each camera's figures but not its views: for the "
        "coverage and per-view figures and the self-check, run calibrate camera LOG --json > camera.json "
        "and give camera.json");
  if (cams.size() > 1)
    doc.sections.push_back(
        {"Chain",
         chain_html(cams) + "<h3>Views shared by each pair of cameras</h3>\n" + covisibility_html(cams),
         {}});
  for (const auto& c : cams) {
    const std::string name = at(c, "name").get<std::string>();
    Section s{escape(name) + " (stream " + escape(c.value("camera_stream", std::string("-"))) + ")",
              parameters_html(c),
              {}};
    if (c.contains("views") && c.contains("coverage_grid")) {
      s.figures = {coverage_figure(c, "-" + name), views_figure(c, "-" + name)};
    } else {
      s.html +=
          "<p class=\"note\">The camchain YAML keeps the figures of this camera, not its views: "
          "the coverage and per-view figures need the JSON result (calibrate camera LOG --json).</p>\n";
    }
    doc.sections.push_back(std::move(s));
  }
  if (auto sc = self_check_section(r); !sc.title.empty()) doc.sections.push_back(std::move(sc));
  return doc;
}

Result<Document> camera_document(const nlohmann::json& r, BuildContext& ctx) {
  Document doc;
  doc.title = "Camera intrinsics calibration";
  doc.subtitle =
      "Report of " + ctx.result_path + " (camera stream " + r.value("camera_stream", std::string("-")) + ")";
  for (const auto& w : at(r, "warnings")) doc.warnings.push_back(w.get<std::string>());
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress, ctx.log_name);
    if (!session.ok()) return session.error();
    doc.sections.push_back(std::move(*session));
  }
  doc.sections.push_back({"Parameters", parameters_html(r), {}});
  Section views{"Views", "", {coverage_figure(r), views_figure(r)}};
  if (Figure e = camera_reprojection_figure(r); !e.id.empty()) {
    views.figures.push_back(std::move(e));
  } else {
    views.html =
        "<p class=\"note\">This result holds the RMS of each view, not each corner's residual (it was "
        "written before they were stored): there is no scatter of them.</p>\n";
  }
  doc.sections.push_back(std::move(views));
  if (auto sc = self_check_section(r); !sc.title.empty()) doc.sections.push_back(std::move(sc));
  return doc;
}

}  // namespace imucal::app::report
