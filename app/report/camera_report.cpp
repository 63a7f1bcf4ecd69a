// The report of a camera intrinsics calibration (imucal calibrate camera --json): intrinsics and
// distortion with their sigmas, the target's coverage of the image and the reprojection error of
// each view. The JSON has the coverage grid and per-view RMS, not per-corner residuals, so there
// is no reprojection scatter.

#include <string>
#include <vector>

#include "app/report/builders.hpp"

namespace imucal::app::report {
namespace {

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
  q.rows.push_back({"views", std::to_string(at(r, "views_used").get<int>()) + " used of " +
                                 std::to_string(at(r, "views_total").get<int>())});
  q.rows.push_back({"coverage", num(number(r, "coverage") * 100.0, 3) + " % of the image grid"});
  q.rows.push_back({"focal length well determined", r.value("focal_well_determined", false) ? "yes" : "no"});
  return q.to_html() + t.to_html() + "<p class=\"note\">Distortion coefficients are unitless.</p>\n";
}

Figure coverage_figure(const nlohmann::json& r) {
  const auto& g = at(r, "coverage_grid");
  const int cols = at(g, "cols").get<int>(), rows = at(g, "rows").get<int>();
  const auto& counts = at(g, "counts");
  const auto& res = at(r, "resolution");
  const double w = res[0].get<double>(), h = res[1].get<double>();
  Figure f;
  f.id = "camera-coverage";
  f.title = "Target coverage of the image";
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

Figure views_figure(const nlohmann::json& r) {
  Figure f;
  f.id = "camera-view-rms";
  f.title = "Reprojection error per view";
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

}  // namespace

Result<Document> camera_document(const nlohmann::json& r, BuildContext& ctx) {
  Document doc;
  doc.title = "Camera intrinsics calibration";
  doc.subtitle =
      "Report of " + ctx.result_path + " (camera stream " + r.value("camera_stream", std::string("-")) + ")";
  for (const auto& w : at(r, "warnings")) doc.warnings.push_back(w.get<std::string>());
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress);
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
