// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The guided calibration session (docs/service-session.md): a state machine over the protocol's
// steps (preflight, warm-up, thermal recording, still start, static poses, six-face holds, checkerboard
// motion, solve, review, write) that turns IMU samples, frame detections and operator keys into prompts, live
// figures and results.
//
// The engine is deterministic and runs on sample time only: every decision is taken while a
// sample is processed or when a key, a fault or a solve result is applied between two samples,
// and each of those is emitted as a message (and so stored in the session log). Replaying the
// samples of a session log with its keys, faults and solve applications at their recorded times
// therefore takes the same decisions and reaches the same results (`imucal replay`).
//
// It owns no device, thread or file. Its host (the service imucald, or replay) feeds it, shows and
// logs what it emits, runs the solves and the write it asks for and hands their outcome back.
#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/camimu_calibration.hpp"
#include "app/session/pose_guide.hpp"
#include "calib/static_calibration.hpp"
#include "calib/thermal_calibration.hpp"
#include "core/calibration_record.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "core/session_messages.hpp"
#include "core/split_check.hpp"
#include "core/time.hpp"

namespace imucal::app::session {

// The words of the session's messages (core/session_messages.hpp).
using session_msg::parse_step;
using session_msg::session_state_name;
using session_msg::SessionMessage;
using session_msg::SessionState;
using session_msg::step_name;
using session_msg::step_state_name;
using session_msg::StepId;
using session_msg::StepState;

/// The steps a configuration runs: session.steps, or every step that applies (gsens and thermal
/// only when listed, motion only with cameras).
std::vector<StepId> configured_steps(const RigConfig& config);

/// What the host found when it probed the rig (step 1).
using session_msg::PreflightReport;

/// A solve the engine asks for. Quick: the static method over the samples so far (live sigmas
/// while poses are captured). Final: the thermal model (after a thermal step), the static method
/// on samples corrected to its reference temperature and, after a motion step, the camera-IMU
/// calibration of the session log.
struct SolveJob {
  int id = 0;
  bool final = false;
  /// The samples from the start of the still step on, as recorded (raw counts or SI); empty in a
  /// session without the poses step (a thermal recording alone): no static calibration then.
  std::shared_ptr<const std::vector<ImuSample>> samples;
  /// The thermal recording (warm-up and thermal steps of a session with the thermal step): means
  /// over 0.1 s of the still rig's samples, in SI units and deg C. Empty: no thermal model.
  std::shared_ptr<const std::vector<ImuSample>> thermal_samples;
  calib::StaticCalibrationOptions static_options;
  bool camimu = false;
  TimeNs t_end_ns = 0;  // last sample in the job
};

/// What a solve produced. The host fills what it ran.
struct SolveOutcome {
  /// The thermal model's fit (determined or with the reason it is not), after a thermal step.
  std::optional<calib::ThermalResult> thermal;
  std::optional<StaticCalibrationResult> imu;
  std::optional<CamImuReport> camimu;
  /// With several cameras: the camera chain's self-check (its halves calibrated apart; kNotRun
  /// with one camera), whose scaling the chain's sigmas in `camimu`'s inputs already carry.
  SplitCheck chain_self_check;
  /// The record to store (core/calibration_record.hpp), built from the typed results above by
  /// run_solve and completed by the host (RunnerOptions::complete_record); empty for a quick solve.
  std::optional<CalibrationRecord> record;
  std::vector<std::string> result_files;
  std::string error;    // empty: success
  double wall_s = 0.0;  // wall-clock time the solve took (the host measures it)
};

/// The engine's view of its host.
class EngineHost {
 public:
  virtual ~EngineHost() = default;
  /// A message for the operator and the session log (docs/service.md).
  virtual void emit(const SessionMessage& message) = 0;
  /// Probes the devices and reads the stored calibration (step 1, and again on redo).
  virtual PreflightReport preflight() = 0;
  /// Runs a solve off the engine's thread; the host calls SessionEngine::solve_finished() later.
  virtual void solve(const SolveJob& job) = 0;
  /// Writes the record, syncs and reads it back; the host calls write_finished() later.
  virtual void write(const CalibrationRecord& record) = 0;
  /// After a fault: reopens what failed. Ok when the step can be redone.
  virtual Status recover() = 0;
  /// The recording ends here (the solve starts): no more samples will be stored.
  virtual void recording_finished() {}
};

class SessionEngine {
 public:
  /// `info` describes the samples (raw or SI); `has_cameras`: the motion step can run.
  SessionEngine(const RigConfig& config, const ImuStreamInfo& info, EngineHost& host);
  ~SessionEngine();
  SessionEngine(const SessionEngine&) = delete;
  SessionEngine& operator=(const SessionEngine&) = delete;

