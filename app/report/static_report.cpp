// SPDX-License-Identifier: BSD-3-Clause
// The report of a static calibration (imucal calibrate static --json): parameters with their
// sigmas, quality before and after, the threshold search and, with the log, the signals, the
// per-pose figures and the pose directions.

#include <cmath>
#include <string>

#include "app/report/builders.hpp"
#include "app/report/static_log.hpp"
#include "core/imu_calibration.hpp"

namespace imucal::app::report {
namespace {

constexpr double kDeg = 180.0 / M_PI;

std::string code(const std::string& s) { return "<code>" + escape(s) + "</code>"; }

Section overview_section(const nlohmann::json& r) {
  const std::string units = at(r, "input_units").get<std::string>();
  Table t{{"", ""}, {}};
  t.rows.push_back({"method", escape(at(r, "method").get<std::string>())});
  t.rows.push_back({"stream", escape(at(r, "stream").get<std::string>()) + " (" + escape(units) + " input)"});
  t.rows.push_back({"convention", code(at(r, "convention").get<std::string>())});
  t.rows.push_back({"gravity", num(number(r, "gravity"), 8) + " m/s<sup>2</sup> (" +
                                   escape(r.value("gravity_source", std::string("not recorded"))) + ")"});
  t.rows.push_back({"still start", num(number(r, "init_still_s"), 4) + " s (" +
                                       escape(r.value("init_still_source", std::string("-"))) + ")"});
  t.rows.push_back({"threshold multiplier", num(number(r, "threshold_multiplier"), 3)});
  t.rows.push_back({"static intervals",
                    std::to_string(at(r, "static_intervals").size()) + ", " +
                        std::to_string(at(r, "distinct_attitudes").get<int>()) + " distinct attitudes, " +
                        std::to_string(at(r, "gyro_transfers").get<int>()) + " gyro transfers"});
  t.rows.push_back({"gyro bias", escape(at(at(r, "gyro"), "bias_source").get<std::string>())});
  // What the recording determined (results of older versions lack these keys: the full model).
  if (r.contains("accel_model")) {
    const auto& m = r["accel_model"];
    t.rows.push_back({"accelerometer model", escape(m.value("form", std::string("full"))) + ": " +
                                                 escape(m.value("reason", std::string()))});
  }
  const auto held = [&](const char* key) {
    std::string out;
    if (r.contains(key))
      for (const auto& n : r[key]) out += (out.empty() ? "" : ", ") + n.get<std::string>();
    return out.empty() ? std::string("none") : out;
  };
  if (r.contains("accel_fixed") || r.contains("gyro_fixed")) {
    t.rows.push_back({"not determined, held at nominal", "accelerometer: " + escape(held("accel_fixed")) +
                                                             "; gyroscope: " + escape(held("gyro_fixed"))});
  }
  if (r.contains("log_software_version"))
    t.rows.push_back({"recorded by", escape(r["log_software_version"].get<std::string>())});
  return {"Result", t.to_html(), {}};
}

/// One triad: scale and bias per axis, the misalignment matrix, all with sigmas.
std::string triad_html(const nlohmann::json& j, const std::string& scale_unit, const std::string& bias_unit) {
  const Eigen::Vector3d s = vec3(at(j, "scale")), b = vec3(at(j, "bias"));
  const auto& sig = at(j, "sigma");
  const Eigen::Vector3d ss = vec3(at(sig, "scale")), sb = vec3(at(sig, "bias"));
  const Eigen::Matrix3d T = mat3(at(j, "misalignment")), sT = mat3(at(sig, "misalignment"));
  Table axes{{"axis", "scale (" + scale_unit + ")", "bias (" + bias_unit + ")"}, {}};
  for (int a = 0; a < 3; ++a)
    axes.rows.push_back({std::string(1, "xyz"[a]), with_sigma(s[a], ss[a]), with_sigma(b[a], sb[a])});
  Table mis{{"misalignment", "x", "y", "z"}, {}};
  for (int row = 0; row < 3; ++row) {
    mis.rows.push_back({std::string(1, "xyz"[row])});
    for (int c = 0; c < 3; ++c) mis.rows.back().push_back(with_sigma(T(row, c), sT(row, c)));
  }
  return axes.to_html() + mis.to_html();
}

Section parameters_section(const nlohmann::json& r) {
  const bool raw = at(r, "input_units").get<std::string>() == "raw";
  const std::string in = raw ? "count" : "";
  Section sec{"Parameters", "", {}};
  sec.html =
      "<p class=\"note\">Every value with its standard deviation from the solver covariance, scaled by "
      "the observed residual variance; entries fixed by the form of the model are marked \"fixed\", those "
      "the recording did not determine are held at nominal and marked \"&sigma; not "
      "determined\".</p>\n<h3>Accelerometer</h3>\n" +
      triad_html(at(r, "accel"), raw ? "m/s<sup>2</sup> per count" : "", raw ? "counts" : "m/s<sup>2</sup>") +
      "<p>Residual RMS " + num(number(at(r, "accel"), "residual_rms_m2ps4"), 4) +
      " m<sup>2</sup>/s<sup>4</sup>.</p>\n<h3>Gyroscope</h3>\n" +
      triad_html(at(r, "gyro"), raw ? "rad/s per count" : "", raw ? "counts" : "rad/s") + "<p>Residual RMS " +
      num(number(at(r, "gyro"), "residual_rms"), 4) + ".</p>\n";
  const auto& gs = at(r, "gsens");
  const std::string mode = at(gs, "mode").get<std::string>();
  sec.html += "<h3>Gyroscope g-sensitivity (" + escape(mode) + ")</h3>\n";
  if (mode == "off") {
    sec.html += "<p>Neglected (Tedaldi's model, G = 0)";
    if (gs.contains("wald_statistic") && gs["wald_statistic"].is_number()) {
      sec.html += ": not distinguishable from zero on this recording (Wald statistic " +
                  num(gs["wald_statistic"].get<double>(), 3) +
                  " of its 9 entries, below the chi-square 95 % point " + num(kGsensWaldLimit, 4) + ")";
    }
    sec.html += ".</p>\n";
    return sec;
  }
  // deg/s per g reads better than rad/s per m/s^2 for MEMS gyros.
  const double k = kDeg * number(r, "gravity");
  const Eigen::Matrix3d G = mat3(at(gs, "G")), sG = mat3(at(gs, "G_sigma"));
  Table t{{"G (deg/s per g)", "x", "y", "z"}, {}};
  for (int row = 0; row < 3; ++row) {
    t.rows.push_back({std::string(1, "xyz"[row])});
    for (int c = 0; c < 3; ++c) t.rows.back().push_back(with_sigma(G(row, c) * k, sG(row, c) * k));
  }
  sec.html += t.to_html() + "<p class=\"note\">w = A_g (w_raw - b_g) - G a; the Earth rate removed: " +
              num(number(gs, "earth_rate_removed") * k, 4) + " deg/s per g.</p>\n";
  return sec;
}

std::string figures_row(const nlohmann::json& f, bool angle) {
  if (f.is_null()) return "<td>-</td><td>-</td>";
  if (angle)
    return "<td>" + num(number(f, "mean_rad") * kDeg, 4) + "</td><td>" + num(number(f, "max_rad") * kDeg, 4) +
           "</td>";
  return "<td>" + num(number(f, "mean_mps2"), 4) + "</td><td>" + num(number(f, "max_mps2"), 4) + "</td>";
}

std::string quality_table(const nlohmann::json& r) {
  const auto& q = at(r, "quality");
  const auto& acc = at(q, "accel_gravity_magnitude");
  const auto& gyr = at(q, "gyro_gravity_direction");
  std::string out =
      "<table>\n<thead><tr><th>figure</th><th colspan=\"2\">before (nominal)</th><th "
      "colspan=\"2\">after</th></tr>"
      "<tr><th></th><th>mean</th><th>max</th><th>mean</th><th>max</th></tr></thead>\n<tbody>\n";
  out += "<tr><td>gravity magnitude error (m/s<sup>2</sup>)</td>" + figures_row(at(acc, "before"), false) +
         figures_row(at(acc, "after"), false) + "</tr>\n";
  out += "<tr><td>tilt it causes (deg)</td>" + figures_row(at(acc, "before"), true) +
         figures_row(at(acc, "after"), true) + "</tr>\n";
  out += "<tr><td>gyro gravity-direction error (deg)</td>" + figures_row(at(gyr, "before"), true) +
         figures_row(at(gyr, "after"), true) + "</tr>\n";
  return out + "</tbody>\n</table>\n";
}

Figure threshold_figure(const nlohmann::json& r) {
  Figure f;
  f.id = "static-threshold-search";
  f.title = "Static detector threshold search";
  f.caption =
      "Tedaldi's Algorithm 1: the accelerometer residual and the number of static intervals for each "
      "threshold multiplier tried; the calibration keeps multiplier " +
      num(number(r, "threshold_multiplier"), 3) + ".";
  f.height_px = 360;
  std::vector<std::vector<double>> rows;
  for (const auto& c : at(r, "threshold_search"))
    rows.push_back({number(c, "multiplier"), number(c, "accel_rms_m2ps4"), number(c, "intervals")});
  f.script = datablock("t", rows) +
             "set grid\nset xlabel 'threshold multiplier'\n"
             "set ylabel 'accelerometer residual RMS (m^2/s^4)'\nset y2label 'static intervals'\nset ytics "
             "nomirror\n"
             "set y2tics\nset key outside right top\nset arrow from " +
             num(number(r, "threshold_multiplier"), 6) + ", graph 0 to " +
             num(number(r, "threshold_multiplier"), 6) +
             ", graph 1 nohead dashtype 2 lc rgb '#888888'\n"
             "plot $t using 1:2 with linespoints pt 7 lc rgb '#0072b2' title 'residual', "
             "$t using 1:3 axes x1y2 with linespoints pt 5 lc rgb '#d55e00' title 'intervals'\n";
  return f;
}

double mean_of(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? std::nan("") : s / static_cast<double>(v.size());
}

/// The per-pose figures are recomputed here (the result JSON has their means only): their means,
/// to compare with the table's.
std::string recomputed_note(const StaticLogData& d) {
  std::string out =
      "<p class=\"note\">Recomputed from the log for the figures below (means): gravity magnitude "
      "error " +
      num(mean_of(d.magnitude_after_mps2), 4) + " m/s<sup>2</sup> after";
  if (d.before_available) out += ", " + num(mean_of(d.magnitude_before_mps2), 4) + " before";
  out += "; gravity-direction error " + num(mean_of(d.direction_after_rad) * kDeg, 4) + " deg after";
  if (d.before_available) out += ", " + num(mean_of(d.direction_before_rad) * kDeg, 4) + " before";
  return out + ". The gyro's slow bias drift, which the calibration also removes, is not applied here.</p>\n";
}

}  // namespace

Result<Document> static_document(const nlohmann::json& r, BuildContext& ctx) {
  Document doc;
  doc.title = "Static IMU calibration";
  doc.subtitle =
      "Report of " + ctx.result_path + (ctx.log_path.empty() ? "" : " with the log " + ctx.shown_log());
  for (const auto& w : at(r, "warnings")) doc.warnings.push_back(w.get<std::string>());
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress, ctx.log_name);
    if (!session.ok()) return session.error();
    doc.sections.push_back(std::move(*session));
  }
  doc.sections.push_back(overview_section(r));
  doc.sections.push_back(parameters_section(r));
  Section quality{"Quality", quality_table(r), {}};
  if (ctx.log_path.empty()) {
    ctx.notes.push_back("no --log: the signals, the per-pose errors and the pose directions are left out");
    quality.html +=
        "<p class=\"note\">The per-pose figures, the signals and the pose directions need the log "
        "(<code>imucal report RESULT --log LOG</code>).</p>\n";
    quality.figures.push_back(threshold_figure(r));
    doc.sections.push_back(std::move(quality));
    return doc;
  }
  auto data = static_log_data(r, ctx.log_path);
  if (!data.ok()) return data.error();
  if (!data->damage_warning.empty()) doc.warnings.push_back(data->damage_warning);
  quality.html += recomputed_note(*data);
  quality.figures = {magnitude_figure(*data), direction_figure(*data), threshold_figure(r)};
  doc.sections.push_back(std::move(quality));
  doc.sections.push_back({"Static intervals",
                          "<p>" + std::to_string(data->poses.size()) + " static intervals of the stream's " +
                              std::to_string(data->samples.size()) + " samples.</p>\n",
                          {signal_figure(*data, false), signal_figure(*data, true), sphere_figure(*data)}});
  return doc;
}

}  // namespace imucal::app::report
