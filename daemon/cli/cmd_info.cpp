// SPDX-License-Identifier: BSD-3-Clause
// imucal info [--json] LOG: what a session log holds and whether it is healthy.
// The output fields are documented in docs/session-log.md.

#include <fmt/printf.h>

#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "app/stream_stats.hpp"
#include "core/printable_text.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

using nlohmann::json;

using app::StreamTiming;

json timing_json(const StreamTiming& t, double nominal_rate_hz) {
  return {{"count", t.count},
          {"t_first_ns", t.t_first_ns},
          {"t_last_ns", t.t_last_ns},
          {"duration_s", ns_to_s(t.t_last_ns - t.t_first_ns)},
          {"nominal_rate_hz", nominal_rate_hz},
          {"measured_rate_hz", t.measured_rate_hz},
          {"median_period_ns", t.median_period_ns},
          {"gap_intervals", t.gap_intervals},
          {"longest_interval_ns", t.longest_interval_ns},
          {"longest_interval_at_ns", t.longest_interval_at_ns},
          {"non_increasing_intervals", t.non_increasing}};
}

std::string timing_text(const StreamTiming& t, double nominal_rate_hz, const char* what) {
  std::ostringstream out;
  out << "    " << what << ": " << t.count << ", nominal " << fmt::sprintf("%.6g", nominal_rate_hz)
      << " Hz, measured " << fmt::sprintf("%.6g", t.measured_rate_hz) << " Hz over "
      << fmt::sprintf("%.3f", ns_to_s(t.t_last_ns - t.t_first_ns)) << " s\n";
  out << "    intervals: median " << fmt::sprintf("%.6g", t.median_period_ns * 1e-6) << " ms, "
      << t.gap_intervals << " with samples lost, longest "
      << fmt::sprintf("%.6g", t.longest_interval_ns * 1e-6) << " ms";
  if (t.longest_interval_ns > 0)
    out << " (ending at t=" << fmt::sprintf("%.6f", ns_to_s(t.longest_interval_at_ns)) << " s)";
  out << "\n";
  if (t.non_increasing > 0) out << "    WARNING: " << t.non_increasing << " non-increasing timestamps\n";
  return out.str();
}

std::string one_line(const std::string& value, std::size_t max_chars) {
  std::string line;
  for (char c : value) line += (c == '\n' || c == '\r' || c == '\t') ? ' ' : c;
  if (line.size() > max_chars) line = line.substr(0, max_chars) + "...";
  return line;
}

json imu_stream_json(const app::ImuStreamStats& st) {
  const ImuStreamInfo& info = st.info;
  json j = {{"id", st.id},
            {"name", info.name},
            {"units", imu_units_name(info.units)},
            {"device", info.device},
            {"accel_full_scale_g", info.accel_full_scale_g},
            {"gyro_full_scale_dps", info.gyro_full_scale_dps},
            {"dlpf_hz", info.dlpf_hz},
            {"flagged_gap_samples", st.flagged_gap},
            {"flagged_reset_samples", st.flagged_reset},
            {"flagged_saturated_samples", st.flagged_saturated},
            {"flagged_time_estimated_samples", st.flagged_time_estimated},
            {"read_error", st.read_error}};
  j.update(timing_json(st.timing, info.rate_hz));
  return j;
}

std::string imu_stream_text(const app::ImuStreamStats& st) {
  const ImuStreamInfo& info = st.info;
  std::ostringstream text;
  text << "  " << info.name << " (id " << st.id << ", "
       << (info.units == ImuUnits::kRaw ? "raw counts" : "SI units") << ", device "
       << (info.device.empty() ? "?" : info.device);
  if (info.accel_full_scale_g > 0) text << ", accel +-" << info.accel_full_scale_g << " g";
  if (info.gyro_full_scale_dps > 0) text << ", gyro +-" << info.gyro_full_scale_dps << " dps";
  if (info.dlpf_hz > 0) text << ", DLPF " << info.dlpf_hz << " Hz";
  text << ")\n" << timing_text(st.timing, info.rate_hz, "samples");
  text << "    flagged: " << st.flagged_gap << " after a gap, " << st.flagged_reset
       << " after a device reset, " << st.flagged_saturated << " saturated, " << st.flagged_time_estimated
       << " with estimated time\n";
  if (!st.read_error.empty()) text << "    ERROR: " << st.read_error << "\n";
  return text.str();
}

json camera_stream_json(const app::CameraStreamStats& st) {
  const CameraStreamInfo& info = st.info;
  json j = {{"id", st.id},
            {"name", info.name},
            {"width", info.width},
            {"height", info.height},
            {"backend", info.backend},
            {"device", info.device},
            {"timestamp_source", info.timestamp_source},
            {"unusable_frames", st.unusable_frames},
            {"read_error", st.read_error}};
  j.update(timing_json(st.timing, info.rate_hz));
  return j;
}

