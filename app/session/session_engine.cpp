// SPDX-License-Identifier: BSD-3-Clause
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
using session_msg::MessageLevel;
using session_msg::Outcome;
using K = session_msg::OperatorKey;

std::vector<StepId> configured_steps(const RigConfig& config) {
  std::vector<StepId> out;
  if (!config.session.steps.empty()) {
    for (const auto& name : config.session.steps)
      if (auto id = parse_step(name); id.ok()) out.push_back(*id);
    return out;
  }
  for (StepId id : session_msg::all_steps()) {
    if (id == StepId::kGsens || id == StepId::kThermal) continue;
    if (id == StepId::kMotion && config.cameras.empty()) continue;
    out.push_back(id);
  }
  return out;
}

SessionEngine::SessionEngine(const RigConfig& config, const ImuStreamInfo& info, EngineHost& host)
    : config_(config),
      guide_(config),
      info_(info),
      host_(host),
      window_(std::make_unique<Window>(info.rate_hz)),
      samples_(std::make_shared<std::vector<ImuSample>>()) {}

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
  for (StepId id : *ids) progress_.steps.push_back({id});
  state_ = SessionState::kRunning;
  session_start_ns_ = now_ns_;
  emit(session_msg::SessionStart{std::nullopt, names});
  enter(0);
  return {};
}

void SessionEngine::reset() {
  progress_ = {};
  operator_since_ns_ = -1;
  sampled_ = false;
  session_start_ns_ = session_end_ns_ = -1;
  last_live_ns_ = 0;
  last_prompt_.reset();
  last_live_.reset();
  last_messages_.clear();
  window_ = std::make_unique<Window>(info_.rate_hz);
  samples_ = std::make_shared<std::vector<ImuSample>>();
  recording_ = true;
  warmup_ = {};
  thermal_ = {};
  still_ = {};
  pose_ = {};
  solve_ = {};
}

void SessionEngine::emit(SessionMessage message) {
  if (!session_msg::time_of(message)) session_msg::set_time(message, static_cast<double>(now_ns_) * 1e-9);
  if (std::holds_alternative<session_msg::Prompt>(message)) last_prompt_ = message;
  if (std::holds_alternative<session_msg::Live>(message)) last_live_ = message;
  if (std::holds_alternative<session_msg::Message>(message) ||
      std::holds_alternative<session_msg::Fault>(message)) {
    last_messages_.push_back(message);
    if (last_messages_.size() > 8) last_messages_.pop_front();
  }
  host_.emit(message);
}

std::optional<StepId> SessionEngine::step_now() const {
  if (progress_.current < progress_.steps.size()) return progress_.steps[progress_.current].id;
  return std::nullopt;
}

void SessionEngine::prompt(const std::string& text, std::vector<K> keys, std::vector<std::string> art,
                           const Eigen::Vector3d* up) {
  progress_.waiting = std::find(keys.begin(), keys.end(), K::kContinue) != keys.end() ||
                      std::find(keys.begin(), keys.end(), K::kAccept) != keys.end();
  operator_since_ns_ = now_ns_;
  session_msg::Prompt m;
  m.step = step_now();
  m.text = text;
  m.keys = std::move(keys);
  m.art = std::move(art);
  if (up) m.up = *up;
  emit(std::move(m));
}

void SessionEngine::live(std::vector<std::string> lines, double progress, session_msg::LiveFigures figures) {
  emit(session_msg::Live{std::nullopt, step_now(), std::move(lines), progress, std::move(figures)});
}

void SessionEngine::message(MessageLevel level, const std::string& text, session_msg::MessageCause cause) {
  emit(session_msg::Message{std::nullopt, level, text, cause});
}

session_msg::Status SessionEngine::status() const {
  session_msg::Status m;
  for (const auto& s : progress_.steps) m.steps.push_back({s.id, s.state});
  m.state = state_;
  m.rig = config_.name;
  if (progress_.current < progress_.steps.size() && running()) m.step = progress_.steps[progress_.current].id;
  m.poses = pose_.ups.size();
  // A session that ended keeps the time it took; samples still come after it.
  const TimeNs until = session_end_ns_ >= 0 ? session_end_ns_ : now_ns_;
  m.elapsed_s = session_start_ns_ < 0 ? 0.0 : static_cast<double>(until - session_start_ns_) * 1e-9;
  return m;
}

std::vector<SessionMessage> SessionEngine::snapshot() const {
  std::vector<SessionMessage> out = {status()};
  for (const auto& m : last_messages_) out.push_back(m);
  if (last_prompt_) out.push_back(*last_prompt_);
  if (last_live_) out.push_back(*last_live_);
  return out;
}

