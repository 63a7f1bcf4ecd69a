// imucal info [--json] LOG: what a session log holds and whether it is healthy.
// The output fields are documented in docs/session-log.md.

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

using nlohmann::json;

/// Timing statistics of one stream, from its timestamps.
struct StreamTiming {
  std::int64_t count = 0;
  TimeNs t_first_ns = 0;
  TimeNs t_last_ns = 0;
  TimeNs median_period_ns = 0;
  double measured_rate_hz = 0.0;
  std::int64_t gap_intervals = 0;  // intervals longer than 1.5x the median period
  TimeNs longest_interval_ns = 0;
  TimeNs longest_interval_at_ns = 0;  // timestamp of the sample that ends the longest interval
  std::int64_t non_increasing = 0;    // intervals <= 0 (duplicate or backwards timestamps)
};

StreamTiming timing_of(const std::vector<TimeNs>& times) {
  StreamTiming t;
  t.count = static_cast<std::int64_t>(times.size());
  if (times.empty()) return t;
  t.t_first_ns = times.front();
  t.t_last_ns = times.back();
  if (times.size() < 2) return t;
  std::vector<TimeNs> periods(times.size() - 1);
  for (std::size_t i = 1; i < times.size(); ++i) periods[i - 1] = times[i] - times[i - 1];
  std::vector<TimeNs> sorted = periods;
  auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), mid, sorted.end());
  t.median_period_ns = *mid;
  const TimeNs span_ns = t.t_last_ns - t.t_first_ns;
  if (span_ns > 0) t.measured_rate_hz = static_cast<double>(times.size() - 1) / ns_to_s(span_ns);
  for (std::size_t i = 0; i < periods.size(); ++i) {
    const TimeNs p = periods[i];
    if (p <= 0) ++t.non_increasing;
    if (t.median_period_ns > 0 && 2 * p > 3 * t.median_period_ns) ++t.gap_intervals;
    if (p > t.longest_interval_ns) {
      t.longest_interval_ns = p;
      t.longest_interval_at_ns = times[i + 1];
    }
  }
  return t;
}

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

std::string fmt(const char* format, double value) {
  char text[64];
  std::snprintf(text, sizeof text, format, value);
  return text;
}