std::string camera_stream_text(const app::CameraStreamStats& st) {
  const CameraStreamInfo& info = st.info;
  std::ostringstream text;
  text << "  " << info.name << " (id " << st.id << ", " << info.width << "x" << info.height << ", "
       << (info.backend.empty() ? "?" : info.backend) << " " << info.device << ", "
       << (info.timestamp_source.empty() ? "unknown" : info.timestamp_source) << " timestamps)\n"
       << timing_text(st.timing, info.rate_hz, "frames");
  if (st.unusable_frames > 0)
    text << "    UNUSABLE: " << st.unusable_frames << " frames whose image is unreadable or fails its CRC\n";
  if (!st.read_error.empty()) text << "    ERROR: " << st.read_error << "\n";
  return text.str();
}

json summary_json(const std::string& path, const app::LogSummary& s) {
  json imu = json::array();
  for (const auto& st : s.imu) imu.push_back(imu_stream_json(st));
  json cameras = json::array();
  for (const auto& st : s.cameras) cameras.push_back(camera_stream_json(st));
  json out;
  out["path"] = path;
  out["schema_version"] = s.meta("schema_version");
  out["software_version"] = s.meta("software_version");
  out["created_utc"] = s.meta("created_utc");
  out["complete"] = s.health.complete;
  out["damaged"] = s.health.damaged;
  out["damage_message"] = s.health.damage_message;
  out["t_start_ns"] = s.t_start_ns;
  out["t_end_ns"] = s.t_end_ns;
  out["duration_s"] = ns_to_s(s.t_end_ns - s.t_start_ns);
  out["imu_streams"] = imu;
  out["camera_streams"] = cameras;
  out["events"] = {{"count", s.event_count}, {"by_kind", s.events_by_kind}};
  out["metadata"] = s.metadata;
  return out;
}

std::string summary_text(const std::string& path, const app::LogSummary& s) {
  std::ostringstream text;
  text << "session log " << path << "\n";
  text << "  schema " << s.meta("schema_version") << ", written by imucal " << s.meta("software_version")
       << ", created " << s.meta("created_utc") << "\n";
  text << "  status: "
       << (s.health.complete ? "complete"
                             : "INCOMPLETE (the writer did not close it; the recording was interrupted)")
       << (s.health.damaged ? ", DAMAGED" : "") << "\n";
  text << "  duration: " << fmt::sprintf("%.3f", ns_to_s(s.t_end_ns - s.t_start_ns)) << " s";
  if (s.any_time) {
    text << " (t=" << fmt::sprintf("%.6f", ns_to_s(s.t_start_ns)) << " s to "
         << fmt::sprintf("%.6f", ns_to_s(s.t_end_ns)) << " s)";
  }
  text << "\n";
  text << "IMU streams: " << s.imu.size() << "\n";
  for (const auto& st : s.imu) text << imu_stream_text(st);
  text << "camera streams: " << s.cameras.size() << "\n";
  for (const auto& st : s.cameras) text << camera_stream_text(st);
  text << "events: " << s.event_count;
  if (!s.events_by_kind.empty()) {
    text << " (";
    bool first = true;
    for (const auto& [kind, n] : s.events_by_kind) {
      text << (first ? "" : ", ") << kind << " " << n;
      first = false;
    }
    text << ")";
  }
  text << "\nmetadata:\n";
  for (const auto& [key, value] : s.metadata) text << "  " << key << ": " << one_line(value, 100) << "\n";
  return text.str();
}

int run_info(const std::string& path, bool as_json) {
  auto summary = app::summarize_log(path);
  // Anything that prevents reading the log is an input problem, including a newer schema.
  if (!summary.ok()) throw CliExit{kExitInput, summary.error().message};
  std::cout
      << (as_json
              ? summary_json(path, *summary).dump(2, ' ', false, nlohmann::json::error_handler_t::replace) +
                    "\n"
              // Names, devices and metadata come from the file: no control character reaches the
              // terminal (an escape sequence in a log's metadata could retitle or clear it).
              : printable_text(summary_text(path, *summary), true));
  std::cout.flush();
  if (summary->health.damaged) {
    std::cerr
        << "imucal: WARNING: session log " << path << " is damaged: " << summary->health.damage_message
        << ". The figures above cover only what was readable; record the session again if the lost part "
           "matters.\n";
    return kExitInput;
  }
  return kExitOk;
}

const CommandRegistrar registrar(30, [](CLI::App& root) {
  auto* cmd = root.add_subcommand("info", "Summarise a session log: streams, rates, gaps, events, health");
  auto path = std::make_shared<std::string>();
  auto as_json = std::make_shared<bool>(false);
  cmd->add_option("LOG", *path, "Session log (.imulog)")->required();
  cmd->add_flag("--json", *as_json, "Print JSON (fields in docs/session-log.md)");
  cmd->callback([path, as_json] {
    const int code = run_info(*path, *as_json);
    if (code != kExitOk) throw CliExit{code, ""};
  });
});

}  // namespace
}  // namespace imucal::cli
