// SPDX-License-Identifier: BSD-3-Clause
// The session messages' name tables and their encoder (the decoder is in
// session_messages_decode.cpp).
#include "core/session_messages.hpp"

#include <algorithm>

namespace imucal::session_msg {

using nlohmann::json;

namespace {

template <typename E>
struct Name {
  E value;
  const char* name;
};

constexpr Name<StepId> kStepNames[] = {{StepId::kPreflight, "preflight"}, {StepId::kWarmup, "warmup"},
                                       {StepId::kThermal, "thermal"},     {StepId::kStill, "still"},
                                       {StepId::kPoses, "poses"},         {StepId::kGsens, "gsens"},
                                       {StepId::kMotion, "motion"},       {StepId::kSolve, "solve"},
                                       {StepId::kReview, "review"},       {StepId::kWrite, "write"}};
constexpr Name<StepState> kStepStateNames[] = {{StepState::kPending, "pending"},
                                               {StepState::kActive, "active"},
                                               {StepState::kDone, "done"},
                                               {StepState::kSkipped, "skipped"},
                                               {StepState::kFailed, "failed"}};
constexpr Name<SessionState> kSessionStateNames[] = {
    {SessionState::kIdle, "idle"}, {SessionState::kRunning, "running"}, {SessionState::kReview, "review"},
    {SessionState::kDone, "done"}, {SessionState::kAborted, "aborted"}, {SessionState::kFailed, "failed"}};
constexpr Name<MessageLevel> kLevelNames[] = {
    {MessageLevel::kInfo, "info"}, {MessageLevel::kWarning, "warning"}, {MessageLevel::kError, "error"}};
constexpr Name<Outcome> kOutcomeNames[] = {
    {Outcome::kWritten, "written"},   {Outcome::kCompleted, "completed"}, {Outcome::kRecorded, "recorded"},
    {Outcome::kRejected, "rejected"}, {Outcome::kAborted, "aborted"},     {Outcome::kFailed, "failed"}};

constexpr Name<DeviceState> kDeviceStateNames[] = {{DeviceState::kClosed, "closed"},
                                                   {DeviceState::kOpen, "open"},
                                                   {DeviceState::kStreaming, "streaming"},
                                                   {DeviceState::kFailed, "failed"}};

/// The operator's keys: the protocol's name and the console's letter.
struct KeyInfo {
  OperatorKey key;
  const char* name;
  char letter;
};
constexpr KeyInfo kKeys[] = {{OperatorKey::kContinue, "continue", 'c'}, {OperatorKey::kRedo, "redo", 'r'},
                             {OperatorKey::kAbort, "abort", 'a'},       {OperatorKey::kAccept, "accept", 'y'},
                             {OperatorKey::kReject, "reject", 'n'},     {OperatorKey::kSkip, "skip", 's'}};

template <typename E, std::size_t N>
const char* name_of(const Name<E> (&table)[N], E value) {
  for (const auto& entry : table)
    if (entry.value == value) return entry.name;
  return "?";
}

template <typename E, std::size_t N>
Result<E> value_of(const Name<E> (&table)[N], std::string_view name, const char* what) {
  std::string all;
  for (const auto& entry : table) {
    if (entry.name == name) return entry.value;
    all += std::string(all.empty() ? "" : ", ") + entry.name;
  }
  return make_error(Errc::kInvalidArgument, "'" + std::string(name) + "' is not " + what + " (" + all + ")");
}

json vec(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

json mat(const Eigen::Matrix3d& m) { return json::array({vec(m.row(0)), vec(m.row(1)), vec(m.row(2))}); }

std::string step_or_empty(const std::optional<StepId>& step) { return step ? step_name(*step) : ""; }

json stamped(const char* type, const std::optional<double>& t) {
  json m = {{"type", type}};
  if (t) m["t"] = *t;
  return m;
}

struct Encoder {
  json operator()(const SessionStart& m) const {
    json j = stamped("session", m.t);
    j["event"] = "start";
    j["steps"] = m.steps;
    return j;
  }
  json operator()(const Status& m) const {
    json j = stamped("status", m.t);
    json steps = json::array();
    for (const auto& s : m.steps)
      steps.push_back({{"name", step_name(s.name)}, {"state", step_state_name(s.state)}});
    j["state"] = session_state_name(m.state);
    j["rig"] = m.rig;
    j["steps"] = steps;
    j["step"] = step_or_empty(m.step);
    j["poses"] = m.poses;
    j["elapsed_s"] = m.elapsed_s;
    if (m.service) {
      const ServiceDevices& d = m.service->devices;
      json cams = json::array();
      for (const auto& c : d.cameras)
        cams.push_back({{"name", c.name},
                        {"state", device_state_name(c.state)},
                        {"frames", c.frames},
                        {"faults", c.faults},
                        {"error", c.error}});
      j["devices"] = {{"imu",
                       {{"state", device_state_name(d.imu.state)},
                        {"sim", d.imu.sim},
                        {"samples", d.imu.samples},
                        {"faults", d.imu.faults},
                        {"rate_hz", d.imu.rate_hz},
                        {"gyro_offsets", d.imu.gyro_offsets},
                        {"error", d.imu.error}}},
                      {"storage", d.storage},
                      {"cameras", cams}};
      j["session_dir"] = m.service->session_dir;
      j["version"] = m.service->version;
      j["recorded_bytes"] = m.service->recorded_bytes;
      if (m.service->live_view)
        j["live_view"] = {{"url", m.service->live_view->url},
                          {"token_file", m.service->live_view->token_file}};
    }
    return j;
  }
  json operator()(const Prompt& m) const {
    json j = stamped("prompt", m.t);
    json keys = json::array();
    for (OperatorKey k : m.keys) keys.push_back(key_name(k));
    j["step"] = step_or_empty(m.step);
    j["text"] = m.text;
    j["keys"] = keys;
    if (!m.art.empty()) j["art"] = m.art;
    if (m.up) j["up"] = vec(*m.up);
    return j;
  }
  json operator()(const Live& m) const {
    json j = stamped("live", m.t);
    j["step"] = step_or_empty(m.step);
    j["lines"] = m.lines;
    j["progress"] = m.progress;
    std::visit([&j](const auto& f) { figures(j, f); }, m.figures);
    return j;
  }
  static void figures(json&, const std::monostate&) {}
  static void figures(json& j, const PreflightReport& r) { j["figures"] = encode(r); }
  static void figures(json& j, const WarmupFigures& f) {
    j["figures"] = {{"temperature_c", f.temperature_c}, {"rate_c_per_min", f.rate_c_per_min}};
  }
  static void figures(json& j, const ThermalFigures& f) {
    j["figures"] = {{"temperature_c", f.temperature_c},
                    {"rate_c_per_min", f.rate_c_per_min},
                    {"range_c", {f.range_c[0], f.range_c[1]}},
                    {"gyro_slope_dps_per_c", vec(f.gyro_slope_dps_per_c)},
                    {"accel_slope_mps2_per_c", vec(f.accel_slope_mps2_per_c)}};
  }
  static void figures(json& j, const PoseFigures& f) {
    j["figures"] = {
        {"poses", f.poses}, {"still", f.still}, {"missing", f.missing}, {"scale_sigma", f.scale_sigma}};
    // Written only when said, so that the events of logs from before it encode back the same.
    if (f.poses_needed > 0) j["figures"]["poses_needed"] = f.poses_needed;
  }
  static void figures(json& j, const MotionFigures& f) {
    j["figures"] = {{"gyro_rms_dps", vec(f.gyro_rms_dps)},
                    {"frames", f.frames},
                    {"frames_seen", f.frames_seen},
                    {"camera_frames", f.camera_frames},
                    {"camera_frames_seen", f.camera_frames_seen},
                    {"frames_seen_by_every_camera", f.frames_seen_by_every_camera}};
    // Written only when known, so that the events of logs from before it encode back the same.
    if (!f.coverage.empty()) {
      json cov = json::array();
      for (const CameraCoverage& c : f.coverage)
        cov.push_back({{"cols", c.cols},
                       {"rows", c.rows},
                       {"cells", c.cells},
                       {"views", c.views},
                       {"x", c.x},
                       {"y", c.y},
                       {"size", c.size},
                       {"skew", c.skew}});
      j["figures"]["coverage"] = cov;
    }
  }
  json operator()(const Message& m) const {
    json j = stamped("message", m.t);
    j["level"] = level_name(m.level);
    j["text"] = m.text;
    return j;
  }
  json operator()(const Fault& m) const {
    json j = stamped("fault", m.t);
    j["source"] = m.source;
    j["step"] = step_or_empty(m.step);
    j["text"] = m.text;
    j["advice"] = m.advice;
    return j;
  }
  json operator()(const Preflight& m) const {
    json j = stamped("preflight", m.t);
    j["report"] = encode(m.report);
    return j;
  }
  json operator()(const Key& m) const {
    json j = stamped("key", m.t);
    j["key"] = key_name(m.key);
    return j;
  }
  json operator()(const Stop& m) const {
    json j = stamped("stop", m.t);
    j["reason"] = m.reason;
    return j;
  }
  json operator()(const Solve& m) const {
    json j = stamped("solve", m.t);
    j["id"] = m.id;
    j["final"] = m.final;
    j["samples"] = m.samples;
    if (m.thermal_means) j["thermal_means"] = *m.thermal_means;
    if (m.camimu) j["camimu"] = *m.camimu;
    return j;
  }
  json operator()(const Applied& m) const {
    json j = stamped("applied", m.t);
    j["id"] = m.id;
    j["error"] = m.error;
    j["wall_s"] = m.wall_s;
    return j;
  }
  json operator()(const ResultSummary& m) const;
  json operator()(const Written& m) const {
    json j = stamped("written", m.t);
    j["ok"] = m.ok;
    j["error"] = m.error;
    if (m.where) j["where"] = *m.where;
    return j;
  }
  json operator()(const PoseCaptured& m) const {
    json j = stamped("pose", m.t);
    j["index"] = m.index;
    j["up"] = vec(m.up);
    return j;
  }
  json operator()(const FaceHeld& m) const {
    json j = stamped("face", m.t);
    j["face"] = m.face;
    j["up"] = vec(m.up);
    return j;
  }
  json operator()(const Review& m) const;
  json operator()(const Done& m) const {
    json j = stamped("done", m.t);
    j["outcome"] = outcome_name(m.outcome);
    j["text"] = m.text;
    if (m.stored) j["stored"] = *m.stored;
    if (!m.reports.empty()) j["reports"] = m.reports;
    if (m.session_dir) j["session_dir"] = *m.session_dir;
    return j;
  }
};

json Encoder::operator()(const ResultSummary& m) const {
  json j = stamped("result", m.t);
  j["files"] = m.files;
  if (m.thermal) {
    j["thermal"] = {{"determined", m.thermal->determined}};
    if (m.thermal->determined) {
      j["thermal"]["reference_c"] = m.thermal->reference_c;
      j["thermal"]["valid_range_c"] = {m.thermal->valid_range_c[0], m.thermal->valid_range_c[1]};
    } else {
      j["thermal"]["reason"] = m.thermal->reason;
    }
  }
  if (m.imu) {
    const auto& c = *m.imu;
    j["imu"] = {
        {"A_a", mat(c.A_a)}, {"b_a", vec(c.b_a)}, {"A_g", mat(c.A_g)}, {"b_g", vec(c.b_g)}, {"G", mat(c.G)}};
  }
  if (m.cameras) {
    json cams = json::array();
    for (const auto& cam : *m.cameras) {
      const Eigen::Vector4d& q = cam.q_cam_imu_wxyz;
      cams.push_back({{"name", cam.name},
                      {"t_cam_imu_m", vec(cam.t_cam_imu_m)},
                      {"q_cam_imu_wxyz", {q[0], q[1], q[2], q[3]}},
                      {"timeshift_cam_imu_s", cam.timeshift_cam_imu_s},
                      {"reprojection_rms_px", cam.reprojection_rms_px}});
    }
    j["cameras"] = cams;
  }
  if (m.self_check)
    j["self_check"] = {{"verdict", m.self_check->verdict},
                       {"summary", m.self_check->summary},
                       {"advice", m.self_check->advice}};
  return j;
}

json Encoder::operator()(const Review& m) const {
  json j = stamped("review", m.t);
  json gates = json::array();
  for (const auto& g : m.gates) {
    gates.push_back({{"name", g.name}, {"value", g.value}, {"limit", g.limit}, {"pass", g.pass}});
    if (g.digits) gates.back()["digits"] = *g.digits;
  }
  j["pass"] = m.pass;
  j["gates"] = gates;
  j["lines"] = m.lines;
  if (m.difference_to_stored) {
    const auto& d = *m.difference_to_stored;
    j["difference_to_stored"] = {
        {"b_a", vec(d.b_a)}, {"b_g", vec(d.b_g)}, {"scale_a", vec(d.scale_a)}, {"scale_g", vec(d.scale_g)}};
  } else {
    j["difference_to_stored"] = nullptr;
  }
  j["files"] = m.files;
  return j;
}

}  // namespace

const char* step_name(StepId step) { return name_of(kStepNames, step); }
const char* step_state_name(StepState state) { return name_of(kStepStateNames, state); }
const char* session_state_name(SessionState state) { return name_of(kSessionStateNames, state); }
const char* level_name(MessageLevel level) { return name_of(kLevelNames, level); }
const char* outcome_name(Outcome outcome) { return name_of(kOutcomeNames, outcome); }
const char* device_state_name(DeviceState state) { return name_of(kDeviceStateNames, state); }

const char* key_name(OperatorKey key) {
  for (const auto& k : kKeys)
    if (k.key == key) return k.name;
  return "?";
}

char key_letter(OperatorKey key) {
  for (const auto& k : kKeys)
    if (k.key == key) return k.letter;
  return '?';
}

std::optional<OperatorKey> key_of_letter(char letter) {
  for (const auto& k : kKeys)
    if (k.letter == letter) return k.key;
  return std::nullopt;
}

const std::vector<StepId>& all_steps() {
  static const std::vector<StepId> steps = [] {
    std::vector<StepId> out;
    for (const auto& s : kStepNames) out.push_back(s.value);
    return out;
  }();
  return steps;
}

const std::vector<OperatorKey>& all_keys() {
  static const std::vector<OperatorKey> keys = [] {
    std::vector<OperatorKey> out;
    for (const auto& k : kKeys) out.push_back(k.key);
    return out;
  }();
  return keys;
}

std::string key_list() {
  std::string all;
  for (const auto& k : kKeys) all += std::string(all.empty() ? "" : ", ") + k.name;
  return all;
}

Result<StepId> parse_step(std::string_view name) { return value_of(kStepNames, name, "a session step"); }
Result<StepState> parse_step_state(std::string_view name) {
  return value_of(kStepStateNames, name, "a step state");
}
Result<SessionState> parse_session_state(std::string_view name) {
  return value_of(kSessionStateNames, name, "a session state");
}
Result<MessageLevel> parse_level(std::string_view name) {
  return value_of(kLevelNames, name, "a message level");
}
Result<Outcome> parse_outcome(std::string_view name) {
  return value_of(kOutcomeNames, name, "a session outcome");
}
Result<DeviceState> parse_device_state(std::string_view name) {
  return value_of(kDeviceStateNames, name, "a device state");
}

Result<OperatorKey> parse_key(std::string_view name) {
  for (const auto& k : kKeys)
    if (k.name == name) return k.key;
  return make_error(Errc::kInvalidArgument, "'" + std::string(name) + "' is not a key (" + key_list() + ")");
}

bool PreflightReport::ok() const {
  return std::all_of(devices.begin(), devices.end(), [](const Device& d) { return d.ok; });
}

bool Prompt::offers(OperatorKey key) const { return std::find(keys.begin(), keys.end(), key) != keys.end(); }

const char* type_name(const SessionMessage& message) {
  struct Types {
    const char* operator()(const SessionStart&) const { return "session"; }
    const char* operator()(const Status&) const { return "status"; }
    const char* operator()(const Prompt&) const { return "prompt"; }
    const char* operator()(const Live&) const { return "live"; }
    const char* operator()(const Message&) const { return "message"; }
    const char* operator()(const Fault&) const { return "fault"; }
    const char* operator()(const Preflight&) const { return "preflight"; }
    const char* operator()(const Key&) const { return "key"; }
    const char* operator()(const Stop&) const { return "stop"; }
    const char* operator()(const Solve&) const { return "solve"; }
    const char* operator()(const Applied&) const { return "applied"; }
    const char* operator()(const ResultSummary&) const { return "result"; }
    const char* operator()(const Written&) const { return "written"; }
    const char* operator()(const PoseCaptured&) const { return "pose"; }
    const char* operator()(const FaceHeld&) const { return "face"; }
    const char* operator()(const Review&) const { return "review"; }
    const char* operator()(const Done&) const { return "done"; }
  };
  return std::visit(Types{}, message);
}

std::optional<double> time_of(const SessionMessage& message) {
  return std::visit([](const auto& m) { return m.t; }, message);
}

void set_time(SessionMessage& message, double t) {
  std::visit([t](auto& m) { m.t = t; }, message);
}

json encode(const SessionMessage& message) { return std::visit(Encoder{}, message); }

json encode(const PreflightReport& report) {
  json devs = json::array();
  for (const auto& d : report.devices) {
    devs.push_back({{"name", d.name}, {"ok", d.ok}, {"detail", d.detail}});
    if (!d.advice.empty()) devs.back()["advice"] = d.advice;
  }
  json stored;  // the record's own JSON form with its summary beside
  if (report.stored) {
    stored = calibration_record_json(report.stored->record);
    stored["summary"] = report.stored->summary;
  }
  json j = {{"rig", report.rig}, {"devices", devs}, {"stored", stored}};
  if (!report.stored_unreadable.empty()) j["stored_unreadable"] = report.stored_unreadable;
  return j;
}

std::string dump(const SessionMessage& message) {
  // Replace, not throw: a host's text may carry bytes from a device name or a file.
  return encode(message).dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string dump(const FrameEvent& event) {
  const json e = {{"camera", event.camera}, {"t_ns", event.t_ns}, {"seen", event.seen}};
  return e.dump(-1, ' ', false, json::error_handler_t::replace);
}

}  // namespace imucal::session_msg