  /// Starts a session with these steps (empty: configured_steps()). Fails while one runs.
  [[nodiscard]] Status start(const std::vector<std::string>& steps);
  /// What start() would run, or why it would refuse, without starting anything.
  [[nodiscard]] Result<std::vector<StepId>> plan(const std::vector<std::string>& steps) const;
  /// One IMU sample, in time order.
  void on_sample(const ImuSample& sample);
  /// A frame of camera `camera` (its index in the configuration) at `t_ns`; `target_seen` when
  /// the target was detected in it.
  void on_frame(std::size_t camera, TimeNs t_ns, bool target_seen);
  /// An operator key. Errors say why it does not apply now.
  [[nodiscard]] Status key(session_msg::OperatorKey key);
  /// A device or storage fault from the host: the step stops and the operator is told how to go on.
  void fault(const std::string& source, const std::string& text);
  /// A warning from the host that changes nothing in the session (the virtual rig slower than
  /// asked): shown to the operator while a session runs, ignored otherwise.
  void note(const std::string& text);
  /// Ends a running session from outside (the service stops: SIGTERM): like abort, with the reason.
  void terminate(const std::string& reason);
  void solve_progress(double fraction, const std::string& text);
  void solve_finished(int id, SolveOutcome outcome);
  /// `where`: the storage, slot and sequence the record went to (named at the end).
  void write_finished(const Status& status, const std::string& where = {});

  SessionState state() const { return state_; }
  /// The step under way while a session runs and the step has not failed; empty otherwise.
  std::optional<StepId> current_step() const {
    if (state_ != SessionState::kRunning || progress_.current >= progress_.steps.size() || progress_.failed)
      return std::nullopt;
    return progress_.steps[progress_.current].id;
  }
  bool running() const { return state_ == SessionState::kRunning || state_ == SessionState::kReview; }
  /// When the step under way started (sample time); a redo starts it again.
  TimeNs step_start_ns() const { return progress_.start_ns; }
  /// Sample time of the engine: the last sample's.
  TimeNs now_ns() const { return now_ns_; }
  /// The session's state now (not stamped).
  session_msg::Status status() const;
  /// Messages that bring a new observer up to date (status, the last prompt and live figures).
  std::vector<SessionMessage> snapshot() const;
  /// The final solve's outcome once it is in.
  const std::optional<SolveOutcome>& result() const { return solve_.final; }
  /// The review's quality gates (after the final solve).
  struct Gate {
    std::string name;
    double value = 0.0;
    double limit = 0.0;
    bool pass = false;
    int digits = 3;  // decimals the value and the limit are shown with
  };
  const std::vector<Gate>& gates() const { return solve_.gates; }
  /// Poses captured so far (gravity directions in the IMU frame).
  const std::vector<Eigen::Vector3d>& poses() const { return pose_.ups; }

 private:
  struct Window;  // stillness over the last 0.5 s
  struct Step {
    StepId id;
    StepState state = StepState::kPending;
  };

