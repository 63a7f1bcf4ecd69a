// SPDX-License-Identifier: BSD-3-Clause
// The report of an Allan analysis (imucal allan --json): the noise figures per axis and the
// Allan deviation curves with the fitted lines.

#include <cmath>
#include <string>

#include "app/report/builders.hpp"

namespace imucal::app::report {
namespace {

/// The fitted lines of one axis over their fit ranges: white noise N / sqrt(tau), random walk
/// K sqrt(tau / 3) and the bias instability floor 0.664 B, as two-point segments (straight on
/// log-log axes). A range of one tau is widened to a factor of 3 either way to stay visible.
std::string fit_lines(const nlohmann::json& axis, int a) {
  const auto& lines = at(axis, "lines");
  auto range = [&](const char* key) {
    const auto& t = at(at(lines, key), "tau_s");
    double lo = t[0].get<double>(), hi = t[1].get<double>();
    if (!(hi > lo * 1.01)) lo /= 3.0, hi *= 3.0;
    return std::pair{lo, hi};
  };
  const double N = number(axis, "noise_density"), K = number(axis, "random_walk");
  const double B = number(axis, "bias_instability"), tb = number(at(lines, "bias_instability"), "tau_s");
  const auto [w0, w1] = range("white_noise");
  const auto [r0, r1] = range("random_walk");
  std::vector<std::vector<double>> rows = {
      {w0, N / std::sqrt(w0)},     {w1, N / std::sqrt(w1)},     {NAN, NAN},
      {r0, K * std::sqrt(r0 / 3)}, {r1, K * std::sqrt(r1 / 3)}, {NAN, NAN},
      {tb / 3, 0.664 * B},         {tb * 3, 0.664 * B}};
  return datablock("fit" + std::to_string(a), rows);
}

Figure adev_figure(const nlohmann::json& sensor, bool gyro) {
  Figure f;
  f.id = gyro ? "allan-gyro" : "allan-accel";
  f.title = gyro ? "Gyroscope Allan deviation" : "Accelerometer Allan deviation";
  const std::string unit = at(sensor, "unit").get<std::string>();
  f.caption =
      "Overlapping Allan deviation per axis (points) and the fitted lines over the averaging times "
      "they were fitted on (dashed): white noise N/sqrt(tau), random walk K*sqrt(tau/3), bias "
      "instability 0.664*B. Values in " +
      unit + ".";
  f.height_px = 520;
  const auto& curve = at(sensor, "curve");
  const auto& tau = at(curve, "tau_s");
  std::vector<std::vector<double>> rows;
  for (std::size_t i = 0; i < tau.size(); ++i) {
    rows.push_back({tau[i].get<double>(), at(curve, "adev_x")[i].get<double>(),
                    at(curve, "adev_y")[i].get<double>(), at(curve, "adev_z")[i].get<double>()});
  }
  std::string s = datablock("adev", rows);
  const auto& axes = at(sensor, "axes");
  for (int a = 0; a < 3; ++a) s += fit_lines(axes[a], a);
  s += "set logscale xy\nset grid xtics ytics mxtics mytics lc rgb '#e0e0e0'\nset format x '10^{%L}'\n"
       "set format y '10^{%L}'\nset xlabel 'averaging time tau (s)'\nset ylabel " +
       gp_quote("Allan deviation (" + unit + ")") + "\nset key outside right top\nplot ";
  for (int a = 0; a < 3; ++a) {
    const std::string c = std::string(" lc rgb '") + kAxisColour[a] + "'";
    s += std::string(a ? ", " : "") + "$adev using 1:" + std::to_string(a + 2) +
         " with linespoints pt 7 ps 0.6" + c + " title '" + "xyz"[a] + "', $fit" + std::to_string(a) +
         " using 1:2 with lines dashtype 2 lw 2" + c + " title '" + "xyz"[a] + " fit'";
  }
  f.script = s + "\n";
  return f;
}

std::string bound(const nlohmann::json& axis, const char* value, const char* flag) {
  return (axis.value(flag, false) ? "&le; " : "") + num(number(axis, value), 4);
}

std::string figures_table(const nlohmann::json& sensor, const std::string& unit, const std::string& rw_unit) {
  Table t{{"axis", "noise density (" + unit + "/&radic;Hz)", "random walk (" + rw_unit + "/&radic;Hz)",
           "bias instability (" + unit + ")", "at tau (s)"},
          {}};
  for (const auto& a : at(sensor, "axes")) {
    t.rows.push_back({escape(at(a, "axis").get<std::string>()), num(number(a, "noise_density"), 4),
                      bound(a, "random_walk", "random_walk_is_upper_bound"),
                      bound(a, "bias_instability", "bias_instability_is_upper_bound"),
                      num(number(a, "bias_instability_tau_s"), 4)});
  }
  return t.to_html();
}

}  // namespace

Result<Document> allan_document(const nlohmann::json& r, BuildContext& ctx) {
  Document doc;
  doc.title = "IMU noise (Allan deviation)";
  doc.subtitle = "Report of " + ctx.result_path;
  if (r.value("random_walk_is_upper_bound", false)) {
    doc.warnings.push_back(
        "the recording is too short to show the random-walk slope: the random walks are upper "
        "bounds from the longest averaging time (record for hours to measure them)");
  }
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress, ctx.log_name);
    if (!session.ok()) return session.error();
    doc.sections.push_back(std::move(*session));
  }
  const auto& k = at(r, "kalibr");
  Table overview{{"", ""}, {}};
  overview.rows.push_back({"log", escape(r.value("log", std::string("-"))) + " (" +
                                      escape(r.value("stream", std::string("-"))) + ")"});
  overview.rows.push_back(
      {"analysed run", num(number(r, "duration_s"), 6) + " s at " + num(number(r, "rate_hz"), 6) + " Hz"});
  overview.rows.push_back(
      {"Kalibr accelerometer", "noise density " + num(number(k, "accelerometer_noise_density"), 4) +
                                   ", random walk " + num(number(k, "accelerometer_random_walk"), 4)});
  overview.rows.push_back(
      {"Kalibr gyroscope", "noise density " + num(number(k, "gyroscope_noise_density"), 4) +
                               ", random walk " + num(number(k, "gyroscope_random_walk"), 4)});
  doc.sections.push_back(
      {"Result", overview.to_html() + "<p class=\"note\">Kalibr's figures are the worst axis.</p>\n", {}});
  const auto& acc = at(r, "accelerometer");
  const auto& gyr = at(r, "gyroscope");
  doc.sections.push_back(
      {"Accelerometer", figures_table(acc, "m/s<sup>2</sup>", "m/s<sup>3</sup>"), {adev_figure(acc, false)}});
  doc.sections.push_back(
      {"Gyroscope", figures_table(gyr, "rad/s", "rad/s<sup>2</sup>"), {adev_figure(gyr, true)}});
  return doc;
}

}  // namespace imucal::app::report
