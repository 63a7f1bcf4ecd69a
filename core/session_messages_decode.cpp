// SPDX-License-Identifier: BSD-3-Clause
// The session messages' decoder: the one place their JSON is read back by field name.
#include <cmath>
#include <limits>

#include "core/session_messages.hpp"

namespace imucal::session_msg {

using nlohmann::json;

namespace {

/// Reads the fields of one JSON object; the first problem is kept and named with the message's
/// type, and every later read returns its default.
class Fields {
 public:
  Fields(const json& object, std::string where) : j_(object), where_(std::move(where)) {
    if (!j_.is_object()) fail("is not a JSON object");
  }
  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  void fail(const std::string& what) {
    if (error_.empty()) error_ = where_ + " " + what;
  }

  /// The field, or null when absent (an error when required).
  const json& at(const char* key, bool required) {
    static const json null;
    if (!ok()) return null;
    const auto it = j_.find(key);
    if (it == j_.end()) {
      if (required) fail("has no \"" + std::string(key) + "\"");
      return null;
    }
    return *it;
  }
  bool has(const char* key) { return ok() && j_.find(key) != j_.end(); }

  std::string text(const char* key, bool required = true) {
    const json& v = at(key, required);
    if (v.is_null()) return {};
    if (!v.is_string()) return wrong(key, v, "a string"), std::string();
    return v.get<std::string>();
  }
  bool flag(const char* key, bool required = true) {
    const json& v = at(key, required);
    if (v.is_null()) return false;
    if (!v.is_boolean()) return wrong(key, v, "true or false"), false;
    return v.get<bool>();
  }
  /// A number; null reads as NaN (a figure that could not be computed).
  double number(const char* key, bool required = true) { return number_of(key, at(key, required)); }
  std::int64_t integer(const char* key, bool required = true) {
    const json& v = at(key, required);
    if (v.is_null()) return 0;
    if (!v.is_number_integer()) return wrong(key, v, "an integer"), 0;
    return v.get<std::int64_t>();
  }
  std::size_t count(const char* key, bool required = true) {
    const std::int64_t n = integer(key, required);
    if (n < 0) return fail("has a negative \"" + std::string(key) + "\""), 0;
    return static_cast<std::size_t>(n);
  }
  std::vector<std::string> texts(const char* key, bool required = true) {
    std::vector<std::string> out;
    const json& v = at(key, required);
    if (v.is_null()) return out;
    if (!v.is_array()) return wrong(key, v, "an array of strings"), out;
    for (const auto& e : v) {
      if (!e.is_string())
        return fail("has an entry of \"" + std::string(key) + "\" that is not a string"), out;
      out.push_back(e.get<std::string>());
    }
    return out;
  }
  std::vector<std::int64_t> integers(const char* key, bool required = true) {
    std::vector<std::int64_t> out;
    const json& v = at(key, required);
    if (v.is_null()) return out;
    if (!v.is_array()) return wrong(key, v, "an array of integers"), out;
    for (const auto& e : v) {
      if (!e.is_number_integer())
        return fail("has an entry of \"" + std::string(key) + "\" that is not an integer"), out;
      out.push_back(e.get<std::int64_t>());
    }
    return out;
  }
  /// `n` numbers (null entries: NaN).
  std::vector<double> numbers(const char* key, std::size_t n, bool required = true) {
    const json& v = at(key, required);
    if (v.is_null()) return std::vector<double>(n, 0.0);
    return numbers_of(key, v, n);
  }
  Eigen::Vector3d vector3(const char* key, bool required = true) {
    const auto v = numbers(key, 3, required);
    return {v[0], v[1], v[2]};
  }
  Eigen::Matrix3d matrix3(const char* key) {
    Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
    const json& v = at(key, true);
    if (!ok()) return m;
    if (!v.is_array() || v.size() != 3) return fail("has a \"" + std::string(key) + "\" that is not 3x3"), m;
    for (std::size_t r = 0; r < 3; ++r) {
      const auto row = numbers_of(key, v[r], 3);
      m.row(static_cast<Eigen::Index>(r)) = Eigen::Vector3d(row[0], row[1], row[2]).transpose();
    }
    return m;
  }
  /// An optional step: "" or absent is none.
  std::optional<StepId> step(const char* key, bool required = true) {
    const std::string name = text(key, required);
    if (name.empty()) return std::nullopt;
    return named(parse_step(name));
  }
  /// A table's value, or the table's error as this message's.
  template <typename T>
  T named(Result<T> value) {
    if (value.ok()) return *value;
    fail(": " + value.error().message);
    return T{};
  }
  /// A sub-object read with its own Fields (null when absent and not required).
  const json& object(const char* key, bool required = true) {
    const json& v = at(key, required);
    if (!v.is_null() && !v.is_object()) wrong(key, v, "an object");
    return v;
  }
  const json& array(const char* key, bool required = true) {
    const json& v = at(key, required);
    if (!v.is_null() && !v.is_array()) wrong(key, v, "an array");
    return v;
  }
  const std::string& where() const { return where_; }

