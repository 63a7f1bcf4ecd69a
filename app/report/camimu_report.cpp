// SPDX-License-Identifier: BSD-3-Clause
// The report of a camera-IMU calibration (imucal calibrate camimu, OUT_DIR/result.json): the
// cameras' extrinsics and time offsets, the IMU's Krebs model, all with sigmas; the IMU residuals
// against the noise the solve assumed; the biases over time and the angular-speed
// cross-correlation that started the time offset; the reprojection residuals of the corners; the
// IMU signals measured and predicted by the basic and the extended model.

#include <algorithm>
#include <cmath>
#include <string>

#include "app/report/builders.hpp"
#include "core/camimu_calibration.hpp"
#include "core/text_format.hpp"

namespace imucal::app::report {
namespace {

constexpr double kDeg = 180.0 / M_PI;

// True when the solve held the parameter `name` (the result's "fixed" list: T_cam_imu, timeshift, ...).
bool held(const nlohmann::json& r, const std::string& name) {
  for (const auto& f : at(r, "fixed"))
    if (f.is_string() && f.get<std::string>() == name) return true;
  return false;
}

std::string vec_sigma(const Eigen::Vector3d& v, const Eigen::Vector3d& s, double scale, bool fixed) {
  std::string out;
  for (int a = 0; a < 3; ++a)
    out += std::string(a ? "<br>" : "") + "xyz"[a] + ": " + with_sigma(v[a] * scale, s[a] * scale, fixed);
  return out;
}

/// Standard deviations of small rotation angles (about the estimate), per axis; "fixed" for a
/// rotation the solve held (its sigma is then absent, not undetermined).
std::string sigmas(const Eigen::Vector3d& s, double scale, bool fixed) {
  if (fixed) return "fixed";
  std::string out;
  for (int a = 0; a < 3; ++a) out += std::string(a ? "<br>" : "") + "xyz"[a] + ": " + num(s[a] * scale, 2);
  return out;
}

/// Angles in rad as a list in degrees (the gravity direction has two).
std::string list_deg(const nlohmann::json& values) {
  std::string out;
  for (const auto& v : values) out += (out.empty() ? "" : ", ") + num(v.get<double>() * kDeg, 2);
  return out;
}

Section cameras_section(const nlohmann::json& r) {
  Table t{{"camera", "translation t_cam_imu (mm)", "rotation sigma (deg)", "time shift cam-imu (ms)",
           "reprojection RMS (px)", "frames, corners (outliers)"},
          {}};
  std::string matrices;
  for (const auto& c : at(r, "cameras")) {
    const std::string name =
        at(c, "name").get<std::string>() + " (" + at(c, "stream").get<std::string>() + ")";
    t.rows.push_back(
        {escape(name),
         vec_sigma(vec3(at(c, "t_cam_imu_m")), vec3(at(c, "translation_sigma_m")), 1e3, held(r, "T_cam_imu")),
         sigmas(vec3(at(c, "rotation_sigma_rad")), kDeg, held(r, "T_cam_imu")),
         with_sigma(number(c, "timeshift_cam_imu_s") * 1e3, number(c, "timeshift_sigma_s") * 1e3,
                    held(r, "timeshift")),
         num(number(c, "reprojection_rms_px"), 4),
         std::to_string(at(c, "frames").get<int>()) + ", " + std::to_string(at(c, "corners").get<int>()) +
             " (" + std::to_string(at(c, "outlier_corners").get<int>()) + ")"});
    Table m{{"T_cam_imu of " + escape(name), "", "", ""}, {}};
    for (const auto& row : at(c, "T_cam_imu")) {
      m.rows.emplace_back();
      for (const auto& v : row) m.rows.back().push_back(num(v.get<double>(), 7));
    }
    matrices += m.to_html();
  }
  return {"Cameras",
          t.to_html() + matrices +
              "<p class=\"note\">The time shift is added to the camera's timestamps to give IMU time "
              "(Kalibr's timeshift_cam_imu).</p>\n",
          {}};
}

Section imu_section(const nlohmann::json& r) {
  const auto& imu = at(r, "imu");
  const auto& k = at(imu, "krebs");
  const auto& s = at(imu, "krebs_sigma");
  Table t{{"Krebs model", "value &plusmn; sigma"}, {}};
  auto row = [&](const char* key, const char* label, const char* sigma_key) {
    t.rows.push_back({label, vec_sigma(vec3(at(k, key)), vec3(at(s, sigma_key)), 1.0, held(r, key))});
  };
  row("S_a", "accelerometer scale S_a", "S_a");
  row("M_a", "accelerometer misalignment M_a", "M_a");
  row("b_a", "accelerometer bias b_a (m/s<sup>2</sup>, start)", "b_a");
  row("S_g", "gyroscope scale S_g", "S_g");
  row("M_g", "gyroscope misalignment M_g", "M_g");
  row("b_g", "gyroscope bias b_g (rad/s, start)", "b_g");
  const std::string c_bg = num(number(imu, "C_bg_angle_rad") * kDeg, 4) + " deg";
  t.rows.push_back({"gyro-to-body rotation C_bg",
                    held(r, "C_bg") ? c_bg + " (fixed)"
                                    : c_bg + "; sigma " + sigmas(vec3(at(s, "C_bg_rad")), kDeg, false)});
  const Eigen::Matrix3d B = mat3(at(k, "B_g")), sB = mat3(at(s, "B_g"));
  std::string b;
  for (int i = 0; i < 3; ++i) {
    b += i ? "<br>" : "";
    for (int j = 0; j < 3; ++j) b += (j ? "; " : "") + with_sigma(B(i, j), sB(i, j), held(r, "B_g"));
  }
  t.rows.push_back({"g-sensitivity B_g (rad/s per m/s<sup>2</sup>)", b});
  std::string fixed;
  for (const auto& f : at(r, "fixed")) fixed += (fixed.empty() ? "" : ", ") + escape(f.get<std::string>());
  return {"IMU",
          t.to_html() + "<p class=\"note\">Fixed (not estimated): " + (fixed.empty() ? "none" : fixed) +
              ". Input units of the stream: " + escape(at(imu, "input_units").get<std::string>()) + ".</p>\n",
          {}};
}

Figure biases_figure(const nlohmann::json& r) {
  Figure f;
  f.id = "camimu-biases";
  f.title = "Bias estimates over time";
  f.caption =
      "The accelerometer (top) and gyroscope (bottom) biases of the solve's bias spline, per axis, as "
      "the change from their values at the start of the recording (in the IMU table).";
  f.height_px = 620;
  // The change from the start: the values (a few tenths) would hide a drift of thousandths.
  std::vector<std::vector<double>> rows;
  Eigen::Vector3d a0 = Eigen::Vector3d::Zero(), g0 = Eigen::Vector3d::Zero();
  for (const auto& b : at(r, "biases")) {
    const Eigen::Vector3d ba = vec3(at(b, "b_a")), bg = vec3(at(b, "b_g")) * kDeg;
    if (rows.empty()) a0 = ba, g0 = bg;
    rows.push_back({number(b, "t_s"), ba[0] - a0[0], ba[1] - a0[1], ba[2] - a0[2], bg[0] - g0[0],
                    bg[1] - g0[1], bg[2] - g0[2]});
  }
  if (rows.empty()) rows.push_back({0, NAN, NAN, NAN, NAN, NAN, NAN});
  std::string s = datablock("b", rows) +
                  "set multiplot layout 2,1\nset grid\nset key outside right top\n"
                  "set ylabel 'accel bias change (m/s^2)'\nset format x ''\nplot ";
  for (int a = 0; a < 3; ++a)
    s += std::string(a ? ", " : "") + "$b using 1:" + std::to_string(a + 2) + " with lines lw 2 lc rgb '" +
         kAxisColour[a] + "' title '" + "xyz"[a] + "'";
  s += "\nset format x '%g'\nset xlabel 'time (s)'\nset ylabel 'gyro bias change (deg/s)'\nplot ";
  for (int a = 0; a < 3; ++a)
    s += std::string(a ? ", " : "") + "$b using 1:" + std::to_string(a + 5) + " with lines lw 2 lc rgb '" +
         kAxisColour[a] + "' title '" + "xyz"[a] + "'";
  f.script = s + "\nunset multiplot\n";
  return f;
}

Figure xcorr_figure(const nlohmann::json& r) {
  Figure f;
  f.id = "camimu-xcorr";
  f.title = "Time offset: angular-speed cross-correlation";
  f.caption =
      "Cross-correlation of the camera's angular speed (from its target poses) with the gyroscope's, "
      "per camera, against the lag (t_imu = t_cam + lag); the peak (dashed) started the time-offset "
      "estimate, the solve's result is the solid line";
  f.height_px = 380;
  const auto& q = at(r, "quality");
  const auto& cameras = at(r, "cameras");
  std::string s, plot, results;
  int i = 0;
  for (const auto& curve : at(q, "xcorr")) {
    std::vector<std::vector<double>> rows;
    const auto& lag = at(curve, "lag_s");
    const auto& val = at(curve, "value");
    for (std::size_t k = 0; k < lag.size() && k < val.size(); ++k)
      rows.push_back({lag[k].get<double>() * 1e3, val[k].get<double>()});
    if (rows.empty()) continue;
    const std::string n = std::to_string(i);
    s += datablock("x" + n, rows);
    plot += std::string(plot.empty() ? "plot " : ", ") + "$x" + n + " using 1:2 with lines lw 2 lc rgb '" +
            kAxisColour[i % 3] + "' title 'cam" + n + "'";
    const auto& peaks = at(q, "xcorr_peak_s");
    if (static_cast<std::size_t>(i) < peaks.size()) {
      const double p = peaks[static_cast<std::size_t>(i)].get<double>() * 1e3;
      s += "set arrow from " + num(p, 10) + ", graph 0 to " + num(p, 10) +
           ", graph 1 nohead dashtype 2 lc rgb '" + kAxisColour[i % 3] + "'\n";
    }
    if (static_cast<std::size_t>(i) < cameras.size() &&
        cameras[static_cast<std::size_t>(i)].contains("timeshift_cam_imu_s")) {
      const auto& cam = cameras[static_cast<std::size_t>(i)];
      const double t = cam["timeshift_cam_imu_s"].get<double>() * 1e3;
      s += "set arrow from " + num(t, 10) + ", graph 0 to " + num(t, 10) + ", graph 1 nohead lw 2 lc rgb '" +
           kAxisColour[i % 3] + "'\n";
      results +=
          std::string(results.empty() ? "" : ", ") + cam.value("name", "cam" + n) + " " + fixed(t, 2) + " ms";
    }
    ++i;
  }
  if (plot.empty()) return {};
  if (!results.empty()) f.caption += " (" + results + ")";
  f.caption += ".";
  f.script = s + "set grid\nset key outside right top\nset xlabel 'lag (ms)'\nset ylabel 'correlation'\n" +
             plot + "\n";
  return f;
}

/// The reprojection residual of every stored corner, one colour per camera. Empty when the
/// result holds none (written before they were stored).
Figure camimu_reprojection_figure(const nlohmann::json& r) {
  std::vector<ResidualSeries> series;
  std::size_t stored = 0, total = 0;
  for (const auto& cam : at(r, "cameras")) {
    if (!cam.contains("residuals")) continue;
    const auto& res = cam["residuals"];
    ResidualSeries rs;
    rs.name = cam.value("name", "cam" + std::to_string(series.size()));
    rs.px = at(res, "px").get<std::vector<double>>();
    rs.loss_px = res.value("outlier_px", 0.0);
    rs.colour = kAxisColour[series.size() % 3];
    stored += rs.px.size() / 2;
    total += static_cast<std::size_t>(res.value("of_corners", 0));
    series.push_back(std::move(rs));
  }
  return reprojection_figure("camimu-reprojection", series,
                             "After the final stage; " + std::to_string(stored) + " of " +
                                 std::to_string(total) +
                                 " corners stored (every k-th in time order when there are more than " +
                                 std::to_string(CamImuCameraResult::kMaxStoredResiduals) + ");");
}

Figure residuals_figure(const nlohmann::json& r) {
  const auto& q = at(r, "quality");
  Figure f;
  f.id = "camimu-imu-residuals";
  f.title = "IMU residuals against the assumed noise";
  f.caption =
      "RMS of the accelerometer and gyroscope residuals per axis after the solve (bars), against the "
      "white-noise standard deviation per sample the solve assumed (dashed): bars far above it mean a "
      "model error or noise figures that are too small.";
  f.height_px = 360;
  const Eigen::Vector3d ra = vec3(at(q, "accel_residual_rms_mps2")),
                        rg = vec3(at(q, "gyro_residual_rms_radps"));
  std::vector<std::vector<double>> rows;
  // The gyroscope in deg/s, as the report's other gyroscope figures.
  for (int a = 0; a < 3; ++a) rows.push_back({static_cast<double>(a), ra[a], rg[a] * kDeg});
  f.script =
      datablock("r", rows) +
      "set multiplot layout 1,2\nset style fill solid 0.8 noborder\nset boxwidth 0.6\nset grid ytics\n"
      "set xtics ('x' 0, 'y' 1, 'z' 2)\nset xrange [-0.7:2.7]\nset yrange [0:*]\nunset key\n"
      "set title 'accelerometer'\nset ylabel 'RMS (m/s^2)'\nplot $r using 1:2 with boxes lc rgb '#0072b2', " +
      num(number(q, "accel_sigma_mps2"), 10) +
      " with lines dashtype 2 lw 2 lc rgb '#d55e00'\nset title 'gyroscope'\nset ylabel 'RMS (deg/s)'\n"
      "plot $r using 1:3 with boxes lc rgb '#0072b2', " +
      num(number(q, "gyro_sigma_radps") * kDeg, 10) +
      " with lines dashtype 2 lw 2 lc rgb '#d55e00'\nunset multiplot\n";
  return f;
}

/// The stored measured and predicted signals of each model, as rows of 13 numbers (t_s, accel
/// measured xyz, predicted xyz, gyro measured xyz, predicted xyz); absent in results written
/// before they were stored.
struct SignalFit {
  std::string model;
  Eigen::Vector3d accel_rms, gyro_rms;
  std::vector<std::vector<double>> rows;
};

std::vector<SignalFit> signal_fits(const nlohmann::json& r) {
  std::vector<SignalFit> out;
  if (!r.contains("imu_signals")) return out;
  for (const auto& s : r["imu_signals"]) {
    SignalFit f{at(s, "model").get<std::string>(),
                vec3(at(s, "accel_residual_rms_mps2")),
                vec3(at(s, "gyro_residual_rms_radps")),
                {}};
    for (const auto& row : at(s, "rows")) {
      if (row.size() != 13) throw JsonError{"imu_signals: a row is not 13 numbers"};
      f.rows.push_back(row.get<std::vector<double>>());
    }
    out.push_back(std::move(f));
  }
  return out;
}

/// Measured (grey) and predicted (colour) gyro (left, deg/s) and accel (right, m/s^2) per axis.
Figure signal_fit_figure(const SignalFit& fit) {
  Figure f;
  f.id = "camimu-imu-fit-" + fit.model;
  f.title = "Measured and predicted IMU signals, " + fit.model + " model";
  f.caption =
      fit.model == "basic"
          ? "The IMU samples (grey) and what the basic model predicts from the solved trajectory, "
            "biases and gravity with the IMU intrinsics (scale, misalignment, gyro-accel rotation, "
            "g-sensitivity) held at their start, identity or the IMU calibration given (colour), per axis; "
          : "The IMU samples (grey) and what the extended model predicts with its estimated "
            "intrinsics (colour), per axis; ";
  f.caption += std::to_string(fit.rows.size()) + " samples shown (every k-th above " +
               std::to_string(ImuSignalFit::kMaxSamples) + ").";
  f.height_px = 820;
  std::vector<std::vector<double>> rows = fit.rows;
  for (auto& row : rows)
    for (int c = 7; c < 13; ++c) row[c] *= kDeg;
  if (rows.empty()) rows.push_back(std::vector<double>(13, NAN));
  std::string s = datablock("s", rows) + "set multiplot layout 3,2\nset grid\nset key top right\n";
  for (int a = 0; a < 3; ++a) {
    const std::string axis(1, "xyz"[a]);
    if (a == 2) s += "set xlabel 'time (s)'\n";
    s += "set ylabel 'gyro " + axis + " (deg/s)'\nplot $s using 1:" + std::to_string(8 + a) +
         " with lines lw 3 lc rgb '#b0b0b0' title 'measured', $s using 1:" + std::to_string(11 + a) +
         " with lines lw 1 lc rgb '" + kAxisColour[a] + "' title 'predicted'\n";
    s += "set ylabel 'accel " + axis + " (m/s^2)'\nplot $s using 1:" + std::to_string(2 + a) +
         " with lines lw 3 lc rgb '#b0b0b0' title 'measured', $s using 1:" + std::to_string(5 + a) +
         " with lines lw 1 lc rgb '" + kAxisColour[a] + "' title 'predicted'\n";
  }
  f.script = s + "unset multiplot\n";
  return f;
}

/// Measured - predicted over time, every model in one panel per axis and sensor.
Figure signal_residual_figure(const std::vector<SignalFit>& fits) {
  Figure f;
  f.id = "camimu-imu-fit-residuals";
  f.title = "IMU residuals over time, per model";
  f.caption =
      "Measured minus predicted gyro (left) and accel (right) per axis for each model; what the basic "
      "model leaves here and the extended model removes is the scale, misalignment, axis rotation and "
      "g-sensitivity of the IMU.";
  f.height_px = 820;
  const char* colour[2] = {"#d55e00", "#0072b2"};
  std::string s = "set multiplot layout 3,2\nset grid\nset key top right\n";
  for (std::size_t m = 0; m < fits.size(); ++m) {
    std::vector<std::vector<double>> rows;
    for (const auto& row : fits[m].rows) {
      std::vector<double> d{row[0]};
      for (int a = 0; a < 3; ++a) d.push_back((row[7 + a] - row[10 + a]) * kDeg);
      for (int a = 0; a < 3; ++a) d.push_back(row[1 + a] - row[4 + a]);
      rows.push_back(std::move(d));
    }
    if (rows.empty()) rows.push_back(std::vector<double>(7, NAN));
    s = datablock("r" + std::to_string(m), rows) + s;
  }
  for (int a = 0; a < 3; ++a) {
    const std::string axis(1, "xyz"[a]);
    if (a == 2) s += "set xlabel 'time (s)'\n";
    for (int sensor = 0; sensor < 2; ++sensor) {
      s += std::string("set ylabel '") + (sensor == 0 ? "gyro " : "accel ") + axis +
           (sensor == 0 ? " (deg/s)'\nplot " : " (m/s^2)'\nplot ");
      for (std::size_t m = 0; m < fits.size(); ++m)
        s += std::string(m ? ", " : "") + "$r" + std::to_string(m) +
             " using 1:" + std::to_string(2 + a + 3 * sensor) + " with lines lw 1 lc rgb '" + colour[m % 2] +
             "' title " + gp_quote(fits[m].model);
      s += "\n";
    }
  }
  f.script = s + "unset multiplot\n";
  return f;
}

/// RMS of measured - predicted per axis for each model.
std::string signal_fit_table(const std::vector<SignalFit>& fits) {
  Table t{{"model", "gyro residual RMS x, y, z (deg/s)", "accel residual RMS x, y, z (m/s<sup>2</sup>)"}, {}};
  for (const auto& f : fits) {
    std::string g, a;
    for (int i = 0; i < 3; ++i) {
      g += (i ? ", " : "") + num(f.gyro_rms[i] * kDeg, 4);
      a += (i ? ", " : "") + num(f.accel_rms[i], 4);
    }
    t.rows.push_back({escape(f.model), g, a});
  }
  return t.to_html();
}

Section overview_section(const nlohmann::json& r) {
  const auto& q = at(r, "quality");
  Table t{{"", ""}, {}};
  t.rows.push_back({"method", escape(at(r, "method").get<std::string>()) + ", model " +
                                  escape(at(r, "model").get<std::string>())});
  const Eigen::Vector3d g = vec3(at(r, "gravity_w_mps2"));
  t.rows.push_back(
      {"gravity in the world frame",
       num(g.norm(), 7) + " m/s<sup>2</sup>, direction sigma (deg) " + list_deg(at(r, "gravity_sigma_rad"))});
  t.rows.push_back({"solve", std::to_string(at(q, "iterations").get<int>()) + " iterations, cost " +
                                 num(number(q, "initial_cost"), 4) + " &rarr; " +
                                 num(number(q, "final_cost"), 4) + ", " +
                                 std::to_string(at(q, "residuals").get<long>()) + " residuals, " +
                                 std::to_string(at(q, "parameters").get<long>()) + " parameters, " +
                                 std::to_string(at(q, "spline_knots").get<long>()) + " spline knots"});
  t.rows.push_back(
      {"excitation (RMS)", "rotation " + num(vec3(at(q, "rotation_excitation_radps")).norm() * kDeg, 4) +
                               " deg/s, acceleration " + num(vec3(at(q, "accel_excitation_mps2")).norm(), 4) +
                               " m/s<sup>2</sup>"});
  if (r.contains("inputs")) {
    const auto& in = r["inputs"];
    t.rows.push_back({"noise from", escape(in.value("noise_source", std::string("-")))});
    const std::string from = in.value("imu_intrinsics", std::string());
    t.rows.push_back(
        {"IMU intrinsics from", from.empty() ? "estimated (no prior calibration given)" : escape(from)});
  }
  std::string notes;
  for (const auto& n : r.value("notes", nlohmann::json::array()))
    notes += "<li>" + escape(n.get<std::string>()) + "</li>";
  return {"Result", t.to_html() + (notes.empty() ? "" : "<ul class=\"note\">" + notes + "</ul>\n"), {}};
}

}  // namespace

Result<Document> camimu_document(const nlohmann::json& r, BuildContext& ctx) {
  Document doc;
  doc.title = "Camera-IMU calibration";
  doc.subtitle = "Report of " + ctx.result_path;
  for (const auto& w : at(r, "warnings")) doc.warnings.push_back(w.get<std::string>());
  if (!ctx.log_path.empty()) {
    auto session = session_section(ctx.log_path, ctx.log_in_progress, ctx.log_name);
    if (!session.ok()) return session.error();
    doc.sections.push_back(std::move(*session));
  }
  doc.sections.push_back(overview_section(r));
  doc.sections.push_back(cameras_section(r));
  doc.sections.push_back(imu_section(r));
  if (auto sc = self_check_section(r); !sc.title.empty()) doc.sections.push_back(std::move(sc));
  Figure reprojection = camimu_reprojection_figure(r);
  Section quality{
      "Quality",
      reprojection.id.empty()
          ? "<p class=\"note\">This result.json holds each camera's RMS reprojection error (above), "
            "not the residual of each corner (it was written before they were stored): there is no "
            "scatter or histogram of them.</p>\n"
          : "",
      {}};
  if (!reprojection.id.empty()) quality.figures.push_back(std::move(reprojection));
  quality.figures.push_back(residuals_figure(r));
  const std::vector<SignalFit> fits = signal_fits(r);
  if (fits.empty()) {
    quality.html +=
        "<p class=\"note\">This result.json holds no measured and predicted IMU signals (it was written "
        "before they were stored).</p>\n";
  } else {
    quality.html += signal_fit_table(fits);
    for (const auto& fit : fits) quality.figures.push_back(signal_fit_figure(fit));
    quality.figures.push_back(signal_residual_figure(fits));
  }
  if (Figure x = xcorr_figure(r); !x.id.empty()) quality.figures.push_back(std::move(x));
  quality.figures.push_back(biases_figure(r));
  doc.sections.push_back(std::move(quality));
  return doc;
}

}  // namespace imucal::app::report
