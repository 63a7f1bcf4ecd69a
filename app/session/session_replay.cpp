// SPDX-License-Identifier: BSD-3-Clause
#include "app/session/session_replay.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <variant>

#include "app/session/session_runner.hpp"
#include "log/session_log.hpp"

namespace imucal::app::session {

namespace msg = session_msg;

namespace {

/// How far after the last IMU sample a logged input may be stamped (the engine stamps with the
/// sample time it has reached; a write may end a little after the samples stop).
constexpr TimeNs kMaxInputAfterLastSampleNs = 10'000'000'000;

/// An input the live session applied to its engine, at the engine's sample time: a message it
/// logged or what the engine saw of a camera frame.
struct Input {
  TimeNs t_ns = 0;
  std::variant<msg::SessionMessage, msg::FrameEvent> message;
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

  void emit(const msg::SessionMessage& message) override {
    if (const auto* r = std::get_if<msg::ResultSummary>(&message)) result_ = *r;
    if (const auto* d = std::get_if<msg::Done>(&message)) outcome_ = msg::outcome_name(d->outcome);
  }
  PreflightReport preflight() override { return preflight_; }
  void solve(const SolveJob& job) override {
    SolveOutcome out = run_solve(job, config_, info_, dir_, nullptr, {motion_log_, false});
    outcomes_[job.id] = std::move(out);
  }
  void write(const CalibrationRecord&) override {}
  Status recover() override { return {}; }

