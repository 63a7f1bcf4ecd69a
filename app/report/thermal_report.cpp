// SPDX-License-Identifier: BSD-3-Clause
// The report of a thermal calibration (imucal calibrate thermal -o THERMAL.yaml): the model per
// axis, and per sensor the bias against die temperature before compensation (the bin means
// about their value at the reference temperature) with the fitted curve and its 2-sigma band,
// and what is left after compensation.

#include <cmath>
#include <string>
#include <vector>

#include "app/report/builders.hpp"

namespace imucal::app::report {
namespace {

constexpr int kCurvePoints = 101;
constexpr double kPi = 3.14159265358979323846;

/// How a sensor is shown: its display unit and the factor from its SI unit.
struct SensorView {
  const char* key;   // "gyro" or "accel"
  const char* name;  // for titles
  const char* unit;  // display unit
  double per_si;     // display units per SI unit
  int bin_column;    // first column of the sensor in bin_means.rows
};
constexpr SensorView kGyro{"gyro", "Gyroscope", "deg/s", 180.0 / kPi, 2};
constexpr SensorView kAccel{"accel", "Accelerometer", "mg", 1000.0 / 9.80665, 5};

/// One axis's fit as the file holds it.
struct AxisFit {
  bool determined = false;
  std::string reason;
  std::vector<double> c;                 // c_0..c_p, SI per K^j
  std::vector<std::vector<double>> cov;  // of c