bool SessionEngine::step_skippable(StepId id) const {
  return id == StepId::kWarmup || id == StepId::kThermal || id == StepId::kGsens || id == StepId::kMotion ||
         id == StepId::kWrite;
}

void SessionEngine::enter(std::size_t index) {
  progress_.current = index;
  if (progress_.current >= progress_.steps.size()) {
    const bool written = std::any_of(progress_.steps.begin(), progress_.steps.end(), [](const Step& s) {
      return s.id == StepId::kWrite && s.state == StepState::kDone;
    });
    if (written) {
      finish(SessionState::kDone, Outcome::kWritten, "The calibration was written, read back and verified.");
    } else {
      finish(SessionState::kDone, solve_.final ? Outcome::kCompleted : Outcome::kRecorded,
             solve_.final ? "The session is complete; the calibration was not written (no write step)."
                          : "The session is complete; nothing was solved (no solve step).");
    }
    return;
  }
  progress_.steps[progress_.current].state = StepState::kActive;
  progress_.waiting = progress_.failed = false;
  progress_.start_ns = now_ns_;
  emit(status());
  begin_step();
}

void SessionEngine::advance() {
  if (progress_.current < progress_.steps.size() &&
      progress_.steps[progress_.current].state == StepState::kActive)
    progress_.steps[progress_.current].state = StepState::kDone;
  enter(progress_.current + 1);
}

void SessionEngine::finish(SessionState state, Outcome outcome, const std::string& text) {
  if (recording_) {
    recording_ = false;
    host_.recording_finished();
  }
  state_ = state;
  progress_.waiting = false;
  session_end_ns_ = now_ns_;
  emit(status());
  session_msg::Done done;
  done.outcome = outcome;
  done.text = text;
  // Where the record went (storage, slot, sequence), named on the end screen.
  if (outcome == Outcome::kWritten && !solve_.written_to.empty()) done.stored = solve_.written_to;
  // The reports to open, when the final solve drew them.
  if (solve_.final) {
    for (const auto& f : solve_.final->result_files)
      if (f.size() > 5 && f.compare(f.size() - 5, 5, ".html") == 0) done.reports.push_back(f);
  }
  emit(std::move(done));
}

bool SessionEngine::operator_wait_over() const {
  if (operator_since_ns_ < 0 || progress_.current >= progress_.steps.size()) return false;
  const bool waits_for_a_key =
      state_ == SessionState::kReview ||
      (state_ == SessionState::kRunning &&
       (progress_.failed || progress_.steps[progress_.current].id == StepId::kPreflight));
  if (!waits_for_a_key) return false;
  return static_cast<double>(now_ns_ - operator_since_ns_) * 1e-9 >= config_.session.operator_wait_s;
}

void SessionEngine::end_operator_wait() {
  const bool review = state_ == SessionState::kReview;
  progress_.steps[progress_.current].state = StepState::kFailed;
  const double wait_s = config_.session.operator_wait_s;
  const std::string waited = wait_s < 120.0 ? fixed(wait_s, 0) + " s" : fixed(wait_s / 60.0, 0) + " min";
  finish(SessionState::kAborted, Outcome::kAborted,
         "Stopped: no key for " + waited +
             " while the session waited for one (session.operator_wait_s), so that its recording "
             "does not grow without end. What was recorded is kept; the stored calibration is "
             "unchanged. " +
             (review ? "The results stay in the session folder (imucal store write writes them); "
                       "or start a new session."
                     : "Start a new session when the rig is ready."));
}