  std::map<int, SolveOutcome> outcomes_;
  std::optional<msg::ResultSummary> result_;
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
  std::optional<msg::ResultSummary> result;
  std::string result_defect;  // the logged result could not be read: why
  std::string outcome;
  std::vector<std::pair<double, std::string>> step_starts;  // rig time (s), step
  int final_id = 0;
  double final_wall_s = 0.0;
  double end_s = 0.0;
  TimeNs last_event_ns = log::kTimeMin;  // the latest stamp of any session event read
};

/// Whether the replay reads events of this type: one of them that cannot be decoded makes the
/// log one that cannot be replayed. The others (prompts, live figures, messages, ...) only
/// informed the operator.
bool replay_reads(const std::string& type) {
  static const char* const kTypes[] = {"key",    "fault", "stop",    "written",   "applied",
                                       "status", "solve", "session", "preflight", "done"};
  return std::any_of(std::begin(kTypes), std::end(kTypes), [&](const char* t) { return type == t; });
}

/// What the replay takes from one logged session event.
void take_event(LoggedSession& s, const msg::SessionMessage& m, TimeNs t_ns, bool* started,
                bool* second_start) {
  const double t_s = static_cast<double>(t_ns) * 1e-9;
  if (const auto* st = std::get_if<msg::Status>(&m)) {
    if (st->state == SessionState::kRunning && st->step &&
        (s.step_starts.empty() || s.step_starts.back().second != step_name(*st->step)))
      s.step_starts.emplace_back(t_s, step_name(*st->step));
  }
  if (const auto* solve = std::get_if<msg::Solve>(&m); solve && solve->final) s.final_id = solve->id;
  if (const auto* a = std::get_if<msg::Applied>(&m); a && a->id == s.final_id) s.final_wall_s = a->wall_s;
  s.end_s = t_s;
  if (const auto* start = std::get_if<msg::SessionStart>(&m)) {
    if (*started) {
      *second_start = true;  // one session per log; a second start is not ours to replay
      return;
    }
    *started = true;
    s.steps = start->steps;
  } else if (const auto* p = std::get_if<msg::Preflight>(&m)) {
    s.preflight = p->report;
  } else if (std::holds_alternative<msg::Key>(m) || std::holds_alternative<msg::Applied>(m) ||
             std::holds_alternative<msg::Fault>(m) || std::holds_alternative<msg::Written>(m) ||
             std::holds_alternative<msg::Stop>(m)) {
    s.inputs.push_back({t_ns, m});
  } else if (const auto* r = std::get_if<msg::ResultSummary>(&m)) {
    s.result = *r;
  } else if (const auto* d = std::get_if<msg::Done>(&m)) {
    s.outcome = msg::outcome_name(d->outcome);
  }
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
  bool second_start = false;
  for (const auto& e : *events) {
    const std::string where = "the session event at t_ns " + std::to_string(e.t_ns);
    if (e.kind == "frame") {
      // What the engine saw of a camera frame in the motion step (the runner's frame event).
      auto frame = msg::parse_frame_event(e.message);
      if (!frame.ok()) return damaged(where + ": " + frame.error().message);
      s.inputs.push_back({e.t_ns, *frame});
      continue;
    }
    if (e.kind != "session") continue;
    auto m = msg::parse(e.message);
    if (!m.ok()) {
      const std::string type = msg::type_of(e.message);
      // A result that cannot be read is a result that differs from the replay's (below).
      if (type == "result") {
        s.result_defect = m.error().message;
        s.result.reset();
        continue;
      }
      if (type.empty() || replay_reads(type)) return damaged(where + ": " + m.error().message);
      continue;
    }
    s.last_event_ns = std::max(s.last_event_ns, e.t_ns);
    take_event(s, *m, e.t_ns, &started, &second_start);
    if (second_start) break;
  }
  if (!started)
    return make_error(Errc::kInsufficientData,
                      "the log holds no service session (no session start event): only logs that imucald "
                      "wrote (sessions/*/session.imulog) can be replayed");
  return s;
}

/// The largest |a - b| over the entries of two vectors or matrices of the same shape.
template <typename A, typename B>
double max_difference(const Eigen::MatrixBase<A>& a, const Eigen::MatrixBase<B>& b) {
  return (a - b).cwiseAbs().maxCoeff();
}

/// The largest difference of the canonical model's and the cameras' entries; infinity when one
/// has a part the other has not, or a camera of another name.
double max_difference(const msg::ResultSummary& a, const msg::ResultSummary& b) {
  double m = 0.0;
  if (a.imu.has_value() != b.imu.has_value()) return INFINITY;
  if (a.imu) {
    const auto &x = *a.imu, &y = *b.imu;
    m = std::max({max_difference(x.A_a, y.A_a), max_difference(x.b_a, y.b_a), max_difference(x.A_g, y.A_g),
                  max_difference(x.b_g, y.b_g), max_difference(x.G, y.G)});
  }
  if (a.cameras.has_value() != b.cameras.has_value()) return INFINITY;
  if (!a.cameras) return m;
  if (a.cameras->size() != b.cameras->size()) return INFINITY;
  for (std::size_t i = 0; i < a.cameras->size(); ++i) {
    const auto &x = (*a.cameras)[i], &y = (*b.cameras)[i];
    if (x.name != y.name) return INFINITY;
    m = std::max({m, max_difference(x.t_cam_imu_m, y.t_cam_imu_m),
                  max_difference(x.q_cam_imu_wxyz, y.q_cam_imu_wxyz),
                  std::abs(x.timeshift_cam_imu_s - y.timeshift_cam_imu_s),
                  std::abs(x.reprojection_rms_px - y.reprojection_rms_px)});
  }
  return m;
}

/// Applies one logged input to the engine. False when the replay diverged.
bool apply(SessionEngine& engine, ReplayHost& host, const Input& input, ReplaySummary& summary,
           std::string* why) {
  if (const auto* frame = std::get_if<msg::FrameEvent>(&input.message)) {
    engine.on_frame(frame->camera, frame->t_ns, frame->seen);
    return true;
  }
  const auto& m = std::get<msg::SessionMessage>(input.message);
  if (const auto* key = std::get_if<msg::Key>(&m)) {
    ++summary.keys;
    (void)engine.key(key->key);
  } else if (const auto* fault = std::get_if<msg::Fault>(&m)) {
    ++summary.faults;
    engine.fault(fault->source, fault->text);
  } else if (const auto* stop = std::get_if<msg::Stop>(&m)) {
    engine.terminate(stop->reason);
  } else if (const auto* written = std::get_if<msg::Written>(&m)) {
    engine.write_finished(written->ok ? Status{} : Status(make_error(Errc::kIo, written->error)),
                          written->where.value_or(std::string()));
  } else if (const auto* applied = std::get_if<msg::Applied>(&m)) {
    const int id = applied->id;
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
void compare_results(const LoggedSession& logged, const std::optional<msg::ResultSummary>& replayed,
                     ReplaySummary* summary) {
  const auto& live = logged.result;
  if (!logged.result_defect.empty()) {
    summary->live_result = true;
    summary->max_difference = INFINITY;
    summary->notes.push_back("the live session's logged result cannot be read (" + logged.result_defect +
                             ")");
    return;
  }
  if (!live && !replayed) return;
  summary->live_result = true;
  if (live && replayed) {
    summary->max_difference = max_difference(*live, *replayed);
    return;
  }
  summary->max_difference = INFINITY;
  summary->notes.push_back(!live ? "the replay produced a result but the live session logged none (its "
                                   "result event is missing)"
                                 : "the live session logged a result but the replay produced none");
}

/// The motion log beside the session log, when the session began its motion step (planned is
/// not run: a session that ended before that step has none).
Status check_motion_log(const LoggedSession& logged, const std::string& motion_log) {
  const bool motion_ran = std::any_of(logged.step_starts.begin(), logged.step_starts.end(),
                                      [](const auto& start) { return start.second == "motion"; });
  if (!motion_ran || std::filesystem::exists(motion_log)) return {};
  return make_error(Errc::kNotFound,
                    "the session ran the motion step, but its motion log " + motion_log +
                        " is missing: replay reads it beside the session log (copy the whole "
                        "session folder)");
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
  IMUCAL_TRY(check_motion_log(*logged, motion_log));
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
      if (!apply(engine, host, logged->inputs[next], summary, &why)) return false;
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
  compare_results(*logged, host.result_, &summary);
  return summary;
}

}  // namespace imucal::app::session
