// SPDX-License-Identifier: BSD-3-Clause
// The session summary of a report (from the log, app/stream_stats.hpp) and the JSON readers the
// document builders share.

#include <cmath>
#include <string>

#include "app/report/builders.hpp"
#include "app/stream_stats.hpp"

namespace imucal::app::report {

const nlohmann::json& at(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key)) throw JsonError{std::string("the key '") + key + "' is missing"};
  return j.at(key);
}

double number(const nlohmann::json& j, const char* key) {
  const auto& v = at(j, key);
  if (v.is_null()) return std::numeric_limits<double>::quiet_NaN();  // NaN is written as null
  if (!v.is_number()) throw JsonError{std::string("'") + key + "' is not a number"};
  return v.get<double>();
}

namespace {
double element(const nlohmann::json& v) {
  if (v.is_null()) return std::numeric_limits<double>::quiet_NaN();
  if (!v.is_number()) throw JsonError{"a vector or matrix holds something that is not a number"};
  return v.get<double>();
}
}  // namespace

Eigen::Vector3d vec3(const nlohmann::json& j) {
  if (!j.is_array() || j.size() != 3) throw JsonError{"a 3-vector is not an array of 3 numbers"};
  return {element(j[0]), element(j[1]), element(j[2])};
}

Eigen::Matrix3d mat3(const nlohmann::json& j) {
  if (!j.is_array() || j.size() != 3) throw JsonError{"a 3x3 matrix is not 3 rows"};
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) m.row(r) = vec3(j[r]).transpose();
  return m;
}

namespace {

/// Metadata worth a row: short plain values (JSON documents such as the rig configuration are
/// only named).
Table metadata_table(const LogSummary& s, std::string* long_keys) {
  Table t{{"key", "value"}, {}};
  for (const auto& [key, value] : s.metadata) {
    const bool structured = !value.empty() && (value.front() == '{' || value.front() == '[');
    if (structured || value.size() > 100) {
      *long_keys += (long_keys->empty() ? "" : ", ") + escape(key);
      continue;
    }
    t.rows.push_back({escape(key), escape(value)});
  }
  return t;
}

Table imu_table(const LogSummary& s) {
  Table t{{"IMU stream", "device", "units", "full scale", "samples", "duration (s)", "rate (Hz)", "gaps",
           "saturated", "resets"},
          {}};
  for (const auto& st : s.imu) {
    const auto& i = st.info;
    const std::string fs = i.accel_full_scale_g > 0 ? std::to_string(i.accel_full_scale_g) + " g, " +
                                                          std::to_string(i.gyro_full_scale_dps) + " deg/s"
                                                    : "-";
    t.rows.push_back({escape(i.name), escape(i.device.empty() ? "-" : i.device),
                      escape(imu_units_name(i.units)), fs, std::to_string(st.timing.count),
                      num(st.timing.duration_s(), 6), num(st.timing.measured_rate_hz, 6),
                      std::to_string(st.timing.gap_intervals), std::to_string(st.flagged_saturated),
                      std::to_string(st.flagged_reset)});
  }
  return t;
}

Table camera_table(const LogSummary& s) {
  Table t{{"camera stream", "resolution", "frames", "duration (s)", "rate (Hz)", "gaps"}, {}};
  for (const auto& c : s.cameras) {
    t.rows.push_back({escape(c.info.name),
                      std::to_string(c.info.width) + " x " + std::to_string(c.info.height),
                      std::to_string(c.timing.count), num(c.timing.duration_s(), 6),
                      num(c.timing.measured_rate_hz, 6), std::to_string(c.timing.gap_intervals)});
  }
  return t;
}

}  // namespace

