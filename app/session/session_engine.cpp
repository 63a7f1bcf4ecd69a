// The session's flow: steps, keys, faults, solves, review and write. The per-sample work of the
// recording steps is in session_steps.cpp.
#include "app/session/session_engine.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

#include "app/initial_guess.hpp"
#include "app/session/session_window.hpp"
#include "core/text_format.hpp"

namespace imucal::app::session {

using nlohmann::json;

namespace {

constexpr StepId kAllSteps[] = {StepId::kPreflight, StepId::kWarmup, StepId::kThermal, StepId::kStill,
                                StepId::kPoses,     StepId::kGsens,  StepId::kMotion,  StepId::kSolve,
                                StepId::kReview,    StepId::kWrite};

}  // namespace

const char* step_name(StepId step) {
  switch (step) {
    case StepId::kPreflight:
      return "preflight";
    case StepId::kWarmup:
      return "warmup";
    case StepId::kThermal:
      return "thermal";
    case StepId::kStill:
      return "still";
    case StepId::kPoses:
      return "poses";
    case StepId::kGsens:
      return "gsens";
    case StepId::kMotion:
      return "motion";
    case StepId::kSolve:
      return "solve";
    case StepId::kReview:
      return "review";
    case StepId::kWrite:
      return "write";
  }
  return "?";
}

const char* step_state_name(StepState state) {
  switch (state) {
    case StepState::kPending:
      return "pending";
    case StepState::kActive:
      return "active";
    case StepState::kDone:
      return "done";
    case StepState::kSkipped:
      return "skipped";
    case StepState::kFailed:
      return "failed";
  }
  return "?";
}

const char* session_state_name(SessionState state) {
  switch (state) {
    case SessionState::kIdle:
      return "idle";
    case SessionState::kRunning:
      return "running";
    case SessionState::kReview:
      return "review";
    case SessionState::kDone:
      return "done";
    case SessionState::kAborted:
      return "aborted";
    case SessionState::kFailed:
      return "failed";
  }
  return "?";
}

Result<StepId> parse_step(const std::string& name) {
  for (StepId id : kAllSteps)
    if (name == step_name(id)) return id;
  std::string all;
  for (StepId id : kAllSteps) all += std::string(all.empty() ? "" : ", ") + step_name(id);
  return make_error(Errc::kInvalidArgument, "'" + name + "' is not a session step (" + all + ")");
}

std::vector<StepId> configured_steps(const RigConfig& config) {
  std::vector<StepId> out;
  if (!config.session.steps.empty()) {
    for (const auto& name : config.session.steps)
      if (auto id = parse_step(name); id.ok()) out.push_back(*id);
    return out;
  }
  for (StepId id : kAllSteps) {
    if (id == StepId::kGsens || id == StepId::kThermal) continue;
    if (id == StepId::kMotion && config.cameras.empty()) continue;
    out.push_back(id);
  }
  return out;
}

bool PreflightReport::ok() const {
  return std::all_of(devices.begin(), devices.end(), [](const Device& d) { return d.ok; });
}

json PreflightReport::to_json() const {
  json devs = json::array();
  for (const auto& d : devices) {
    devs.push_back({{"name", d.name}, {"ok", d.ok}, {"detail", d.detail}});
    if (!d.advice.empty()) devs.back()["advice"] = d.advice;
  }
  return {{"rig", rig}, {"devices", devs}, {"stored", stored ? *stored : json()}};
}

PreflightReport PreflightReport::from_json(const json& j) {
  PreflightReport r;
  r.rig = j.value("rig", "");
  for (const auto& d : j.value("devices", json::array()))
    r.devices.push_back(
        {d.value("name", ""), d.value("ok", false), d.value("detail", ""), d.value("advice", "")});
  if (j.contains("stored") && !j["stored"].is_null()) r.stored = j["stored"];
  return r;
}

SessionEngine::SessionEngine(const RigConfig& config, const ImuStreamInfo& info, EngineHost& host)
    : config_(config),
      guide_(config),
      info_(info),
      host_(host),
      window_(std::make_unique<Window>(info.rate_hz)),
      samples_(std::make_shared<std::vector<ImuSample>>()),
      thermal_(std::make_shared<std::vector<ImuSample>>()) {}

SessionEngine::~SessionEngine() = default;

Result<std::vector<StepId>> SessionEngine::plan(const std::vector<std::string>& names) const {
  if (running()) return make_error(Errc::kAlreadyExists, "a session is running; abort it first");
  std::vector<StepId> ids;
  if (names.empty()) {
    ids = configured_steps(config_);
  } else {
    for (const auto& n : names) {
      auto id = parse_step(n);
      if (!id.ok()) return id.error();
      if (!ids.empty() && *id <= ids.back())
        return make_error(Errc::kInvalidArgument, "step '" + n + "' is repeated or out of protocol order");
      if (*id == StepId::kMotion && config_.cameras.empty())
        return make_error(Errc::kInvalidArgument, "step 'motion' needs cameras; the configuration has none");
      ids.push_back(*id);
    }
  }
  const bool solves = std::find(ids.begin(), ids.end(), StepId::kSolve) != ids.end();
  for (StepId needs_solve : {StepId::kReview, StepId::kWrite}) {
    if (!solves && std::find(ids.begin(), ids.end(), needs_solve) != ids.end())
      return make_error(Errc::kInvalidArgument,
                        std::string("step '") + step_name(needs_solve) + "' needs the 'solve' step");
  }
  const bool poses = std::find(ids.begin(), ids.end(), StepId::kPoses) != ids.end();
  const bool thermal = std::find(ids.begin(), ids.end(), StepId::kThermal) != ids.end();
  if (solves && !poses && !thermal)
    return make_error(Errc::kInvalidArgument,
                      "step 'solve' needs the 'poses' step (the static calibration) or the 'thermal' step");
  // A thermal model is stored with the IMU calibration whose biases it refers to its reference
  // temperature: alone it has nothing to go with.
  if (!poses && std::find(ids.begin(), ids.end(), StepId::kWrite) != ids.end())
    return make_error(
        Errc::kInvalidArgument,
        "step 'write' needs the 'poses' step: a thermal model is stored with the IMU calibration "
        "it corrects (a thermal recording alone leaves its model in the session folder)");
  return ids;
}

Status SessionEngine::start(const std::vector<std::string>& names) {
  auto ids = plan(names);
  if (!ids.ok()) return ids.error();
  reset();
  for (StepId id : *ids) steps_.push_back({id});
  state_ = SessionState::kRunning;
  session_start_ns_ = now_ns_;
  emit({{"type", "session"}, {"event", "start"}, {"steps", names}});
  enter(0);
  return {};
}

void SessionEngine::reset() {
  steps_.clear();
  current_ = 0;
  waiting_ = failed_step_ = false;
  step_start_ns_ = session_start_ns_ = -1;
  last_live_ns_ = 0;
  last_prompt_ = last_live_ = json();
  last_messages_.clear();
  window_ = std::make_unique<Window>(info_.rate_hz);
  samples_ = std::make_shared<std::vector<ImuSample>>();
  recording_ = true;
  temps_.clear();
  thermal_ = std::make_shared<std::vector<ImuSample>>();
  thermal_sum_ = {};
  still_since_ns_ = -1;
  bias_known_ = false;
  still_gyro_sum_.setZero();
  still_count_ = 0;
  poses_.clear();
  need_motion_ = false;
  quick_pending_ = false;
  last_still_ns_ = 0;
  face_ = 0;
  quick_in_flight_ = 0;
  quick_poses_ = 0;
  quick_.reset();
  final_id_ = 0;
  final_.reset();
  gates_.clear();
  gates_pass_ = false;
}

void SessionEngine::emit(json message) {
  if (!message.contains("t")) message["t"] = static_cast<double>(now_ns_) * 1e-9;
  if (message["type"] == "prompt") last_prompt_ = message;
  if (message["type"] == "live") last_live_ = message;
  if (message["type"] == "message" || message["type"] == "fault") {
    last_messages_.push_back(message);
    if (last_messages_.size() > 8) last_messages_.pop_front();
  }
  host_.emit(message);
}

void SessionEngine::prompt(const std::string& text, std::vector<std::string> keys,
                           std::vector<std::string> art, const Eigen::Vector3d* up) {
  waiting_ = std::find(keys.begin(), keys.end(), "continue") != keys.end() ||
             std::find(keys.begin(), keys.end(), "accept") != keys.end();
  const char* step = current_ < steps_.size() ? step_name(steps_[current_].id) : "";
  json m = {{"type", "prompt"}, {"step", step}, {"text", text}, {"keys", std::move(keys)}};
  if (!art.empty()) m["art"] = std::move(art);
  if (up) m["up"] = {up->x(), up->y(), up->z()};
  emit(std::move(m));
}

void SessionEngine::live(std::vector<std::string> lines, double progress, json figures) {
  const char* step = current_ < steps_.size() ? step_name(steps_[current_].id) : "";
  json m = {{"type", "live"}, {"step", step}, {"lines", std::move(lines)}, {"progress", progress}};
  if (!figures.is_null()) m["figures"] = std::move(figures);
  emit(std::move(m));
}

void SessionEngine::message(const std::string& level, const std::string& text) {
  emit({{"type", "message"}, {"level", level}, {"text", text}});
}

json SessionEngine::status() const {
  json steps = json::array();
  for (const auto& s : steps_)
    steps.push_back({{"name", step_name(s.id)}, {"state", step_state_name(s.state)}});
  json j = {
      {"type", "status"},
      {"state", session_state_name(state_)},
      {"rig", config_.name},
      {"steps", steps},
      {"step", current_ < steps_.size() && running() ? step_name(steps_[current_].id) : ""},
      {"poses", poses_.size()},
      {"elapsed_s", session_start_ns_ < 0 ? 0.0 : static_cast<double>(now_ns_ - session_start_ns_) * 1e-9}};
  return j;
}

std::vector<json> SessionEngine::snapshot() const {
  std::vector<json> out = {status()};
  for (const auto& m : last_messages_) out.push_back(m);
  if (!last_prompt_.is_null()) out.push_back(last_prompt_);
  if (!last_live_.is_null()) out.push_back(last_live_);
  return out;
}

bool SessionEngine::step_skippable(StepId id) const {
  return id == StepId::kWarmup || id == StepId::kThermal || id == StepId::kGsens || id == StepId::kMotion ||
         id == StepId::kWrite;
}

void SessionEngine::enter(std::size_t index) {
  current_ = index;
  if (current_ >= steps_.size()) {
    const bool written = std::any_of(steps_.begin(), steps_.end(), [](const Step& s) {
      return s.id == StepId::kWrite && s.state == StepState::kDone;
    });
    if (written) {
      finish(SessionState::kDone, "written", "The calibration was written, read back and verified.");
    } else {
      finish(SessionState::kDone, final_ ? "completed" : "recorded",
             final_ ? "The session is complete; the calibration was not written (no write step)."
                    : "The session is complete; nothing was solved (no solve step).");
    }
    return;
  }
  steps_[current_].state = StepState::kActive;
  waiting_ = failed_step_ = false;
  step_start_ns_ = now_ns_;
  emit(status());
  begin_step();
}

void SessionEngine::advance() {
  if (current_ < steps_.size() && steps_[current_].state == StepState::kActive)
    steps_[current_].state = StepState::kDone;
  enter(current_ + 1);
}

void SessionEngine::finish(SessionState state, const std::string& outcome, const std::string& text) {
  if (recording_) {
    recording_ = false;
    host_.recording_finished();
  }
  state_ = state;
  waiting_ = false;
  emit(status());
  json done = {{"type", "done"}, {"outcome", outcome}, {"text", text}};
  // Where the record went (storage, slot, sequence), named on the end screen.
  if (outcome == "written" && !written_to_.empty()) done["stored"] = written_to_;
  // The reports to open, when the final solve drew them.
  if (final_) {
    json reports = json::array();
    for (const auto& f : final_->result_files)
      if (f.size() > 5 && f.compare(f.size() - 5, 5, ".html") == 0) reports.push_back(f);
    if (!reports.empty()) done["reports"] = reports;
  }
  emit(done);
}

void SessionEngine::begin_step() {
  const StepId id = steps_[current_].id;
  switch (id) {
    case StepId::kPreflight:
      run_preflight();
      break;
    case StepId::kWarmup:
      temps_.clear();
      prompt(thermal_planned() ? "Warming up: leave the rig still until the IMU's temperature settles; the "
                                 "warm-up is recorded for the thermal model"
                               : "Warming up: leave the rig still until the IMU's temperature settles",
             {"skip", "abort"});
      break;
    case StepId::kThermal:
      // A warm-up just before goes on into this step: its recording is kept.
      temps_.clear();
      prompt(
          "Thermal: leave the rig still while it warms up (or cools down); the bias is fitted against "
          "the die temperature. c ends the recording",
          {"continue", "skip", "abort"});
      break;
    case StepId::kStill:
      still_since_ns_ = -1;
      samples_->clear();
      prompt("Keep the rig still for " + fixed(config_.session.still_s, 0) + " s", {"abort"});
      break;
    case StepId::kPoses:
      // The attitude of the still start is not a pose (the static method counts it apart): the
      // first pose comes after the first turn.
      need_motion_ = true;
      poses_prompt();
      break;
    case StepId::kGsens:
      face_ = 0;
      need_motion_ = false;
      still_since_ns_ = -1;
      face_prompt();
      break;
    case StepId::kMotion:
      gyro_sq_ = accel_sum_ = accel_sq_ = Eigen::Vector3d::Zero();
      motion_count_ = frames_ = frames_seen_ = saturated_ = frames_shared_ = 0;
      last_seen_ns_ = last_shared_ns_ = -1;
      camera_frames_.assign(config_.cameras.size(), 0);
      camera_seen_.assign(config_.cameras.size(), 0);
      camera_last_seen_ns_.assign(config_.cameras.size(), -1);
      prompt("Move the rig in front of the target: rotate about every axis and move along every axis, for " +
                 fixed(config_.session.motion_s, 0) + " s",
             {"continue", "skip", "abort"});
      break;
    case StepId::kSolve:
      request_final_solve();
      break;
    case StepId::kReview:
      review();
      break;
    case StepId::kWrite:
      if (!gates_pass_ &&
          std::none_of(steps_.begin(), steps_.end(), [](const Step& s) { return s.id == StepId::kReview; })) {
        steps_[current_].state = StepState::kFailed;
        finish(SessionState::kFailed, "failed",
               "Not written: a quality gate failed and there is no review step to accept it.");
        return;
      }
      if (!final_ || !final_->record) {
        steps_[current_].state = StepState::kFailed;
        finish(SessionState::kFailed, "failed", "Nothing to write: the solve produced no record.");
        return;
      }
      prompt("Writing the calibration to the rig's storage", {});
      host_.write(*final_->record);
      break;
  }
}

void SessionEngine::run_preflight() {
  const PreflightReport report = host_.preflight();
  stored_ = report.stored ? *report.stored : json();
  emit({{"type", "preflight"}, {"report", report.to_json()}});
  std::vector<std::string> lines;
  for (const auto& d : report.devices)
    lines.push_back((d.ok ? "ok    " : "FAIL  ") + d.name + ": " + d.detail);
  lines.push_back(report.stored
                      ? "stored calibration: " + report.stored->value("summary", std::string("present"))
                      : "stored calibration: none");
  live(lines, 1.0, report.to_json());
  if (!report.ok()) {
    steps_[current_].state = StepState::kFailed;
    failed_step_ = true;
    emit(status());
    // The device's own advice when it has one (a self-test spoilt by motion: hold the rig still).
    std::string advice;
    for (const auto& d : report.devices)
      if (!d.ok && !d.advice.empty()) advice += (advice.empty() ? "" : "; ") + d.name + ": " + d.advice;
    prompt(advice.empty()
               ? "A device failed its check (see above). Fix it and press r to check again, or a to abort"
               : "A device failed its check: " + advice + ". Then press r to check again, or a to abort",
           {"redo", "abort"});
    return;
  }
  prompt("Rig '" + report.rig + "': every device answers. Press c to begin", {"continue", "abort"});
}

Status SessionEngine::key(const std::string& key) {
  static const std::vector<std::string> kKeys = {"continue", "redo", "abort", "accept", "reject", "skip"};
  if (std::find(kKeys.begin(), kKeys.end(), key) == kKeys.end())
    return make_error(Errc::kInvalidArgument,
                      "'" + key + "' is not a key (continue, redo, abort, accept, reject, skip)");
  if (!running()) return make_error(Errc::kInvalidArgument, "no session is running (start one first)");
  emit({{"type", "key"}, {"key", key}});
  const StepId id = steps_[current_].id;
  if (key == "abort") {
    steps_[current_].state = StepState::kFailed;
    finish(SessionState::kAborted, "aborted",
           "Aborted by the operator. What was recorded is kept; the stored calibration is unchanged.");
    return {};
  }
  if (key == "redo") {
    if (failed_step_) {
      if (auto s = host_.recover(); !s.ok()) {
        message("error", "Still failing: " + s.error().message);
        return {};
      }
      steps_[current_].state = StepState::kActive;
      failed_step_ = false;
      emit(status());  // the step is no longer marked failed
      message("info", std::string("Redoing step ") + step_name(id));
      begin_step();
      return {};
    }
    if (id == StepId::kPoses && !poses_.empty()) {
      poses_.pop_back();
      message("info", "Dropped pose " + std::to_string(poses_.size() + 1) + "; " +
                          std::to_string(poses_.size()) + " remain");
      poses_prompt();
      return {};
    }
    if (id == StepId::kGsens) {
      face_ = std::max(0, face_ - 1);
      still_since_ns_ = -1;
      message("info", "Redoing the last face");
      face_prompt();
      return {};
    }
    return make_error(Errc::kInvalidArgument, std::string("nothing to redo in step ") + step_name(id));
  }
  if (key == "skip") {
    if (!step_skippable(id))
      return make_error(Errc::kInvalidArgument, std::string("step ") + step_name(id) + " cannot be skipped");
    steps_[current_].state = StepState::kSkipped;
    message("info", std::string("Skipped step ") + step_name(id));
    if (id == StepId::kThermal) thermal_->clear();  // skipped: no thermal model
    enter(current_ + 1);
    return {};
  }
  if (key == "continue") {
    if (failed_step_) return make_error(Errc::kInvalidArgument, "the step failed: redo it (r) or abort (a)");
    if (id == StepId::kPreflight || id == StepId::kMotion) {
      advance();
      return {};
    }
    if (id == StepId::kThermal) {
      end_thermal("ended by the operator");
      return {};
    }
    if (id == StepId::kPoses) {
      if (static_cast<int>(poses_.size()) < config_.session.poses_min) {
        message("warning", "Only " + std::to_string(poses_.size()) + " poses; at least " +
                               std::to_string(config_.session.poses_min) + " are needed");
        return {};
      }
      advance();
      return {};
    }
    return make_error(Errc::kInvalidArgument, std::string("step ") + step_name(id) + " goes on by itself");
  }
  // accept / reject: the review.
  if (id != StepId::kReview)
    return make_error(Errc::kInvalidArgument, "there is nothing to accept or reject yet");
  if (key == "reject") {
    finish(SessionState::kDone, "rejected",
           "Rejected: the results are kept in the session folder; the stored calibration is unchanged.");
    return {};
  }
  if (!final_ || !final_->error.empty())
    return make_error(Errc::kInvalidArgument, "the solve failed; there is nothing to accept");
  advance();
  return {};
}

void SessionEngine::fault(const std::string& source, const std::string& text) {
  if (!running()) return;
  emit({{"type", "fault"},
        {"source", source},
        {"step", step_name(steps_[current_].id)},
        {"text", text},
        {"advice",
         "What was recorded is kept. Fix the " + source + " and press r to redo the step, or a to abort"}});
  steps_[current_].state = StepState::kFailed;
  failed_step_ = true;
  emit(status());
  prompt(source + " fault: " + text + ". Press r to redo the step once fixed, or a to abort",
         {"redo", "abort"});
}

void SessionEngine::terminate(const std::string& reason) {
  if (!running()) return;
  emit({{"type", "stop"}, {"reason", reason}});
  steps_[current_].state = StepState::kFailed;
  finish(SessionState::kAborted, "aborted",
         "Stopped: " + reason + ". What was recorded is kept; the stored calibration is unchanged.");
}

calib::StaticCalibrationOptions SessionEngine::static_options() const {
  calib::StaticCalibrationOptions o;
  o.init_still_s = std::max(config_.session.still_s, o.min_init_still_s);
  if (auto guess = nominal_guess(info_, {}); guess.ok()) {
    o.accel_init = guess->accel;
    o.gyro_init = guess->gyro;
  }
  return o;
}

void SessionEngine::request_quick_solve() {
  if (quick_in_flight_ != 0 || static_cast<int>(poses_.size()) < 9) return;
  SolveJob job;
  job.id = next_solve_id_++;
  job.samples = std::make_shared<const std::vector<ImuSample>>(*samples_);
  job.static_options = static_options();
  job.t_end_ns = now_ns_;
  quick_in_flight_ = job.id;
  quick_poses_ = poses_.size();
  emit({{"type", "solve"}, {"id", job.id}, {"final", false}, {"samples", job.samples->size()}});
  host_.solve(job);
}

void SessionEngine::request_final_solve() {
  if (recording_) {
    recording_ = false;
    host_.recording_finished();
  }
  SolveJob job;
  job.id = next_solve_id_++;
  job.final = true;
  const bool poses =
      std::any_of(steps_.begin(), steps_.end(), [](const Step& s) { return s.id == StepId::kPoses; });
  job.samples = std::make_shared<const std::vector<ImuSample>>(poses ? *samples_ : std::vector<ImuSample>());
  if (!thermal_->empty()) job.thermal_samples = std::make_shared<const std::vector<ImuSample>>(*thermal_);
  job.static_options = static_options();
  job.camimu = std::any_of(steps_.begin(), steps_.end(), [](const Step& s) {
    return s.id == StepId::kMotion && s.state == StepState::kDone;
  });
  job.t_end_ns = now_ns_;
  final_id_ = job.id;
  const std::size_t thermal_means = job.thermal_samples ? job.thermal_samples->size() : 0;
  emit({{"type", "solve"},
        {"id", job.id},
        {"final", true},
        {"samples", job.samples->size()},
        {"thermal_means", thermal_means},
        {"camimu", job.camimu}});
  std::string what = poses ? std::to_string(job.samples->size()) + " samples" : std::string();
  if (thermal_means > 0) what += (what.empty() ? "" : ", ") + std::string("the thermal recording");
  if (job.camimu) what += " and the camera frames";
  prompt("Solving: " + what, {"abort"});
  host_.solve(job);
}

void SessionEngine::solve_progress(double fraction, const std::string& text) {
  if (!running() || current_ >= steps_.size() || steps_[current_].id != StepId::kSolve) return;
  live({text}, fraction);
}

void SessionEngine::solve_finished(int id, SolveOutcome outcome) {
  emit({{"type", "applied"}, {"id", id}, {"error", outcome.error}, {"wall_s", outcome.wall_s}});
  if (!running()) return;
  if (id == quick_in_flight_) {
    quick_in_flight_ = 0;
    if (!outcome.error.empty() || !outcome.imu) {
      // Feedback only: the final solve decides. The method's advice for a whole recording does
      // not apply mid-session, so only its finding is shown.
      const std::string finding = outcome.error.substr(0, outcome.error.find(';'));
      message("info", "No quick solve yet after " + std::to_string(quick_poses_) + " poses (" + finding +
                          "); go on with the poses");
      return;
    }
    quick_ = std::move(outcome.imu);
    const auto rel = [](const Eigen::Vector3d& sigma, const Eigen::Vector3d& scale) {
      return sigma.cwiseQuotient(scale.cwiseAbs()).maxCoeff();
    };
    const double sa = rel(quick_->accel_sigma.scale, quick_->model.accel.scale);
    const double sg = rel(quick_->gyro_sigma.scale, quick_->model.gyro.scale);
    auto sigma = [](double v) {
      return std::isfinite(v) ? fixed(v * 1e3, 2) + "e-3" : std::string("undetermined");
    };
    message("info", "Quick solve (" + std::to_string(quick_poses_) + " poses): scale sigma accel " +
                        sigma(sa) + ", gyro " + sigma(sg) + " (target " +
                        fixed(config_.session.pose_sigma_target * 1e3, 2) + "e-3)");
    // New poses came while it ran: solve again with them.
    if (poses_.size() > quick_poses_ && !quick_pending_) request_quick_solve();
    return;
  }
  if (id != final_id_) return;
  final_ = std::move(outcome);
  if (final_->error.empty()) {
    evaluate_gates();
    emit(result_message());
  }
  if (!final_->error.empty()) {
    steps_[current_].state = StepState::kFailed;
    finish(SessionState::kFailed, "failed",
           "The solve failed: " + final_->error + ". The recording is kept; replay it with `imucal replay`.");
    return;
  }
  advance();
}

json SessionEngine::result_message() const {
  json m = {{"type", "result"}, {"files", final_->result_files}};
  auto mat = [](const Eigen::Matrix3d& M) {
    return json::array(
        {{M(0, 0), M(0, 1), M(0, 2)}, {M(1, 0), M(1, 1), M(1, 2)}, {M(2, 0), M(2, 1), M(2, 2)}});
  };
  auto vec = [](const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); };
  if (final_->thermal) {
    const auto& t = *final_->thermal;
    m["thermal"] = {{"determined", t.determined}};
    if (t.determined) {
      m["thermal"]["reference_c"] = t.reference_c;
      m["thermal"]["valid_range_c"] = {t.temp_min_c, t.temp_max_c};
    } else {
      m["thermal"]["reason"] = t.reason;
    }
  }
  if (final_->imu) {
    const auto& c = final_->imu->canonical;
    m["imu"] = {
        {"A_a", mat(c.A_a)}, {"b_a", vec(c.b_a)}, {"A_g", mat(c.A_g)}, {"b_g", vec(c.b_g)}, {"G", mat(c.G)}};
  }
  if (final_->camimu) {
    json cams = json::array();
    for (const auto& cam : final_->camimu->result.cameras) {
      const Eigen::Quaterniond q(cam.T_cam_imu.rotation());
      cams.push_back({{"name", cam.name},
                      {"t_cam_imu_m", vec(cam.T_cam_imu.translation())},
                      {"q_cam_imu_wxyz", {q.w(), q.x(), q.y(), q.z()}},
                      {"timeshift_cam_imu_s", cam.timeshift_cam_imu_s},
                      {"reprojection_rms_px", cam.reprojection_rms_px}});
    }
    m["cameras"] = cams;
    const SplitCheck& sc = final_->camimu->result.self_check;
    if (sc.verdict != SplitCheck::Verdict::kNotRun)
      m["self_check"] = {
          {"verdict", split_check_verdict_name(sc.verdict)}, {"summary", sc.summary}, {"advice", sc.advice}};
  }
  return m;
}

void SessionEngine::write_finished(const Status& status, const std::string& where) {
  written_to_ = status.ok() ? where : std::string();
  emit({{"type", "written"},
        {"ok", status.ok()},
        {"error", status.ok() ? "" : status.error().message},
        {"where", written_to_}});
  if (!running() || steps_[current_].id != StepId::kWrite) return;
  if (!status.ok()) {
    fault("storage", status.error().message);
    return;
  }
  advance();
}

}  // namespace imucal::app::session
