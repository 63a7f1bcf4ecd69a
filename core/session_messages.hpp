// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The guided session's messages (docs/service.md, "Messages"): what the session engine
// (app/session/session_engine.hpp) emits and its hosts act on, as one variant of typed structs.
// The service's socket, its clients and the session log carry them as JSON objects with a
// "type"; encode() and decode() are the one place that JSON is written and read. Their forms are
// those of the service's protocol: an object's keys are sorted, a number that cannot be
// computed (NaN) travels as null.
//
// In core because every host of the engine needs them: the service and replay (app/), the
// virtual rig's scripted operator (sim/) and the console client (daemon/ctl/).
#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "core/calibration_record.hpp"
#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::session_msg {

// ---- the words the messages use, each with its one name table ------------------------------

/// The session's steps, in protocol order.
enum class StepId { kPreflight, kWarmup, kThermal, kStill, kPoses, kGsens, kMotion, kSolve, kReview, kWrite };
enum class StepState { kPending, kActive, kDone, kSkipped, kFailed };
enum class SessionState { kIdle, kRunning, kReview, kDone, kAborted, kFailed };
/// The keys an operator can send (the protocol's "key" request and the engine's key()).
enum class OperatorKey { kContinue, kRedo, kAbort, kAccept, kReject, kSkip };
enum class MessageLevel { kInfo, kWarning, kError };
/// How a session ended (the "done" message).
enum class Outcome { kWritten, kCompleted, kRecorded, kRejected, kAborted, kFailed };
/// A device of the service (the status's "devices"): an IMU is open, closed or failed; a camera
/// streams (in the motion step), is closed, or failed.
enum class DeviceState { kClosed, kOpen, kStreaming, kFailed };

const char* step_name(StepId step);
const char* step_state_name(StepState state);
const char* session_state_name(SessionState state);
const char* key_name(OperatorKey key);
/// The console's letter for a key: c, r, a, y, n, s.
char key_letter(OperatorKey key);
/// The key a console letter stands for, if any.
std::optional<OperatorKey> key_of_letter(char letter);
const char* level_name(MessageLevel level);
const char* outcome_name(Outcome outcome);
const char* device_state_name(DeviceState state);

/// Every step, in protocol order; every operator key, in the order the protocol lists them.
const std::vector<StepId>& all_steps();
const std::vector<OperatorKey>& all_keys();
/// "continue, redo, abort, accept, reject, skip"
std::string key_list();

/// Names back to values; the errors name what is allowed.
[[nodiscard]] Result<StepId> parse_step(std::string_view name);
[[nodiscard]] Result<StepState> parse_step_state(std::string_view name);
[[nodiscard]] Result<SessionState> parse_session_state(std::string_view name);
[[nodiscard]] Result<OperatorKey> parse_key(std::string_view name);
[[nodiscard]] Result<MessageLevel> parse_level(std::string_view name);
[[nodiscard]] Result<Outcome> parse_outcome(std::string_view name);
[[nodiscard]] Result<DeviceState> parse_device_state(std::string_view name);

// ---- the messages ----------------------------------------------------------------------------
// Each carries `t`, the engine's sample time in seconds when it emitted it; a status made for an
// observer's snapshot or a status request has none.

/// What the host found when it probed the rig (the preflight step).
struct PreflightReport {
  struct Device {
    std::string name;  // "imu", "cam0", "storage"
    bool ok = false;
    std::string detail;  // "MPU-6000 on /dev/spidev0.0, WHO_AM_I 0x68, self-test passed" or the error
    std::string advice;  // when it failed: what the operator can do ("hold the rig still ...")
  };
  /// The calibration on the rig's storage.
  struct Stored {
    CalibrationRecord record;
    std::string summary;  // where it is: "sequence 3 in slot B, written ..."
  };
  std::vector<Device> devices;
  std::string rig;               // the configuration's name
  std::optional<Stored> stored;  // none: nothing stored (or stored_unreadable says why it is not here)
  /// A stored record that did not read back from a message (a damaged session log): why. The
  /// session then says the stored calibration is present but not comparable.
  std::string stored_unreadable;
  bool ok() const;
};

/// {"type":"session","event":"start"}: a session starts with these steps (as requested; empty:
/// the configured ones).
struct SessionStart {
  std::optional<double> t;
  std::vector<std::string> steps;
};