Result<Section> session_section(const std::string& log_path, bool in_progress, const std::string& shown) {
  const std::string& name = shown.empty() ? log_path : shown;
  auto summary = summarize_log(log_path);
  if (!summary.ok()) return summary.error().context("the log " + name);
  const LogSummary& s = *summary;
  Section sec;
  sec.title = "Session";
  sec.html = "<p>Log <code>" + escape(name) + "</code>: " +
             (s.any_time ? num(ns_to_s(s.t_end_ns - s.t_start_ns), 6) + " s recorded, " : std::string()) +
             std::to_string(s.imu.size()) + " IMU stream(s), " + std::to_string(s.cameras.size()) +
             " camera stream(s), " + std::to_string(s.event_count) + " event(s); " +
             (s.health.damaged    ? "<strong>damaged</strong>: " + escape(s.health.damage_message)
              : s.health.complete ? "closed cleanly"
              : in_progress ? "still being recorded when this report was drawn (the session went on to its "
                              "review and write; the log holds them)"
                            : "<strong>not closed cleanly</strong> (the recording was interrupted)") +
             ".</p>\n";
  sec.html += imu_table(s).to_html();
  if (!s.cameras.empty()) sec.html += camera_table(s).to_html();
  std::string long_keys;
  const Table meta = metadata_table(s, &long_keys);
  if (!meta.rows.empty()) sec.html += "<p>Metadata:</p>\n" + meta.to_html();
  if (!long_keys.empty())
    sec.html += "<p class=\"note\">Also recorded (structured, see <code>imucal info</code>): " + long_keys +
                ".</p>\n";
  return sec;
}

/// The self-check (core/split_check.hpp): the verdict, the advice, and every compared parameter
/// in every part with its sigma and the largest difference in combined sigmas.
Section self_check_section(const nlohmann::json& r) {
  if (!r.contains("self_check") || !r["self_check"].is_object() ||
      r["self_check"].value("verdict", std::string("not run")) == "not run")
    return {};
  const nlohmann::json& sc = r["self_check"];
  const std::string verdict = at(sc, "verdict").get<std::string>();
  std::string html = "<p>" + escape(at(sc, "summary").get<std::string>()) + "</p>\n";
  if (const std::string advice = at(sc, "advice").get<std::string>(); !advice.empty())
    html += "<p class=\"note\">" + escape(advice) + "</p>\n";
  const nlohmann::json scaled = sc.value("sigmas_scaled", nlohmann::json::object());
  for (const auto& [name, factor] : scaled.items())
    html += "<p class=\"note\">" + escape(name) + "'s sigmas in this report are scaled by " +
            num(factor.get<double>(), 3) +
            " (the parts spread that much more than their own sigmas allow).</p>\n";
  const auto& spans = at(sc, "spans_s");
  std::vector<std::string> head{"parameter"};
  for (std::size_t i = 0; i < spans.size(); ++i)
    head.push_back("part " + std::to_string(i + 1) + " (" + num(spans[i].at(0).get<double>(), 3) + "-" +
                   num(spans[i].at(1).get<double>(), 3) + " s)");
  head.push_back("largest difference (combined sigmas)");
  Table t{head, {}};
  const double limit = number(sc, "z_limit");
  for (const auto& p : at(sc, "parameters")) {
    std::vector<std::string> row{escape(at(p, "name").get<std::string>()) + " (" +
                                 escape(at(p, "unit").get<std::string>()) + ")"};
    const auto& v = at(p, "values");
    const auto& sg = at(p, "sigmas");
    for (std::size_t i = 0; i < v.size() && i < sg.size(); ++i)
      row.push_back(v[i].is_null() ? "not solved"
                                   : with_sigma(v[i].get<double>(),
                                                sg[i].is_null() ? std::nan("") : sg[i].get<double>()));
    const double z = number(p, "worst_z");
    row.push_back(std::isfinite(z) && z > limit ? "<b>" + num(z, 2) + "</b>" : num(z, 2));
    t.rows.push_back(std::move(row));
  }
  if (verdict != "not run" && !t.rows.empty()) html += t.to_html();
  html +=
      "<p class=\"note\">Each part of the recording was calibrated on its own with the whole solve's "
      "choices; rotations are the small-angle difference to the whole recording's, about the camera's axes. "
      "The parts agree when no difference exceeds the limit and the chi-square's probability is at least "
      "0.001.</p>\n";
  return {"Self-check", html, {}};
}

}  // namespace imucal::app::report