void SessionEngine::begin_step() {
  const StepId id = progress_.steps[progress_.current].id;
  switch (id) {
    case StepId::kPreflight:
      run_preflight();
      break;
    case StepId::kWarmup:
      warmup_ = {};
      prompt(thermal_planned() ? "Warming up: leave the rig still until the IMU's temperature settles; the "
                                 "warm-up is recorded for the thermal model"
                               : "Warming up: leave the rig still until the IMU's temperature settles",
             {K::kSkip, K::kAbort});
      break;
    case StepId::kThermal:
      // A warm-up just before goes on into this step: its recording is kept.
      warmup_ = {};
      prompt(
          "Thermal: leave the rig still while it warms up (or cools down); the bias is fitted against "
          "the die temperature. c ends the recording",
          {K::kContinue, K::kSkip, K::kAbort});
      break;
    case StepId::kStill:
      still_.since_ns = -1;
      samples_->clear();
      prompt("Keep the rig still for " + fixed(config_.session.still_s, 0) + " s", {K::kAbort});
      break;
    case StepId::kPoses:
      // The attitude of the still start is not a pose (the static method counts it apart): the
      // first pose comes after the first turn.
      pose_.need_motion = true;
      poses_prompt();
      break;
    case StepId::kGsens:
      pose_.face = 0;
      pose_.need_motion = false;
      still_.since_ns = -1;
      face_prompt();
      break;
    case StepId::kMotion:
      motion_ = MotionState(config_.cameras.size());
      prompt("Move the rig in front of the target: rotate about every axis and move along every axis, for " +
                 fixed(config_.session.motion_s, 0) + " s",
             {K::kContinue, K::kSkip, K::kAbort});
      break;
    case StepId::kSolve:
      request_final_solve();
      break;
    case StepId::kReview:
      review();
      break;
    case StepId::kWrite:
      if (!solve_.gates_pass && std::none_of(progress_.steps.begin(), progress_.steps.end(),
                                             [](const Step& s) { return s.id == StepId::kReview; })) {
        progress_.steps[progress_.current].state = StepState::kFailed;
        finish(SessionState::kFailed, Outcome::kFailed,
               "Not written: a quality gate failed and there is no review step to accept it.");
        return;
      }
      if (!solve_.final || !solve_.final->record) {
        progress_.steps[progress_.current].state = StepState::kFailed;
        finish(SessionState::kFailed, Outcome::kFailed, "Nothing to write: the solve produced no record.");
        return;
      }
      prompt("Writing the calibration to the rig's storage", {});
      host_.write(*solve_.final->record);
      break;
  }
}

void SessionEngine::run_preflight() {
  const PreflightReport report = host_.preflight();
  stored_ = report.stored;
  stored_unreadable_ = report.stored_unreadable;
  emit(session_msg::Preflight{std::nullopt, report});
  std::vector<std::string> lines;
  for (const auto& d : report.devices)
    lines.push_back((d.ok ? "ok    " : "FAIL  ") + d.name + ": " + d.detail);
  lines.push_back(report.stored                       ? "stored calibration: " + report.stored->summary
                  : !report.stored_unreadable.empty() ? "stored calibration: present, not readable"
                                                      : "stored calibration: none");
  live(lines, 1.0, report);
  if (!report.ok()) {
    progress_.steps[progress_.current].state = StepState::kFailed;
    progress_.failed = true;
    emit(status());
    // The device's own advice when it has one (a self-test spoilt by motion: hold the rig still).
    std::string advice;
    for (const auto& d : report.devices)
      if (!d.ok && !d.advice.empty()) advice += (advice.empty() ? "" : "; ") + d.name + ": " + d.advice;
    prompt(advice.empty()
               ? "A device failed its check (see above). Fix it and press r to check again, or a to abort"
               : "A device failed its check: " + advice + ". Then press r to check again, or a to abort",
           {K::kRedo, K::kAbort});
    return;
  }
  prompt("Rig '" + report.rig + "': every device answers. Press c to begin", {K::kContinue, K::kAbort});
}