/// The service's devices, added to the engine's status by imucald.
struct ServiceDevices {
  struct Imu {
    DeviceState state = DeviceState::kClosed;
    bool sim = false;
    std::int64_t samples = 0;
    std::int64_t faults = 0;
    double rate_hz = 0.0;
    std::string gyro_offsets;
    std::string error;
  };
  struct Camera {
    std::string name;
    DeviceState state = DeviceState::kClosed;
    std::int64_t frames = 0;
    std::int64_t faults = 0;
    std::string error;
  };
  Imu imu;
  std::string storage;
  std::vector<Camera> cameras;
};
/// Where the live view is served (none: it is off), and the file that holds its keys' token.
struct LiveViewAddress {
  std::string url;         // "http://127.0.0.1:8421/"
  std::string token_file;  // readable by the imucal group only
};
struct ServiceStatus {
  ServiceDevices devices;
  std::string session_dir;
  std::string version;
  /// Bytes the session folder's logs hold on disk (session.imulog, motion.imulog and their
  /// write-ahead files): what the session has recorded so far (0: no session yet).
  std::int64_t recorded_bytes = 0;
  std::optional<LiveViewAddress> live_view;
};

struct Status {
  std::optional<double> t;
  SessionState state = SessionState::kIdle;
  std::string rig;
  struct Step {
    StepId name = StepId::kPreflight;
    StepState state = StepState::kPending;
  };
  std::vector<Step> steps;
  std::optional<StepId> step;  // the step under way (none: "")
  std::size_t poses = 0;
  double elapsed_s = 0.0;
  std::optional<ServiceStatus> service;  // imucald's devices, session folder and version
};

struct Prompt {
  std::optional<double> t;
  std::optional<StepId> step;
  std::string text;
  std::vector<OperatorKey> keys;
  std::vector<std::string> art;       // a drawing of the rig's attitude (none: no "art")
  std::optional<Eigen::Vector3d> up;  // the axis the operator is asked to turn up
  bool offers(OperatorKey key) const;
};

struct WarmupFigures {
  double temperature_c = 0.0;
  double rate_c_per_min = 0.0;
};
struct ThermalFigures {
  double temperature_c = 0.0;
  double rate_c_per_min = 0.0;
  std::array<double, 2> range_c{0.0, 0.0};
  Eigen::Vector3d gyro_slope_dps_per_c = Eigen::Vector3d::Zero();    // NaN: not yet
  Eigen::Vector3d accel_slope_mps2_per_c = Eigen::Vector3d::Zero();  // NaN: not yet
};
struct PoseFigures {
  std::size_t poses = 0;
  bool still = false;
  std::vector<std::string> missing;  // the faces not yet up: "+X", "-Z", ...
  double scale_sigma = 0.0;          // NaN before the first quick solve
  std::size_t poses_needed = 0;      // the fewest poses that may end the step (0: not said)
};
/// Where in a camera's image the target has been seen so far (the motion step): corners per cell
/// of a grid over the image, and how much of the image's breadth, height, scale and tilt the
/// views span, each from 0 to 1 (the measures of ROS's camera_calibration: docs/service.md).
struct CameraCoverage {
  int cols = 0, rows = 0;
  std::vector<std::int64_t> cells;  // row-major, cols x rows
  std::int64_t views = 0;           // frames in which the target was found
  double x = 0.0, y = 0.0, size = 0.0, skew = 0.0;
};
struct MotionFigures {
  Eigen::Vector3d gyro_rms_dps = Eigen::Vector3d::Zero();
  std::int64_t frames = 0;
  std::int64_t frames_seen = 0;
  std::vector<std::int64_t> camera_frames;
  std::vector<std::int64_t> camera_frames_seen;
  std::int64_t frames_seen_by_every_camera = 0;
  std::vector<CameraCoverage> coverage;  // each camera's, in configuration order (none: not known)
};
/// The figures of a live message, by step (the preflight's are its report); none for the others.
using LiveFigures =
    std::variant<std::monostate, PreflightReport, WarmupFigures, ThermalFigures, PoseFigures, MotionFigures>;

struct Live {
  std::optional<double> t;
  std::optional<StepId> step;
  std::vector<std::string> lines;
  double progress = 0.0;
  LiveFigures figures;
};

/// Why the engine said a message, where a host in its process acts on it. Not on the wire; a
/// decoded message has kNone.
enum class MessageCause {
  kNone,
  kPoseRefused,  // the hold is too close to a captured pose: turn further
  kWrongFace,    // the six-face step: another face is up than the one asked for
};

struct Message {
  std::optional<double> t;
  MessageLevel level = MessageLevel::kInfo;
  std::string text;
  MessageCause cause = MessageCause::kNone;  // in the process only (above)
};

struct Fault {
  std::optional<double> t;
  std::string source;  // "imu", "cam0", "storage"
  std::optional<StepId> step;
  std::string text;
  std::string advice;
};

struct Preflight {
  std::optional<double> t;
  PreflightReport report;
};

struct Key {
  std::optional<double> t;
  OperatorKey key = OperatorKey::kContinue;
};

struct Stop {
  std::optional<double> t;
  std::string reason;
};

/// A solve the engine asked its host for; a final one names what it covers.
struct Solve {
  std::optional<double> t;
  int id = 0;
  bool final = false;
  std::size_t samples = 0;
  std::optional<std::size_t> thermal_means;  // final solves
  std::optional<bool> camimu;                // final solves
};

