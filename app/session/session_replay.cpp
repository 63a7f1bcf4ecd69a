#include "app/session/session_replay.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>

#include "app/session/session_runner.hpp"
#include "log/session_log.hpp"

namespace imucal::app::session {

using nlohmann::json;

namespace {

/// How far after the last IMU sample a logged input may be stamped (the engine stamps with the
/// sample time it has reached; a write may end a little after the samples stop).
constexpr TimeNs kMaxInputAfterLastSampleNs = 10'000'000'000;

/// An input the live session applied to its engine, at the engine's sample time.
struct Input {
  TimeNs t_ns = 0;
  json message;
};

/// The engine's host during a replay: the logged preflight, solves run at once and held until
/// the log says they were applied, no storage.
class ReplayHost final : public EngineHost {
 public:
  ReplayHost(const RigConfig& config, const ImuStreamInfo& info, std::string dir, PreflightReport preflight,
             std::string motion_log)
      : config_(config),
        info_(info),
        dir_(std::move(dir)),
        preflight_(std::move(preflight)),
        motion_log_(std::move(motion_log)) {}

  void emit(const json& message) override {
    if (message.value("type", "") == "result") result_ = message;
    if (message.value("type", "") == "done") outcome_ = message.value("outcome", "");
  }
  PreflightReport preflight() override { return preflight_; }
  void solve(const SolveJob& job) override {
    SolveOutcome out = run_solve(job, config_, info_, dir_, nullptr, {motion_log_, false});
    outcomes_[job.id] = std::move(out);
  }
  void write(const CalibrationRecord&) override {}
  Status recover() override { return {}; }

  std::map<int, SolveOutcome> outcomes_;
  json result_;
  std::string outcome_;