  /// f(T) - f(T_ref) and its 1-sigma (the gradient [0, dT, dT^2, ...] through the covariance).
  double change(double dT) const {
    double sum = 0.0, p = 1.0;
    for (std::size_t j = 1; j < c.size(); ++j) sum += c[j] * (p *= dT);
    return sum;
  }
  double change_sigma(double dT) const {
    std::vector<double> g(c.size(), 0.0);
    for (std::size_t j = 1; j < c.size(); ++j) g[j] = std::pow(dT, static_cast<double>(j));
    double v = 0.0;
    for (std::size_t i = 0; i < c.size(); ++i)
      for (std::size_t k = 0; k < c.size(); ++k) v += g[i] * cov[i][k] * g[k];
    return std::sqrt(std::max(v, 0.0));
  }
};

AxisFit axis_fit(const nlohmann::json& axis) {
  AxisFit f;
  f.determined = at(axis, "determined").get<bool>();
  if (!f.determined) {
    f.reason = axis.value("reason", std::string());
    return f;
  }
  for (const auto& x : at(axis, "coefficients")) f.c.push_back(x.get<double>());
  for (const auto& row : at(axis, "covariance")) {
    f.cov.emplace_back();
    for (const auto& x : row) f.cov.back().push_back(x.get<double>());
    if (f.cov.back().size() != f.c.size())
      throw JsonError{"covariance: a row is not as long as coefficients"};
  }
  if (f.cov.size() != f.c.size()) throw JsonError{"covariance: not as many rows as coefficients"};
  return f;
}

struct Range {
  double ref = 0.0, lo = 0.0, hi = 0.0;
};

/// Before compensation: the bin means less c_0 (points), the fitted change (line) and its
/// 2-sigma band, per axis.
Figure drift_figure(const nlohmann::json& r, const SensorView& v, const Range& range,
                    const AxisFit (&fits)[3]) {
  Figure f;
  f.id = std::string("thermal-") + v.key;
  f.title = std::string(v.name) + " bias against die temperature";
  f.caption = std::string("Points: the ") + v.name +
              " means of the time bins less each axis's value at the reference temperature (" +
              num(range.ref, 4) +
              " deg C): the drift without compensation, temperature and bias random walk together. "
              "Lines: the fitted change f(T) - f(T_ref); shaded: its 2-sigma band. Values in " +
              v.unit + ".";
  f.height_px = 480;
  const auto& rows = at(at(r, "bin_means"), "rows");
  std::string s;
  std::string plot;
  for (int a = 0; a < 3; ++a) {
    if (!fits[a].determined) continue;
    std::vector<std::vector<double>> pts, curve;
    for (const auto& row : rows) {
      pts.push_back({row[1].get<double>(), (row[v.bin_column + a].get<double>() - fits[a].c[0]) * v.per_si});
    }
    for (int i = 0; i < kCurvePoints; ++i) {
      const double T = range.lo + (range.hi - range.lo) * i / (kCurvePoints - 1);
      const double c = fits[a].change(T - range.ref), sd = fits[a].change_sigma(T - range.ref);
      curve.push_back({T, c * v.per_si, (c - 2 * sd) * v.per_si, (c + 2 * sd) * v.per_si});
    }
    const std::string n = std::to_string(a);
    s += datablock("pts" + n, pts) + datablock("fit" + n, curve);
    const std::string colour = std::string(" lc rgb '") + kAxisColour[a] + "'";
    plot += std::string(plot.empty() ? "" : ", ") + "$fit" + n +
            " using 1:3:4 with filledcurves fs transparent solid 0.18 noborder fc rgb '" + kAxisColour[a] +
            "' notitle, $pts" + n + " using 1:2 with points pt 7 ps 0.5" + colour + " title '" + "xyz"[a] +
            "', $fit" + n + " using 1:2 with lines lw 2" + colour + " title '" + "xyz"[a] + " fit'";
  }
  if (plot.empty()) return {};
  s += "set grid lc rgb '#e0e0e0'\nset xlabel 'die temperature (deg C)'\nset ylabel " +
       gp_quote(std::string("change of the bias (") + v.unit + ")") + "\nset key outside right top\nplot " +
       plot + "\n";
  f.script = s;
  return f;
}

/// After compensation: the bin means less the fitted curve, per axis, with the RMS before and
/// after in the caption.
Figure residual_figure(const nlohmann::json& r, const SensorView& v, const Range& range,
                       const AxisFit (&fits)[3]) {
  Figure f;
  f.id = std::string("thermal-") + v.key + "-after";
  f.title = std::string(v.name) + " bias after compensation";
  const auto& rows = at(at(r, "bin_means"), "rows");
  std::string s, plot, rms;
  for (int a = 0; a < 3; ++a) {
    if (!fits[a].determined) continue;
    std::vector<std::vector<double>> pts;
    double before = 0.0, after = 0.0;
    for (const auto& row : rows) {
      const double T = row[1].get<double>(), y = row[v.bin_column + a].get<double>() - fits[a].c[0];
      const double left = y - fits[a].change(T - range.ref);
      pts.push_back({T, left * v.per_si});
      before += y * y;
      after += left * left;
    }
    const double n = std::max<double>(1.0, static_cast<double>(rows.size()));
    rms += std::string(rms.empty() ? "" : "; ") + "xyz"[a] + " " + num(std::sqrt(before / n) * v.per_si, 3) +
           " before, " + num(std::sqrt(after / n) * v.per_si, 3) + " after";
    const std::string k = std::to_string(a);
    s += datablock("left" + k, pts);
    plot += std::string(plot.empty() ? "" : ", ") + "$left" + k +
            " using 1:2 with linespoints pt 7 ps 0.5 lc rgb '" + kAxisColour[a] + "' title '" + "xyz"[a] +
            "'";
  }
  if (plot.empty()) return {};
  f.caption =
      std::string("The time bins' ") + v.name +
      " means less the fitted curve: what compensation leaves (the bias random walk and the noise of a "
      "bin mean). RMS about the value at the reference temperature (" +
      v.unit + "): " + rms + ".";
  f.height_px = 380;
  s += "set grid lc rgb '#e0e0e0'\nset xlabel 'die temperature (deg C)'\nset ylabel " +
       gp_quote(std::string("left after compensation (") + v.unit + ")") +
       "\nset key outside right top\nset xzeroaxis lt -1\nplot " + plot + "\n";
  f.script = s;
  return f;
}

/// The coefficients c_1..c_p with their sigmas, in the display unit per K^j.
std::string coefficients_html(const AxisFit& a, const SensorView& v) {
  if (a.c.size() <= 1) return "none (order 0: no change with temperature)";
  std::string out;
  for (std::size_t j = 1; j < a.c.size(); ++j) {
    out += std::string(j > 1 ? "<br>" : "") + "c<sub>" + std::to_string(j) +
           "</sub> = " + with_sigma(a.c[j] * v.per_si, std::sqrt(a.cov[j][j]) * v.per_si, false) + " " +
           v.unit + "/K" + (j > 1 ? "<sup>" + std::to_string(j) + "</sup>" : "");
  }
  return out;
}

Section sensor_section(const nlohmann::json& r, const SensorView& v, const Range& range) {
  const auto& sensor = at(r, v.key);
  AxisFit fits[3];
  Table t{{"axis", "order (AIC)", "coefficients about T_ref", "drift over the range", "left after (RMS)",
           "model sigma (RMS)", "bias random walk"},
          {}};
  for (int a = 0; a < 3; ++a) {
    const auto& axis = at(sensor, std::string(1, "xyz"[a]).c_str());
    fits[a] = axis_fit(axis);
    if (!fits[a].determined) {
      t.rows.push_back(
          {std::string(1, "xyz"[a]), "not determined: " + escape(fits[a].reason), "", "", "", "", ""});
      continue;
    }
    t.rows.push_back({std::string(1, "xyz"[a]), std::to_string(fits[a].c.size() - 1),
                      coefficients_html(fits[a], v),
                      num(number(axis, "uncompensated_drift") * v.per_si, 3) + " " + v.unit,
                      num(number(axis, "residual_rms") * v.per_si, 3) + " " + v.unit,
                      num(number(axis, "model_sigma_rms") * v.per_si, 3) + " " + v.unit,
                      num(number(axis, "bias_random_walk") * v.per_si, 3) + " " + v.unit + "/&radic;s"});
  }
  Section s{v.name, t.to_html(), {}};
  for (Figure f : {drift_figure(r, v, range, fits), residual_figure(r, v, range, fits)}) {
    if (!f.script.empty()) s.figures.push_back(std::move(f));
  }
  return s;
}

}  // namespace

Result<Document> thermal_document(const nlohmann::json& r, BuildContext& ctx) {
  Document doc;
  doc.title = "Bias against die temperature (thermal calibration)";
  doc.subtitle = "Report of " + ctx.result_path;
  for (const auto& w : r.value("warnings", nlohmann::json::array()))
    doc.warnings.push_back(w.get<std::string>());
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress, ctx.log_name);
    if (!session.ok()) return session.error();
    doc.sections.push_back(std::move(*session));
  }
  const auto& valid = at(r, "valid_range_c");
  const Range range{number(r, "reference_temperature_c"), valid[0].get<double>(), valid[1].get<double>()};
  Table overview{{"", ""}, {}};
  overview.rows.push_back({"log", escape(r.value("log", std::string("-"))) + " (" +
                                      escape(r.value("stream", std::string("-"))) + ", " +
                                      escape(r.value("input_units", std::string("-"))) + ")"});
  overview.rows.push_back({"die temperature", num(range.lo, 4) + " to " + num(range.hi, 4) +
                                                  " deg C (the model is valid over this range only)"});
  overview.rows.push_back({"reference temperature", num(range.ref, 4) + " deg C"});
  overview.rows.push_back({"recording", num(number(r, "duration_s"), 5) + " s, " +
                                            std::to_string(at(r, "samples").get<long long>()) +
                                            " samples in " + std::to_string(at(r, "bins").get<long long>()) +
                                            " bins of " + num(number(r, "bin_s"), 3) + " s"});
  overview.rows.push_back(
      {"temperature moved one way only",
       r.value("temperature_monotonic", false) ? "yes: random walk and curve told apart by shape" : "no"});
  overview.rows.push_back({"order chosen by", escape(r.value("order_criterion", std::string("-")))});
  overview.rows.push_back({"scale against temperature",
                           escape(r.value("scale_against_temperature", std::string("not determined")))});
  doc.sections.push_back({"Result", overview.to_html(), {}});
  doc.sections.push_back(sensor_section(r, kGyro, range));
  doc.sections.push_back(sensor_section(r, kAccel, range));
  return doc;
}

}  // namespace imucal::app::report