/// A solve's outcome applied to the engine.
struct Applied {
  std::optional<double> t;
  int id = 0;
  std::string error;  // empty: success
  double wall_s = 0.0;
};

/// The final solve's result in brief.
struct ResultSummary {
  struct Thermal {
    bool determined = false;
    double reference_c = 0.0;                   // determined
    std::array<double, 2> valid_range_c{0, 0};  // determined
    std::string reason;                         // not determined
  };
  struct Imu {  // the canonical model
    Eigen::Matrix3d A_a = Eigen::Matrix3d::Identity();
    Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
    Eigen::Matrix3d A_g = Eigen::Matrix3d::Identity();
    Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
    Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  };
  struct Camera {
    std::string name;
    Eigen::Vector3d t_cam_imu_m = Eigen::Vector3d::Zero();
    Eigen::Vector4d q_cam_imu_wxyz = Eigen::Vector4d(1, 0, 0, 0);
    double timeshift_cam_imu_s = 0.0;
    double reprojection_rms_px = 0.0;
  };
  struct SelfCheck {
    std::string verdict;  // split_check_verdict_name()
    std::string summary;
    std::string advice;
  };
  std::optional<double> t;
  std::vector<std::string> files;
  std::optional<Thermal> thermal;
  std::optional<Imu> imu;
  std::optional<std::vector<Camera>> cameras;  // after a camera-IMU solve
  std::optional<SelfCheck> self_check;
};

struct Written {
  std::optional<double> t;
  bool ok = false;
  std::string error;
  std::optional<std::string> where;  // the storage, slot and sequence (none from older services)
};

/// A pose captured (poses step): its index from 1 and the gravity direction up, IMU frame.
struct PoseCaptured {
  std::optional<double> t;
  std::size_t index = 0;
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
};

/// A face held (six-face step).
struct FaceHeld {
  std::optional<double> t;
  std::string face;  // "+X", ...
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
};

struct Review {
  struct Gate {
    std::string name;
    double value = 0.0;  // NaN: not determined
    double limit = 0.0;
    bool pass = false;
    std::optional<int> digits;  // decimals to show (none from older services: 3)
  };
  /// The change from the stored calibration (biases, relative scale changes).
  struct Difference {
    Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
    Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
    Eigen::Vector3d scale_a = Eigen::Vector3d::Zero();
    Eigen::Vector3d scale_g = Eigen::Vector3d::Zero();
  };
  std::optional<double> t;
  bool pass = false;
  std::vector<Gate> gates;
  std::vector<std::string> lines;
  std::optional<Difference> difference_to_stored;
  std::vector<std::string> files;
};

struct Done {
  std::optional<double> t;
  Outcome outcome = Outcome::kCompleted;
  std::string text;
  std::optional<std::string> stored;       // where the record went (written)
  std::vector<std::string> reports;        // HTML reports of the final solve (none: no "reports")
  std::optional<std::string> session_dir;  // the session's folder (the runner adds it)
};

using SessionMessage =
    std::variant<SessionStart, Status, Prompt, Live, Message, Fault, Preflight, Key, Stop, Solve, Applied,
                 ResultSummary, Written, PoseCaptured, FaceHeld, Review, Done>;

/// The message's "type" on the wire.
const char* type_name(const SessionMessage& message);
/// The message's time (none: not stamped), and a setter.
std::optional<double> time_of(const SessionMessage& message);
void set_time(SessionMessage& message, double t);

// ---- the one encoder and decoder --------------------------------------------------------------

nlohmann::json encode(const SessionMessage& message);
nlohmann::json encode(const PreflightReport& report);
/// The message as its JSON text, without a newline; invalid UTF-8 replaced.
std::string dump(const SessionMessage& message);

/// A message back from its JSON. Errors (kCorrupt) name the type and the field: not an object, no
/// "type", a type this version does not know (from a newer service), a required field missing
/// (from an older one) or of the wrong kind, a name outside its table. Fields added over time are
/// optional; unknown fields are ignored.
[[nodiscard]] Result<SessionMessage> decode(const nlohmann::json& message);
/// The same from a line of JSON text.
[[nodiscard]] Result<SessionMessage> parse(std::string_view text);
[[nodiscard]] Result<PreflightReport> decode_preflight_report(const nlohmann::json& report);
/// The "type" of a message's JSON text, whether or not the rest decodes ("" when it has none):
/// for a reader that tolerates damage in some kinds and not in others.
std::string type_of(std::string_view text);

/// What the engine saw of a camera frame in the motion step: the session log's "frame" event.
struct FrameEvent {
  std::size_t camera = 0;
  TimeNs t_ns = 0;
  bool seen = false;
};
std::string dump(const FrameEvent& event);
[[nodiscard]] Result<FrameEvent> parse_frame_event(std::string_view text);

}  // namespace imucal::session_msg