 private:
  RigConfig config_;
  ImuStreamInfo info_;
  std::string dir_;
  PreflightReport preflight_;
  std::string motion_log_;
};

struct LoggedSession {
  std::vector<std::string> steps;
  PreflightReport preflight;
  std::vector<Input> inputs;
  json result;
  std::string outcome;
  std::vector<std::pair<double, std::string>> step_starts;  // rig time (s), step
  int final_id = 0;
  double final_wall_s = 0.0;
  double end_s = 0.0;
  TimeNs last_event_ns = log::kTimeMin;  // the latest stamp of any session event read
};

/// A field the replay reads from a logged event, the JSON kind it must have, and whether the
/// event means nothing without it.
struct Field {
  const char* name;
  json::value_t kind;  // number_integer stands for any integer, number_float for any number
  bool required;
};

bool has_kind(const json& v, json::value_t kind) {
  switch (kind) {
    case json::value_t::number_integer:
      return v.is_number_integer();
    case json::value_t::number_float:
      return v.is_number();
    default:
      return v.type() == kind;
  }
}

const char* kind_name(json::value_t kind) {
  switch (kind) {
    case json::value_t::string:
      return "a string";
    case json::value_t::boolean:
      return "true or false";
    case json::value_t::number_integer:
      return "an integer";
    case json::value_t::number_float:
      return "a number";
    case json::value_t::array:
      return "an array";
    default:
      return "an object";
  }
}

/// The fields of each event type the replay reads (docs/service-session.md, "Session log").
const std::map<std::string, std::vector<Field>>& replay_fields() {
  using V = json::value_t;
  static const std::map<std::string, std::vector<Field>> fields = {
      {"frame", {{"t_ns", V::number_integer, true}, {"seen", V::boolean, true}}},
      {"key", {{"key", V::string, true}}},
      {"fault", {{"source", V::string, false}, {"text", V::string, false}}},
      {"stop", {{"reason", V::string, false}}},
      {"written", {{"ok", V::boolean, true}, {"error", V::string, false}, {"where", V::string, false}}},
      {"applied", {{"id", V::number_integer, true}, {"wall_s", V::number_float, false}}},
      {"status", {{"state", V::string, false}, {"step", V::string, false}}},
      {"solve", {{"id", V::number_integer, false}, {"final", V::boolean, false}}},
      {"session", {{"event", V::string, false}, {"steps", V::array, false}}},
      {"preflight", {{"report", V::object, false}}},
      {"result", {}},
      {"done", {{"outcome", V::string, true}}},
  };
  return fields;
}

/// Why a logged event cannot be replayed as it stands, or empty.
std::string event_defect(const json& m, TimeNs t_ns) {
  const std::string where = "the session event at t_ns " + std::to_string(t_ns);
  if (m.is_discarded() || !m.is_object()) return where + " is not a JSON object";
  const auto type_it = m.find("type");
  if (type_it == m.end() || !type_it->is_string()) return where + " has no type (a string)";
  const auto fields = replay_fields().find(type_it->get<std::string>());
  if (fields == replay_fields().end()) return {};
  for (const Field& f : fields->second) {
    const auto it = m.find(f.name);
    if (it == m.end()) {
      if (f.required) return where + " (" + fields->first + ") has no \"" + f.name + "\"";
      continue;
    }
    if (!has_kind(*it, f.kind))
      return where + " (" + fields->first + "): \"" + f.name + "\" is " + it->type_name() + ", not " +
             kind_name(f.kind);
    if (fields->first == "session" && std::string(f.name) == "steps") {
      for (const auto& step : *it)
        if (!step.is_string()) return where + " (session): a step that is not a string";
    }
  }
  return {};
}

Result<LoggedSession> read_session_events(const log::SessionLogReader& reader, const std::string& path) {
  auto events = reader.events();
  if (!events.ok()) return events.error();
  LoggedSession s;
  bool started = false;
  // An event altered or cut short makes the replay a different session: refused, as damage.
  auto damaged = [&](const std::string& defect) {
    return make_error(Errc::kCorrupt, path + ": " + defect +
                                          ": the log was altered or is damaged, and cannot be replayed "
                                          "(imucal info shows what it holds)");
  };
  for (const auto& e : *events) {
    if (e.kind != "frame" && e.kind != "session") continue;
    json m = json::parse(e.message, nullptr, false);
    if (e.kind == "frame") {
      // What the engine saw of a camera frame in the motion step (the runner's frame event).
      if (m.is_object()) m["type"] = "frame";
      if (const std::string defect = event_defect(m, e.t_ns); !defect.empty()) return damaged(defect);
      s.inputs.push_back({e.t_ns, m});
      continue;
    }
    if (const std::string defect = event_defect(m, e.t_ns); !defect.empty()) return damaged(defect);
    const std::string type = m.value("type", "");
    const double t_s = static_cast<double>(e.t_ns) * 1e-9;
    s.last_event_ns = std::max(s.last_event_ns, e.t_ns);
    if (type == "status" && m.value("state", "") == "running" && !m.value("step", "").empty() &&
        (s.step_starts.empty() || s.step_starts.back().second != m.value("step", ""))) {
      s.step_starts.emplace_back(t_s, m.value("step", ""));
    }
    if (type == "solve" && m.value("final", false)) s.final_id = m.value("id", 0);
    if (type == "applied" && m.value("id", -1) == s.final_id) s.final_wall_s = m.value("wall_s", 0.0);
    s.end_s = t_s;
    if (type == "session" && m.value("event", "") == "start") {
      if (started) break;  // one session per log; a second start is not ours to replay
      started = true;
      for (const auto& n : m.value("steps", json::array()))
        if (n.is_string()) s.steps.push_back(n.get<std::string>());
    } else if (type == "preflight") {
      s.preflight = PreflightReport::from_json(m.value("report", json::object()));
    } else if (type == "key" || type == "applied" || type == "fault" || type == "written" || type == "stop") {
      s.inputs.push_back({e.t_ns, m});
    } else if (type == "result") {
      s.result = m;
    } else if (type == "done") {
      s.outcome = m.value("outcome", "");
    }
  }
  if (!started)
    return make_error(Errc::kInsufficientData,
                      "the log holds no service session (no session start event): only logs that imucald "
                      "wrote (sessions/*/session.imulog) can be replayed");
  return s;
}

double max_difference(const json& a, const json& b) {
  if (a.is_number() && b.is_number()) return std::abs(a.get<double>() - b.get<double>());
  if (a.is_array() && b.is_array() && a.size() == b.size()) {
    double m = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, max_difference(a[i], b[i]));
    return m;
  }
  if (a.is_object() && b.is_object()) {
    // Every key of either: a key only one of them has (an emptied result) is a difference.
    double m = 0.0;
    for (auto it = a.begin(); it != a.end(); ++it)
      m = std::max(m, b.contains(it.key()) ? max_difference(it.value(), b[it.key()]) : INFINITY);
    for (auto it = b.begin(); it != b.end(); ++it)
      if (!a.contains(it.key())) m = INFINITY;
    return m;
  }
  return a == b ? 0.0 : INFINITY;
}

/// Applies one logged input to the engine. False when the replay diverged.
bool apply(SessionEngine& engine, ReplayHost& host, const json& m, ReplaySummary& summary, std::string* why) {
  const std::string type = m.value("type", "");
  if (type == "frame") {
    engine.on_frame(m.value("camera", std::size_t{0}), m.value("t_ns", TimeNs{0}), m.value("seen", false));
  } else if (type == "key") {
    ++summary.keys;
    (void)engine.key(m.value("key", ""));
  } else if (type == "fault") {
    ++summary.faults;
    engine.fault(m.value("source", ""), m.value("text", ""));
  } else if (type == "stop") {
    engine.terminate(m.value("reason", ""));
  } else if (type == "written") {
    const bool ok = m.value("ok", false);
    engine.write_finished(ok ? Status{} : Status(make_error(Errc::kIo, m.value("error", ""))),
                          m.value("where", std::string()));
  } else if (type == "applied") {
    const int id = m.value("id", 0);
    auto it = host.outcomes_.find(id);
    if (it == host.outcomes_.end()) {
      *why = "the log applied solve " + std::to_string(id) + ", which the replay never requested";
      return false;
    }
    ++summary.solves;
    engine.solve_finished(id, std::move(it->second));
    host.outcomes_.erase(it);
  }
  return true;
}

/// The folder for the replay's result files: `out_dir` (created; a file there is a usage
/// error), or a new temporary folder.
Result<std::string> output_folder(const std::string& out_dir) {
  std::string dir = out_dir;
  std::error_code ec;
  if (!dir.empty() && std::filesystem::exists(dir, ec) && !std::filesystem::is_directory(dir, ec)) {
    return make_error(Errc::kInvalidArgument,
                      dir + " exists and is not a folder: give a folder for the replay's result files (-o)");
  }
  if (dir.empty()) {
    std::string tmpl = (std::filesystem::temp_directory_path() / "imucal-replay-XXXXXX").string();
    if (!mkdtemp(tmpl.data()))
      return make_error(Errc::kIo, "cannot create a temporary folder for the replay");
    dir = tmpl;
  }
  std::filesystem::create_directories(dir, ec);
  if (ec) return make_error(Errc::kIo, "cannot create " + dir + ": " + ec.message());
  return dir;
}

/// The live session's logged result against the replay's: the largest difference of the
/// canonical model's and the cameras' entries, or infinity when only one of them has a result.
void compare_results(const json& live, const json& replayed, ReplaySummary* summary) {
  if (live.is_null() && replayed.is_null()) return;
  summary->live_result = true;
  if (!live.is_null() && !replayed.is_null()) {
    summary->max_difference =
        std::max(max_difference(live.value("imu", json()), replayed.value("imu", json())),
                 max_difference(live.value("cameras", json()), replayed.value("cameras", json())));
    return;
  }
  summary->max_difference = INFINITY;
  summary->notes.push_back(live.is_null()
                               ? "the replay produced a result but the live session logged none (its "
                                 "result event is missing)"
                               : "the live session logged a result but the replay produced none");
}

}  // namespace