std::string timing_text(const StreamTiming& t, double nominal_rate_hz, const char* what) {
  std::ostringstream out;
  out << "    " << what << ": " << t.count << ", nominal " << fmt("%.6g", nominal_rate_hz) << " Hz, measured "
      << fmt("%.6g", t.measured_rate_hz) << " Hz over " << fmt("%.3f", ns_to_s(t.t_last_ns - t.t_first_ns))
      << " s\n";
  out << "    intervals: median " << fmt("%.6g", t.median_period_ns * 1e-6) << " ms, " << t.gap_intervals
      << " longer than 1.5x median, longest " << fmt("%.6g", t.longest_interval_ns * 1e-6) << " ms";
  if (t.longest_interval_ns > 0)
    out << " (ending at t=" << fmt("%.6f", ns_to_s(t.longest_interval_at_ns)) << " s)";
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

int run_info(const std::string& path, bool as_json) {
  auto opened = log::SessionLogReader::open(path);
  if (!opened.ok()) {
    // Anything that prevents reading the log is an input problem, including a newer schema.
    throw CliExit{kExitInput, opened.error().message};
  }
  const log::SessionLogReader& log = **opened;

  json out;
  std::ostringstream text;
  out["path"] = path;
  const auto& meta = log.metadata();
  const auto meta_or = [&](const char* key) {
    const auto it = meta.find(key);
    return it == meta.end() ? std::string() : it->second;
  };
  text << "session log " << path << "\n";
  text << "  schema " << meta_or("schema_version") << ", written by imucal " << meta_or("software_version")
       << ", created " << meta_or("created_utc") << "\n";

  TimeNs t_start_ns = 0, t_end_ns = 0;
  bool any_time = false;
  const auto extend = [&](const StreamTiming& t) {
    if (t.count == 0) return;
    t_start_ns = any_time ? std::min(t_start_ns, t.t_first_ns) : t.t_first_ns;
    t_end_ns = any_time ? std::max(t_end_ns, t.t_last_ns) : t.t_last_ns;
    any_time = true;
  };

  json imu_json = json::array();
  std::ostringstream imu_text;
  for (const auto& [id, info] : log.imu_streams()) {
    std::vector<TimeNs> times;
    std::int64_t flagged_gap = 0, flagged_reset = 0, flagged_saturated = 0, flagged_estimated = 0;
    if (auto count = log.imu_count(id); count.ok()) times.reserve(static_cast<std::size_t>(*count));
    const Status read =
        log.for_each_imu(id, imucal::log::kTimeMin, imucal::log::kTimeMax, [&](const ImuSample& s) {
          times.push_back(s.t_ns);
          if (s.flags & kImuFlagGapBefore) ++flagged_gap;
          if (s.flags & kImuFlagDeviceReset) ++flagged_reset;
          if (s.flags & (kImuFlagAccelSaturated | kImuFlagGyroSaturated)) ++flagged_saturated;
          if (s.flags & kImuFlagTimeEstimated) ++flagged_estimated;
          return true;
        });
    const StreamTiming t = timing_of(times);
    extend(t);
    json j = {{"id", id},
              {"name", info.name},
              {"units", imu_units_name(info.units)},
              {"device", info.device},
              {"accel_full_scale_g", info.accel_full_scale_g},
              {"gyro_full_scale_dps", info.gyro_full_scale_dps},
              {"dlpf_hz", info.dlpf_hz},
              {"flagged_gap_samples", flagged_gap},
              {"flagged_reset_samples", flagged_reset},
              {"flagged_saturated_samples", flagged_saturated},
              {"flagged_time_estimated_samples", flagged_estimated},
              {"read_error", read.ok() ? std::string() : read.error().message}};
    j.update(timing_json(t, info.rate_hz));
    imu_json.push_back(j);
    imu_text << "  " << info.name << " (id " << id << ", "
             << (info.units == ImuUnits::kRaw ? "raw counts" : "SI units") << ", device "
             << (info.device.empty() ? "?" : info.device);
    if (info.accel_full_scale_g > 0) imu_text << ", accel +-" << info.accel_full_scale_g << " g";
    if (info.gyro_full_scale_dps > 0) imu_text << ", gyro +-" << info.gyro_full_scale_dps << " dps";
    if (info.dlpf_hz > 0) imu_text << ", DLPF " << info.dlpf_hz << " Hz";
    imu_text << ")\n" << timing_text(t, info.rate_hz, "samples");
    imu_text << "    flagged: " << flagged_gap << " after a gap, " << flagged_reset
             << " after a device reset, " << flagged_saturated << " saturated, " << flagged_estimated
             << " with estimated time\n";
    if (!read.ok()) imu_text << "    ERROR: " << read.error().message << "\n";
  }

  json cam_json = json::array();
  std::ostringstream cam_text;
  for (const auto& [id, info] : log.camera_streams()) {
    auto times = log.frame_times(id);
    const StreamTiming t = timing_of(times.ok() ? *times : std::vector<TimeNs>{});
    extend(t);
    json j = {{"id", id},
              {"name", info.name},
              {"width", info.width},
              {"height", info.height},
              {"backend", info.backend},
              {"device", info.device},
              {"timestamp_source", info.timestamp_source},
              {"read_error", times.ok() ? std::string() : times.error().message}};
    j.update(timing_json(t, info.rate_hz));
    cam_json.push_back(j);
    cam_text << "  " << info.name << " (id " << id << ", " << info.width << "x" << info.height << ", "
             << (info.backend.empty() ? "?" : info.backend) << " " << info.device << ", "
             << (info.timestamp_source.empty() ? "unknown" : info.timestamp_source) << " timestamps)\n"
             << timing_text(t, info.rate_hz, "frames");
    if (!times.ok()) cam_text << "    ERROR: " << times.error().message << "\n";
  }

  std::map<std::string, std::int64_t> events_by_kind;
  std::int64_t event_count = 0;
  if (auto events = log.events(); events.ok()) {
    for (const auto& e : *events) ++events_by_kind[e.kind];
    event_count = static_cast<std::int64_t>(events->size());
  }

  const auto& health = log.health();
  out["schema_version"] = meta_or("schema_version");
  out["software_version"] = meta_or("software_version");
  out["created_utc"] = meta_or("created_utc");
  out["complete"] = health.complete;
  out["damaged"] = health.damaged;
  out["damage_message"] = health.damage_message;
  out["t_start_ns"] = t_start_ns;
  out["t_end_ns"] = t_end_ns;
  out["duration_s"] = ns_to_s(t_end_ns - t_start_ns);
  out["imu_streams"] = imu_json;
  out["camera_streams"] = cam_json;
  out["events"] = {{"count", event_count}, {"by_kind", events_by_kind}};
  out["metadata"] = meta;

  text << "  status: "
       << (health.complete ? "complete"
                           : "INCOMPLETE (the writer did not close it; the recording was interrupted)")
       << (health.damaged ? ", DAMAGED" : "") << "\n";
  text << "  duration: " << fmt("%.3f", ns_to_s(t_end_ns - t_start_ns)) << " s";
  if (any_time) {
    text << " (t=" << fmt("%.6f", ns_to_s(t_start_ns)) << " s to " << fmt("%.6f", ns_to_s(t_end_ns)) << " s)";
  }
  text << "\n";
  text << "IMU streams: " << log.imu_streams().size() << "\n" << imu_text.str();
  text << "camera streams: " << log.camera_streams().size() << "\n" << cam_text.str();
  text << "events: " << event_count;
  if (!events_by_kind.empty()) {
    text << " (";
    bool first = true;
    for (const auto& [kind, n] : events_by_kind) {
      text << (first ? "" : ", ") << kind << " " << n;
      first = false;
    }
    text << ")";
  }
  text << "\nmetadata:\n";
  for (const auto& [key, value] : meta) text << "  " << key << ": " << one_line(value, 100) << "\n";

  std::cout << (as_json ? out.dump(2) : text.str()) << (as_json ? "\n" : "");
  std::cout.flush();
  if (health.damaged) {
    std::cerr
        << "imucal: WARNING: session log " << path << " is damaged: " << health.damage_message
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