Status SessionEngine::key(K key) {
  if (!running()) return make_error(Errc::kInvalidArgument, "no session is running (start one first)");
  emit(session_msg::Key{std::nullopt, key});
  operator_since_ns_ = now_ns_;
  const StepId id = progress_.steps[progress_.current].id;
  if (key == K::kAbort) {
    progress_.steps[progress_.current].state = StepState::kFailed;
    finish(SessionState::kAborted, Outcome::kAborted,
           "Aborted by the operator. What was recorded is kept; the stored calibration is unchanged.");
    return {};
  }
  if (key == K::kRedo) {
    if (progress_.failed) {
      if (auto s = host_.recover(); !s.ok()) {
        message(MessageLevel::kError, "Still failing: " + s.error().message);
        return {};
      }
      progress_.steps[progress_.current].state = StepState::kActive;
      progress_.failed = false;
      emit(status());  // the step is no longer marked failed
      message(MessageLevel::kInfo, std::string("Redoing step ") + step_name(id));
      begin_step();
      return {};
    }
    if (id == StepId::kPoses && !pose_.ups.empty()) {
      pose_.ups.pop_back();
      message(MessageLevel::kInfo, "Dropped pose " + std::to_string(pose_.ups.size() + 1) + "; " +
                                       std::to_string(pose_.ups.size()) + " remain");
      poses_prompt();
      return {};
    }
    if (id == StepId::kGsens) {
      pose_.face = std::max(0, pose_.face - 1);
      still_.since_ns = -1;
      message(MessageLevel::kInfo, "Redoing the last face");
      face_prompt();
      return {};
    }
    return make_error(Errc::kInvalidArgument, std::string("nothing to redo in step ") + step_name(id));
  }
  if (key == K::kSkip) {
    if (!step_skippable(id))
      return make_error(Errc::kInvalidArgument, std::string("step ") + step_name(id) + " cannot be skipped");
    progress_.steps[progress_.current].state = StepState::kSkipped;
    message(MessageLevel::kInfo, std::string("Skipped step ") + step_name(id));
    if (id == StepId::kThermal) thermal_.means.clear();  // skipped: no thermal model
    enter(progress_.current + 1);
    return {};
  }
  if (key == K::kContinue) {
    if (progress_.failed)
      return make_error(Errc::kInvalidArgument, "the step failed: redo it (r) or abort (a)");
    if (id == StepId::kPreflight || id == StepId::kMotion) {
      advance();
      return {};
    }
    if (id == StepId::kThermal) {
      end_thermal("ended by the operator");
      return {};
    }
    if (id == StepId::kPoses) {
      if (static_cast<int>(pose_.ups.size()) < config_.session.poses_min) {
        message(MessageLevel::kWarning, "Only " + std::to_string(pose_.ups.size()) + " poses; at least " +
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
  if (key == K::kReject) {
    finish(SessionState::kDone, Outcome::kRejected,
           "Rejected: the results are kept in the session folder; the stored calibration is unchanged.");
    return {};
  }
  if (!solve_.final || !solve_.final->error.empty())
    return make_error(Errc::kInvalidArgument, "the solve failed; there is nothing to accept");
  advance();
  return {};
}

void SessionEngine::fault(const std::string& source, const std::string& text) {
  if (!running()) return;
  emit(session_msg::Fault{
      std::nullopt, source, progress_.steps[progress_.current].id, text,
      "What was recorded is kept. Fix the " + source + " and press r to redo the step, or a to abort"});
  progress_.steps[progress_.current].state = StepState::kFailed;
  progress_.failed = true;
  emit(status());
  prompt(source + " fault: " + text + ". Press r to redo the step once fixed, or a to abort",
         {K::kRedo, K::kAbort});
}

void SessionEngine::note(const std::string& text) {
  if (running()) message(MessageLevel::kWarning, text);
}

void SessionEngine::terminate(const std::string& reason) {
  if (!running()) return;
  emit(session_msg::Stop{std::nullopt, reason});
  progress_.steps[progress_.current].state = StepState::kFailed;
  finish(SessionState::kAborted, Outcome::kAborted,
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
  if (pose_.quick_in_flight != 0 || static_cast<int>(pose_.ups.size()) < 9) return;
  SolveJob job;
  job.id = next_solve_id_++;
  job.samples = std::make_shared<const std::vector<ImuSample>>(*samples_);
  job.static_options = static_options();
  job.t_end_ns = now_ns_;
  pose_.quick_in_flight = job.id;
  pose_.quick_poses = pose_.ups.size();
  emit(session_msg::Solve{std::nullopt, job.id, false, job.samples->size(), std::nullopt, std::nullopt});
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
  const bool poses = std::any_of(progress_.steps.begin(), progress_.steps.end(),
                                 [](const Step& s) { return s.id == StepId::kPoses; });
  job.samples = std::make_shared<const std::vector<ImuSample>>(poses ? *samples_ : std::vector<ImuSample>());
  if (!thermal_.means.empty())
    job.thermal_samples = std::make_shared<const std::vector<ImuSample>>(thermal_.means);
  job.static_options = static_options();
  job.camimu = std::any_of(progress_.steps.begin(), progress_.steps.end(), [](const Step& s) {
    return s.id == StepId::kMotion && s.state == StepState::kDone;
  });
  job.t_end_ns = now_ns_;
  solve_.final_id = job.id;
  const std::size_t thermal_means = job.thermal_samples ? job.thermal_samples->size() : 0;
  emit(session_msg::Solve{std::nullopt, job.id, true, job.samples->size(), thermal_means, job.camimu});
  std::string what = poses ? std::to_string(job.samples->size()) + " samples" : std::string();
  if (thermal_means > 0) what += (what.empty() ? "" : ", ") + std::string("the thermal recording");
  if (job.camimu) what += " and the camera frames";
  prompt("Solving: " + what, {K::kAbort});
  host_.solve(job);
}

void SessionEngine::solve_progress(double fraction, const std::string& text) {
  if (!running() || progress_.current >= progress_.steps.size() ||
      progress_.steps[progress_.current].id != StepId::kSolve)
    return;
  live({text}, fraction);
}

void SessionEngine::solve_finished(int id, SolveOutcome outcome) {
  emit(session_msg::Applied{std::nullopt, id, outcome.error, outcome.wall_s});
  if (!running()) return;
  if (id == pose_.quick_in_flight) {
    pose_.quick_in_flight = 0;
    if (!outcome.error.empty() || !outcome.imu) {
      // Feedback only: the final solve decides. The method's advice for a whole recording does
      // not apply mid-session, so only its finding is shown.
      const std::string finding = outcome.error.substr(0, outcome.error.find(';'));
      message(MessageLevel::kInfo, "No quick solve yet after " + std::to_string(pose_.quick_poses) +
                                       " poses (" + finding + "); go on with the poses");
      return;
    }
    pose_.quick = std::move(outcome.imu);
    const auto rel = [](const Eigen::Vector3d& sigma, const Eigen::Vector3d& scale) {
      return sigma.cwiseQuotient(scale.cwiseAbs()).maxCoeff();
    };
    const double sa = rel(pose_.quick->accel_sigma.scale, pose_.quick->model.accel.scale);
    const double sg = rel(pose_.quick->gyro_sigma.scale, pose_.quick->model.gyro.scale);
    auto sigma = [](double v) {
      return std::isfinite(v) ? fixed(v * 1e3, 2) + "e-3" : std::string("undetermined");
    };
    message(MessageLevel::kInfo, "Quick solve (" + std::to_string(pose_.quick_poses) +
                                     " poses): scale sigma accel " + sigma(sa) + ", gyro " + sigma(sg) +
                                     " (target " + fixed(config_.session.pose_sigma_target * 1e3, 2) +
                                     "e-3)");
    // New poses came while it ran: solve again with them.
    if (pose_.ups.size() > pose_.quick_poses && !pose_.quick_pending) request_quick_solve();
    return;
  }
  if (id != solve_.final_id) return;
  solve_.final = std::move(outcome);
  if (solve_.final->error.empty()) {
    evaluate_gates();
    emit(result_message());
  }
  if (!solve_.final->error.empty()) {
    progress_.steps[progress_.current].state = StepState::kFailed;
    finish(SessionState::kFailed, Outcome::kFailed,
           "The solve failed: " + solve_.final->error +
               ". The recording is kept; replay it with `imucal replay`.");
    return;
  }
  advance();
}

session_msg::ResultSummary SessionEngine::result_message() const {
  session_msg::ResultSummary m;
  m.files = solve_.final->result_files;
  if (solve_.final->thermal) {
    const auto& t = *solve_.final->thermal;
    m.thermal = {
        t.determined, t.determined ? t.reference_c : 0.0,
        t.determined ? std::array<double, 2>{t.temp_min_c, t.temp_max_c} : std::array<double, 2>{0.0, 0.0},
        t.determined ? std::string() : t.reason};
  }
  if (solve_.final->imu) {
    const auto& c = solve_.final->imu->canonical;
    m.imu = session_msg::ResultSummary::Imu{c.A_a, c.b_a, c.A_g, c.b_g, c.G};
  }
  if (solve_.final->camimu) {
    m.cameras.emplace();
    for (const auto& cam : solve_.final->camimu->result.cameras) {
      const Eigen::Quaterniond q(cam.T_cam_imu.rotation());
      m.cameras->push_back({cam.name, cam.T_cam_imu.translation(),
                            Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()), cam.timeshift_cam_imu_s,
                            cam.reprojection_rms_px});
    }
    const SplitCheck& sc = solve_.final->camimu->result.self_check;
    if (sc.verdict != SplitCheck::Verdict::kNotRun)
      m.self_check =
          session_msg::ResultSummary::SelfCheck{split_check_verdict_name(sc.verdict), sc.summary, sc.advice};
  }
  return m;
}

void SessionEngine::write_finished(const Status& status, const std::string& where) {
  solve_.written_to = status.ok() ? where : std::string();
  emit(session_msg::Written{std::nullopt, status.ok(), status.ok() ? "" : status.error().message,
                            solve_.written_to});
  if (!running() || progress_.steps[progress_.current].id != StepId::kWrite) return;
  if (!status.ok()) {
    fault("storage", status.error().message);
    return;
  }
  advance();
}

}  // namespace imucal::app::session