Result<ReplaySummary> replay_session(const ReplayOptions& options) {
  auto reader = log::SessionLogReader::open(options.log_path);
  if (!reader.ok()) return reader.error();
  if ((*reader)->health().damaged) {
    return make_error(Errc::kCorrupt,
                      options.log_path + " is damaged (" + (*reader)->health().damage_message +
                          "): a replay needs the whole session, and would not be the same one");
  }
  auto logged = read_session_events(**reader, options.log_path);
  if (!logged.ok()) return logged.error();
  const auto& meta = (*reader)->metadata();
  const auto cfg = meta.find("rig_config");
  if (cfg == meta.end())
    return make_error(Errc::kCorrupt, options.log_path + ": no rig_config in the log's metadata");
  auto config = parse_rig_config(cfg->second, options.log_path + " (rig_config)");
  // The configuration is part of the log here, not of the command line: damage, not usage.
  if (!config.ok()) return make_error(Errc::kCorrupt, config.error().message);
  auto stream = (*reader)->find_imu_stream();
  if (!stream.ok()) return stream.error();
  const ImuStreamInfo info = (*reader)->imu_streams().at(*stream);

  auto dir = output_folder(options.out_dir);
  if (!dir.ok()) return dir.error();

  const std::string motion_log =
      (std::filesystem::path(options.log_path).parent_path() / kMotionLogFile).string();
  if (std::find(logged->steps.begin(), logged->steps.end(), "motion") != logged->steps.end() &&
      !std::filesystem::exists(motion_log)) {
    return make_error(Errc::kNotFound, "the session ran the motion step, but its motion log " + motion_log +
                                           " is missing: replay reads it beside the session log (copy the "
                                           "whole session folder)");
  }
  ReplayHost host(*config, info, *dir, logged->preflight, motion_log);
  SessionEngine engine(*config, info, host);
  if (auto s = engine.start(logged->steps); !s.ok()) {
    // The steps come from the log: one the engine refuses is the log's defect, not usage.
    const Error e = s.error().context("starting the replayed session");
    if (e.code != Errc::kInvalidArgument) return e;
    return make_error(Errc::kCorrupt,
                      options.log_path + ": " + e.message +
                          ": the log was altered or written by another version, and cannot be "
                          "replayed");
  }

  ReplaySummary summary;
  std::size_t next = 0;
  std::string why;
  // Inputs logged before a sample go in before it; those after the last sample (up to
  // t = INT64_MAX), after it.
  auto apply_until = [&](std::optional<TimeNs> t_ns) {
    while (next < logged->inputs.size() && (!t_ns || logged->inputs[next].t_ns < *t_ns)) {
      if (!apply(engine, host, logged->inputs[next].message, summary, &why)) return false;
      ++next;
    }
    return true;
  };
  bool diverged = false;
  TimeNs last_sample_ns = log::kTimeMin;
  IMUCAL_TRY((*reader)->for_each_imu(*stream, log::kTimeMin, log::kTimeMax, [&](const ImuSample& s) {
    if (!apply_until(s.t_ns)) {
      diverged = true;
      return false;
    }
    engine.on_sample(s);
    last_sample_ns = s.t_ns;
    ++summary.samples;
    return true;
  }));
  // The engine stamps what it logs with the sample time it has reached: an event (an input, or
  // the result and the outcome) far after the last sample was not written by it.
  if (!diverged && summary.samples > 0 && logged->last_event_ns > last_sample_ns &&
      logged->last_event_ns - last_sample_ns > kMaxInputAfterLastSampleNs) {
    return make_error(Errc::kCorrupt,
                      options.log_path + ": a session event is stamped " +
                          std::to_string(static_cast<double>(logged->last_event_ns - last_sample_ns) * 1e-9) +
                          " s after the recording's last sample: the log was altered or is damaged, and "
                          "cannot be replayed");
  }
  if (!diverged && !apply_until(std::nullopt)) diverged = true;
  if (diverged) {
    return make_error(Errc::kSolverFailed,
                      "the replay diverged from the live session of " + options.log_path + ": " + why);
  }

  for (std::size_t i = 0; i < logged->step_starts.size(); ++i) {
    const double end = i + 1 < logged->step_starts.size() ? logged->step_starts[i + 1].first : logged->end_s;
    summary.step_times.push_back({logged->step_starts[i].second, end - logged->step_starts[i].first});
  }
  summary.live_final_solve_wall_s = logged->final_wall_s;
  summary.state = engine.state();
  summary.outcome = host.outcome_;
  summary.live_outcome = logged->outcome;
  if (engine.result() && engine.result()->imu) {
    summary.imu = engine.result()->imu;
    summary.result_files = engine.result()->result_files;
  }
  compare_results(logged->result, host.result_, &summary);
  return summary;
}

}  // namespace imucal::app::session