  void reset();
  void evaluate_gates();
  session_msg::ResultSummary result_message() const;
  void emit(SessionMessage message);
  /// `art`: lines of a drawing that go with the prompt (the rig's attitude), none when empty.
  /// `up`: the axis the operator is asked to turn up (samples' frame), for a client to draw.
  void prompt(const std::string& text, std::vector<session_msg::OperatorKey> keys,
              std::vector<std::string> art = {}, const Eigen::Vector3d* up = nullptr);
  void poses_prompt();  // the poses step's prompt, with the next direction not yet covered
  void face_prompt();   // the six-face step's prompt for face_
  void live(std::vector<std::string> lines, double progress, session_msg::LiveFigures figures = {});
  void message(session_msg::MessageLevel level, const std::string& text,
               session_msg::MessageCause cause = session_msg::MessageCause::kNone);
  void enter(std::size_t index);
  void advance();
  void finish(SessionState state, session_msg::Outcome outcome, const std::string& text);
  std::optional<StepId> step_now() const;  // the step of the current index (none past the end)
  void begin_step();
  bool step_skippable(StepId id) const;

  void run_preflight();
  void sample_warmup(const ImuSample& si);
  void sample_thermal(const ImuSample& si);
  /// The warm-up's and thermal step's view of the die: the sample's temperature added to the
  /// window, the rate (deg C/min, least squares over the window), the step's elapsed time and
  /// whether the die has settled (a full window below session.warmup_rate_c_per_min). Empty, with
  /// `no_temperature` said as a warning, when the IMU gives no temperature.
  struct TemperatureTrend {
    double rate_c_per_min = 0.0;
    double window_s = 0.0;  // the window's length so far
    double elapsed_s = 0.0;
    bool settled = false;
  };
  std::optional<TemperatureTrend> temperature_trend(const ImuSample& si, const std::string& no_temperature);
  /// The thermal recording: 0.1 s means of the still rig's samples (SI); motion starts it again.
  void record_thermal(const ImuSample& si, bool still);
  void end_thermal(const std::string& why);
  bool thermal_planned() const;
  void sample_still(const ImuSample& si, bool still);
  void sample_poses(const ImuSample& si, bool still);
  void sample_gsens(const ImuSample& si, bool still);
  void sample_motion(const ImuSample& si);
  void capture_pose();
  void request_quick_solve();
  void request_final_solve();
  void review();
  std::vector<std::string> difference_to_stored(std::optional<session_msg::Review::Difference>* diff) const;
  std::vector<std::string> imu_difference_to_stored(
      std::optional<session_msg::Review::Difference>* diff) const;
  /// The cameras the review shows: the record's, or the camera-IMU result's without a record.
  std::vector<CameraRecord> review_cameras() const;
  std::vector<std::string> coverage() const;
  std::string missing_words() const;  // the directions not yet up, in the guide's words
  calib::StaticCalibrationOptions static_options() const;
  ImuSample to_si(const ImuSample& raw) const;
  bool live_due();
  /// True once the session has waited session.operator_wait_s of sample time for a key while
  /// it uses no sample (preflight, a failed step, the review): then it ends, so that its
  /// recording stays bounded, and says so.
  bool operator_wait_over() const;
  void end_operator_wait();

  RigConfig config_;
  PoseGuide guide_;
  ImuStreamInfo info_;
  EngineHost& host_;
  SessionState state_ = SessionState::kIdle;
  /// The session's steps and where it is in them, made anew with each session.
  struct StepProgress {
    std::vector<Step> steps;
    std::size_t current = 0;
    bool waiting = false;  // the step waits for the operator (prompt with keys)
    bool failed = false;   // the current step failed: it waits for redo, skip or abort
    TimeNs start_ns = -1;  // when the current step started (sample time)
  };
  StepProgress progress_;
  // Sample time of the last prompt or key: a session that waits for a key and uses no sample
  // stops once it has waited session.operator_wait_s from here (operator_wait_over()).
  TimeNs operator_since_ns_ = -1;
  bool sampled_ = false;  // a sample came since start(): before, now_ns_ may be another session's
  TimeNs now_ns_ = 0;
  TimeNs session_start_ns_ = -1;
  TimeNs session_end_ns_ = -1;  // when it ended: its elapsed time stops there
  TimeNs last_live_ns_ = 0;
  std::optional<SessionMessage> last_prompt_, last_live_;
  std::deque<SessionMessage> last_messages_;