 private:
  std::vector<double> numbers_of(const char* key, const json& v, std::size_t n) {
    if (!v.is_array() || v.size() != n)
      return fail("has a \"" + std::string(key) + "\" that is not " + std::to_string(n) + " numbers"),
             std::vector<double>(n, 0.0);
    std::vector<double> out;
    for (const auto& e : v) out.push_back(number_of(key, e));
    return out;
  }
  double number_of(const char* key, const json& v) {
    if (v.is_null()) return std::numeric_limits<double>::quiet_NaN();
    if (!v.is_number()) return wrong(key, v, "a number"), 0.0;
    return v.get<double>();
  }
  void wrong(const char* key, const json& v, const char* kind) {
    fail(": \"" + std::string(key) + "\" is " + v.type_name() + ", not " + kind);
  }
  const json& j_;
  std::string where_;
  std::string error_;
};

template <typename M>
Result<SessionMessage> finish(Fields& f, M message) {
  if (!f.ok()) return make_error(Errc::kCorrupt, f.error());
  return SessionMessage(std::move(message));
}

std::optional<double> stamp(Fields& f) {
  if (!f.has("t")) return std::nullopt;
  return f.number("t");
}

Result<PreflightReport> read_report(const json& j, const std::string& where) {
  Fields f(j, where);
  PreflightReport r;
  r.rig = f.text("rig", false);
  const json& devices = f.array("devices", false);
  if (devices.is_array()) {
    for (const auto& d : devices) {
      Fields df(d, where + ": a device");
      r.devices.push_back(
          {df.text("name"), df.flag("ok"), df.text("detail", false), df.text("advice", false)});
      if (!df.ok()) return make_error(Errc::kCorrupt, df.error());
    }
  }
  const json& stored = f.at("stored", false);
  if (stored.is_object()) {
    json j = stored;
    const std::string summary = j.value("summary", std::string("stored"));
    j.erase("summary");
    auto record = calibration_record_from_json(j);
    if (record.ok()) {
      r.stored = PreflightReport::Stored{std::move(*record), summary};
    } else {
      r.stored_unreadable = record.error().message;
    }
  } else if (!stored.is_null()) {
    r.stored_unreadable = "the stored record is not a mapping";
  }
  if (std::string said = f.text("stored_unreadable", false); !said.empty())
    r.stored_unreadable = std::move(said);
  if (!f.ok()) return make_error(Errc::kCorrupt, f.error());
  return r;
}

Result<SessionMessage> read_status(Fields& f) {
  Status m;
  m.t = stamp(f);
  m.state = f.named(parse_session_state(f.text("state")));
  m.rig = f.text("rig", false);
  const json& steps = f.array("steps", false);
  if (steps.is_array()) {
    for (const auto& s : steps) {
      Fields sf(s, f.where() + ": a step");
      m.steps.push_back(
          {sf.named(parse_step(sf.text("name"))), sf.named(parse_step_state(sf.text("state")))});
      if (!sf.ok()) f.fail(": " + sf.error());
    }
  }
  m.step = f.step("step", false);
  m.poses = f.count("poses", false);
  m.elapsed_s = f.number("elapsed_s", false);
  if (f.has("devices")) {
    ServiceStatus s;
    Fields devices(f.object("devices"), f.where() + ": devices");
    Fields imu(devices.object("imu"), f.where() + ": devices: imu");
    s.devices.imu = {imu.named(parse_device_state(imu.text("state"))),
                     imu.flag("sim"),
                     imu.integer("samples"),
                     imu.integer("faults"),
                     imu.number("rate_hz"),
                     imu.text("gyro_offsets"),
                     imu.text("error")};
    s.devices.storage = devices.text("storage");
    const json& cams = devices.array("cameras", false);
    if (cams.is_array()) {
      for (const auto& c : cams) {
        Fields cf(c, f.where() + ": a camera");
        s.devices.cameras.push_back({cf.text("name"), cf.named(parse_device_state(cf.text("state"))),
                                     cf.integer("frames"), cf.integer("faults"), cf.text("error")});
        if (!cf.ok()) f.fail(": " + cf.error());
      }
    }
    if (!devices.ok()) f.fail(": " + devices.error());
    if (!imu.ok()) f.fail(": " + imu.error());
    s.session_dir = f.text("session_dir", false);
    s.version = f.text("version", false);
    s.recorded_bytes = static_cast<std::int64_t>(f.count("recorded_bytes", false));  // older services: 0
    if (f.has("live_view")) {
      Fields lv(f.object("live_view"), f.where() + ": live_view");
      s.live_view = LiveViewAddress{lv.text("url"), lv.text("token_file")};
      if (!lv.ok()) f.fail(": " + lv.error());
    }
    m.service = std::move(s);
  }
  return finish(f, std::move(m));
}

Result<SessionMessage> read_prompt(Fields& f) {
  Prompt m;
  m.t = stamp(f);
  m.step = f.step("step", false);
  m.text = f.text("text");
  for (const auto& k : f.texts("keys")) m.keys.push_back(f.named(parse_key(k)));
  m.art = f.texts("art", false);
  if (f.has("up")) m.up = f.vector3("up");
  return finish(f, std::move(m));
}

/// The motion figures' coverage (absent from older services: none).
std::vector<CameraCoverage> read_coverage(Fields& g) {
  std::vector<CameraCoverage> out;
  const json& cov = g.array("coverage", false);
  if (!cov.is_array()) return out;
  for (const auto& c : cov) {
    Fields cf(c, g.where() + ": coverage");
    CameraCoverage m;
    m.cols = static_cast<int>(cf.count("cols"));
    m.rows = static_cast<int>(cf.count("rows"));
    m.cells = cf.integers("cells");
    m.views = cf.integer("views");
    m.x = cf.number("x");
    m.y = cf.number("y");
    m.size = cf.number("size");
    m.skew = cf.number("skew");
    if (cf.ok() && m.cells.size() != static_cast<std::size_t>(m.cols) * static_cast<std::size_t>(m.rows))
      cf.fail("has " + std::to_string(m.cells.size()) + " cells, not cols x rows");
    if (!cf.ok()) {
      g.fail(": " + cf.error());
      return {};
    }
    out.push_back(std::move(m));
  }
  return out;
}

LiveFigures read_figures(Fields& f, const std::optional<StepId>& step) {
  if (!f.has("figures") || !step) return std::monostate{};
  const json& j = f.object("figures");
  const std::string where = f.where() + ": figures";
  Fields g(j, where);
  LiveFigures out;
  switch (*step) {
    case StepId::kPreflight: {
      auto report = read_report(j, where);
      if (!report.ok()) f.fail(": " + report.error().message);
      return report.ok() ? LiveFigures(*report) : LiveFigures();
    }
    case StepId::kWarmup:
      out = WarmupFigures{g.number("temperature_c"), g.number("rate_c_per_min")};
      break;
    case StepId::kThermal: {
      const auto range = g.numbers("range_c", 2);
      out = ThermalFigures{g.number("temperature_c"),
                           g.number("rate_c_per_min"),
                           {range[0], range[1]},
                           g.vector3("gyro_slope_dps_per_c"),
                           g.vector3("accel_slope_mps2_per_c")};
      break;
    }
    case StepId::kPoses:
      out = PoseFigures{g.count("poses"), g.flag("still"), g.texts("missing"), g.number("scale_sigma"),
                        g.count("poses_needed", false)};
      break;
    case StepId::kMotion: {
      MotionFigures m{g.vector3("gyro_rms_dps"),
                      g.integer("frames"),
                      g.integer("frames_seen"),
                      g.integers("camera_frames"),
                      g.integers("camera_frames_seen"),
                      g.integer("frames_seen_by_every_camera"),
                      read_coverage(g)};
      out = std::move(m);
      break;
    }
    default:
      g.fail("are not expected in this step");
  }
  if (!g.ok()) f.fail(": " + g.error());
  return out;
}

Result<SessionMessage> read_live(Fields& f) {
  Live m;
  m.t = stamp(f);
  m.step = f.step("step", false);
  m.lines = f.texts("lines");
  m.progress = f.number("progress", false);
  m.figures = read_figures(f, m.step);
  return finish(f, std::move(m));
}

Result<SessionMessage> read_result(Fields& f) {
  ResultSummary m;
  m.t = stamp(f);
  m.files = f.texts("files", false);
  if (f.has("thermal")) {
    Fields g(f.object("thermal"), f.where() + ": thermal");
    ResultSummary::Thermal t;
    t.determined = g.flag("determined");
    if (t.determined) {
      t.reference_c = g.number("reference_c");
      const auto range = g.numbers("valid_range_c", 2);
      t.valid_range_c = {range[0], range[1]};
    } else {
      t.reason = g.text("reason", false);
    }
    if (!g.ok()) f.fail(": " + g.error());
    m.thermal = t;
  }
  if (f.has("imu")) {
    Fields g(f.object("imu"), f.where() + ": imu");
    m.imu = ResultSummary::Imu{g.matrix3("A_a"), g.vector3("b_a"), g.matrix3("A_g"), g.vector3("b_g"),
                               g.matrix3("G")};
    if (!g.ok()) f.fail(": " + g.error());
  }
  if (f.has("cameras")) {
    m.cameras.emplace();
    const json& cams = f.array("cameras");
    for (const auto& c : cams.is_array() ? cams : json::array()) {
      Fields g(c, f.where() + ": a camera");
      const auto q = g.numbers("q_cam_imu_wxyz", 4);
      m.cameras->push_back({g.text("name"), g.vector3("t_cam_imu_m"), Eigen::Vector4d(q[0], q[1], q[2], q[3]),
                            g.number("timeshift_cam_imu_s"), g.number("reprojection_rms_px")});
      if (!g.ok()) f.fail(": " + g.error());
    }
  }
  if (f.has("self_check")) {
    Fields g(f.object("self_check"), f.where() + ": self_check");
    m.self_check =
        ResultSummary::SelfCheck{g.text("verdict"), g.text("summary", false), g.text("advice", false)};
    if (!g.ok()) f.fail(": " + g.error());
  }
  return finish(f, std::move(m));
}

Result<SessionMessage> read_review(Fields& f) {
  Review m;
  m.t = stamp(f);
  m.pass = f.flag("pass");
  const json& gates = f.array("gates", false);
  for (const auto& gate : gates.is_array() ? gates : json::array()) {
    Fields g(gate, f.where() + ": a gate");
    Review::Gate out{g.text("name"), g.number("value"), g.number("limit", false), g.flag("pass"),
                     std::nullopt};
    if (g.has("digits")) out.digits = static_cast<int>(g.integer("digits"));
    if (!g.ok()) f.fail(": " + g.error());
    m.gates.push_back(std::move(out));
  }
  m.lines = f.texts("lines", false);
  if (const json& d = f.object("difference_to_stored", false); d.is_object()) {
    Fields g(d, f.where() + ": difference_to_stored");
    m.difference_to_stored =
        Review::Difference{g.vector3("b_a"), g.vector3("b_g"), g.vector3("scale_a"), g.vector3("scale_g")};
    if (!g.ok()) f.fail(": " + g.error());
  }
  m.files = f.texts("files", false);
  return finish(f, std::move(m));
}

Result<SessionMessage> read_done(Fields& f) {
  Done m;
  m.t = stamp(f);
  m.outcome = f.named(parse_outcome(f.text("outcome")));
  m.text = f.text("text", false);
  if (f.has("stored")) m.stored = f.text("stored");
  m.reports = f.texts("reports", false);
  if (f.has("session_dir")) m.session_dir = f.text("session_dir");
  return finish(f, std::move(m));
}

Result<SessionMessage> read_solve(Fields& f) {
  Solve m;
  m.t = stamp(f);
  m.id = static_cast<int>(f.integer("id"));
  m.final = f.flag("final");
  m.samples = f.count("samples", false);
  if (f.has("thermal_means")) m.thermal_means = f.count("thermal_means");
  if (f.has("camimu")) m.camimu = f.flag("camimu");
  return finish(f, std::move(m));
}

Result<SessionMessage> read_simple(const std::string& type, Fields& f) {
  if (type == "session") {
    if (f.text("event") != "start") f.fail("is not a session start (\"event\": \"start\")");
    return finish(f, SessionStart{stamp(f), f.texts("steps", false)});
  }
  if (type == "message")
    return finish(
        f, Message{stamp(f), f.named(parse_level(f.text("level"))), f.text("text"), MessageCause::kNone});
  if (type == "fault")
    return finish(f, Fault{stamp(f), f.text("source", false), f.step("step", false), f.text("text", false),
                           f.text("advice", false)});
  if (type == "preflight") {
    const json& j = f.object("report", false);
    auto report =
        j.is_null() ? Result<PreflightReport>(PreflightReport{}) : read_report(j, f.where() + ": report");
    if (!report.ok()) return report.error();
    return finish(f, Preflight{stamp(f), std::move(*report)});
  }
  if (type == "key") return finish(f, Key{stamp(f), f.named(parse_key(f.text("key")))});
  if (type == "stop") return finish(f, Stop{stamp(f), f.text("reason", false)});
  if (type == "applied")
    return finish(f, Applied{stamp(f), static_cast<int>(f.integer("id")), f.text("error", false),
                             f.number("wall_s", false)});
  if (type == "written") {
    Written m{stamp(f), f.flag("ok"), f.text("error", false), std::nullopt};
    if (f.has("where")) m.where = f.text("where");
    return finish(f, std::move(m));
  }
  if (type == "pose") return finish(f, PoseCaptured{stamp(f), f.count("index"), f.vector3("up")});
  if (type == "face") return finish(f, FaceHeld{stamp(f), f.text("face"), f.vector3("up")});
  return make_error(Errc::kCorrupt, "a session message of type \"" + type +
                                        "\", which this version does not know (from a newer service?)");
}

}  // namespace

Result<PreflightReport> decode_preflight_report(const json& report) {
  return read_report(report, "a preflight report");
}

Result<SessionMessage> decode(const json& message) {
  if (!message.is_object()) return make_error(Errc::kCorrupt, "the session message is not a JSON object");
  const auto type_it = message.find("type");
  if (type_it == message.end() || !type_it->is_string())
    return make_error(Errc::kCorrupt, "the session message has no type (a string)");
  const std::string type = type_it->get<std::string>();
  Fields f(message, "the session message (" + type + ")");
  if (type == "status") return read_status(f);
  if (type == "prompt") return read_prompt(f);
  if (type == "live") return read_live(f);
  if (type == "result") return read_result(f);
  if (type == "review") return read_review(f);
  if (type == "done") return read_done(f);
  if (type == "solve") return read_solve(f);
  return read_simple(type, f);
}

Result<SessionMessage> parse(std::string_view text) {
  const json j = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded())
    return make_error(Errc::kCorrupt, "the session message is not a JSON object (not valid JSON)");
  return decode(j);
}

std::string type_of(std::string_view text) {
  const json j = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) return {};
  const auto it = j.find("type");
  return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

Result<FrameEvent> parse_frame_event(std::string_view text) {
  const json j = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  Fields f(j, "the frame event");
  FrameEvent e{f.count("camera", false), f.integer("t_ns"), f.flag("seen")};
  if (!f.ok()) return make_error(Errc::kCorrupt, f.error());
  return e;
}

}  // namespace imucal::session_msg