  std::unique_ptr<Window> window_;
  std::shared_ptr<std::vector<ImuSample>> samples_;  // from the still step on
  bool recording_ = true;

  /// The warm-up's temperatures, made anew on entering the warm-up or thermal step.
  struct WarmupState {
    std::deque<std::pair<double, double>> temps;  // (t s, deg C), one per 0.5 s
    TimeNs last_temp_ns = 0;
  };
  WarmupState warmup_;
  /// The thermal recording, made anew with the session (and when the rig moves during it).
  struct ThermalState {
    struct Mean {  // the 0.1 s mean being summed
      TimeNs first_ns = -1, last_ns = 0;
      Eigen::Vector3d accel = Eigen::Vector3d::Zero(), gyro = Eigen::Vector3d::Zero();
      double temperature = 0.0;
      long count = 0;
    } sum;
    std::vector<ImuSample> means;  // the means so far (SI, deg C)
  };
  ThermalState thermal_;
  /// The holds: since when the rig is still (the still start, a pose, a face), and the still
  /// start's gyro bias; made anew with the session.
  struct StillState {
    TimeNs since_ns = -1;                                // -1: moving
    Eigen::Vector3d gyro_sum = Eigen::Vector3d::Zero();  // the still start's, so far
    long count = 0;
    Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
    bool bias_known = false;
  };
  StillState still_;
  int next_solve_id_ = 1;  // unique over the engine's life
  /// The poses (and six faces) captured this session and their quick solves, made anew with it.
  struct PoseState {
    std::vector<Eigen::Vector3d> ups;  // the up direction of each pose captured
    bool need_motion = false;          // after a capture or a refusal the rig must move first
    bool quick_pending = false;        // a pose was captured: solve once the rig has moved for 0.5 s
    TimeNs last_still_ns = 0;
    int face = 0;             // six-face: the face prompted
    int quick_in_flight = 0;  // id, 0 = none
    std::size_t quick_poses = 0;
    std::optional<StaticCalibrationResult> quick;
  };
  PoseState pose_;
  /// The motion step's figures, made anew on entering it.
  struct MotionState {
    MotionState() = default;
    explicit MotionState(std::size_t cameras)
        : camera_frames(cameras, 0), camera_seen(cameras, 0), camera_last_seen_ns(cameras, -1) {}
    Eigen::Vector3d gyro_sq = Eigen::Vector3d::Zero(), accel_sum = Eigen::Vector3d::Zero(),
                    accel_sq = Eigen::Vector3d::Zero();
    long count = 0;  // samples
    long frames = 0, frames_seen = 0;
    TimeNs last_seen_ns = -1;
    // Several cameras: each one's frames and detections, its last detection, and the instants at
    // which every camera saw the target (within half a frame interval of each other).
    std::vector<long> camera_frames, camera_seen;
    std::vector<TimeNs> camera_last_seen_ns;
    long frames_shared = 0;
    TimeNs last_shared_ns = -1;
    long saturated = 0;
  };
  MotionState motion_;
  /// The final solve, its review and the write, made anew with the session.
  struct SolveState {
    int final_id = 0;
    std::optional<SolveOutcome> final;
    std::vector<Gate> gates;
    bool gates_pass = false;
    std::string written_to;  // where the write put the record (storage, slot, sequence)
  };
  SolveState solve_;
  /// The calibration on the storage at preflight (none: nothing stored, or a record that did not
  /// read, whose reason is stored_unreadable_).
  std::optional<PreflightReport::Stored> stored_;
  std::string stored_unreadable_;
};

}  // namespace imucal::app::session
