#include "daemon/ctl/console.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/text_format.hpp"
#include "daemon/service/protocol.hpp"

namespace imucal::ctl {
namespace {

using nlohmann::json;

// Service messages are parsed defensively: a field of the wrong type reads as absent.
std::string str(const json& j, const char* key) {
  if (j.is_object()) {
    const auto it = j.find(key);
    if (it != j.end() && it->is_string()) {
      return it->get<std::string>();
    }
  }
  return {};
}

std::optional<double> num(const json& j, const char* key) {
  if (j.is_object()) {
    const auto it = j.find(key);
    if (it != j.end() && it->is_number()) {
      return it->get<double>();
    }
  }
  return std::nullopt;
}

bool flag(const json& j, const char* key, bool fallback) {
  if (j.is_object()) {
    const auto it = j.find(key);
    if (it != j.end() && it->is_boolean()) {
      return it->get<bool>();
    }
  }
  return fallback;
}

const json& array(const json& j, const char* key) {
  static const json empty = json::array();
  if (j.is_object()) {
    const auto it = j.find(key);
    if (it != j.end() && it->is_array()) {
      return *it;
    }
  }
  return empty;
}

std::string mark(const std::string& state) {
  if (state == "done") return "[x]";
  if (state == "active") return "[>]";
  if (state == "skipped") return "[-]";
  if (state == "failed") return "[!]";
  return "[ ]";
}

std::string fault_text(const json& message) {
  std::string text = "FAULT";
  if (const auto step = str(message, "step"); !step.empty()) {
    text += " [" + step + "]";
  }
  text += ": " + str(message, "text");
  if (const auto advice = str(message, "advice"); !advice.empty()) {
    text += " -- " + advice;
  }
  return text;
}

std::string message_text(const json& message) {
  const std::string level = str(message, "level").empty() ? "info" : str(message, "level");
  return level + ": " + str(message, "text");
}

// "step 3 of 5: poses" from the status's step list, or just the step's name.
std::string step_position(const json& status) {
  const std::string step = str(status, "step");
  const json& steps = array(status, "steps");
  for (std::size_t i = 0; i < steps.size(); ++i) {
    if (str(steps[i], "name") == step && !step.empty()) {
      return "step " + std::to_string(i + 1) + " of " + std::to_string(steps.size()) + ": " + step;
    }
  }
  return step.empty() ? "" : "step: " + step;
}

std::string header(const json& status) {
  if (!status.is_object()) {
    return "imucal  (waiting for the service's status)";
  }
  std::string line = "imucal  rig " + (str(status, "rig").empty() ? "?" : str(status, "rig"));
  line += "  |  " + (str(status, "state").empty() ? "?" : str(status, "state"));
  if (const auto position = step_position(status); !position.empty()) {
    line += "  |  " + position;
  }
  if (const auto elapsed = num(status, "elapsed_s")) {
    line += "  |  " + fixed(*elapsed, 1) + " s";
  }
  return line;
}

std::string gate_line(const json& gate) {
  std::string line = "  " + std::string(flag(gate, "pass", false) ? "pass " : "FAIL ") + str(gate, "name");
  const auto value = num(gate, "value");
  const auto limit = num(gate, "limit");
  // The decimals the service chose for the figure (a count has none); 3 from older services.
  const auto digits = num(gate, "digits");
  const int d = digits && *digits >= 0 && *digits <= 9 ? static_cast<int>(*digits) : 3;
  if (value) {
    line += "  " + fixed(*value, d);
  } else if (gate.is_object() && gate.contains("value") && gate["value"].is_null()) {
    line += "  not determined";  // a figure that could not be computed (NaN travels as null)
  }
  if (limit) {
    line += "  (limit " + fixed(*limit, d) + ")";
  }
  return line;
}

const char* key_letter(const std::string& key) {
  if (key == "continue") return "c";
  if (key == "redo") return "r";
  if (key == "abort") return "a";
  if (key == "accept") return "y";
  if (key == "reject") return "n";
  if (key == "skip") return "s";
  return nullptr;
}

std::string key_help(const ConsoleState& state) {
  if (state.confirm_abort) {
    return "Abort the session? y: yes, abort  n: no, go on";
  }
  if (state.observe) {
    return "observing (keys are not sent)  q detach";
  }
  std::string help;
  for (const auto& key : array(state.prompt, "keys")) {
    if (key.is_string()) {
      if (const char* letter = key_letter(key.get<std::string>())) {
        help += std::string(letter) + " " + key.get<std::string>() + "  ";
      }
    }
  }
  return help + "q detach";
}

void add_recent(ConsoleState& state, std::string text) {
  state.recent.push_back(std::move(text));
  while (state.recent.size() > state.max_recent) {
    state.recent.pop_front();
  }
}

void add_section(std::vector<std::string>& lines, const ConsoleState& state, int width) {
  if (state.prompt.is_object()) {
    lines.emplace_back("");
    lines.push_back(">> " + str(state.prompt, "text"));
  }
  if (state.live.is_object()) {
    lines.emplace_back("");
    for (const auto& line : array(state.live, "lines")) {
      if (line.is_string()) {
        lines.push_back("   " + line.get<std::string>());
      }
    }
    if (const auto progress = num(state.live, "progress")) {
      lines.push_back("   " + progress_bar(*progress, std::clamp(width - 12, 10, 50)));
    }
  }
  if (state.review.is_object()) {
    lines.emplace_back("");
    lines.push_back(std::string("Review: ") + (flag(state.review, "pass", false) ? "PASS" : "FAIL"));
    for (const auto& gate : array(state.review, "gates")) {
      lines.push_back(gate_line(gate));
    }
    for (const auto& line : array(state.review, "lines")) {
      if (line.is_string()) {
        lines.push_back("  " + line.get<std::string>());
      }
    }
  }
  if (state.done.is_object()) {
    lines.emplace_back("");
    lines.push_back("Session " + str(state.done, "outcome") + ": " + str(state.done, "text"));
    if (const std::string stored = str(state.done, "stored"); !stored.empty()) {
      lines.push_back("Stored on: " + stored);
    }
    if (const std::string dir = str(state.done, "session_dir"); !dir.empty()) {
      lines.push_back("Session folder: " + dir);
    }
  }
}

}  // namespace

void update(ConsoleState& state, const json& message) {
  const std::string type = str(message, "type");
  if (type == "status") {
    if (str(message, "step") != str(state.status, "step")) {
      state.live = nullptr;  // figures of the previous step are no longer news
    }
    const std::string session = str(message, "state");
    if (session == "running" || session == "idle") {
      state.review = nullptr;
    }
    if (session == "running") {
      state.done = nullptr;
    }
    state.status = message;
  } else if (type == "prompt") {
    if (str(message, "step") != str(state.live, "step")) {
      state.live = nullptr;
    }
    state.prompt = message;
  } else if (type == "live") {
    state.live = message;
  } else if (type == "message") {
    add_recent(state, message_text(message));
  } else if (type == "fault") {
    add_recent(state, fault_text(message));
  } else if (type == "review") {
    state.review = message;
  } else if (type == "done") {
    state.done = message;
    state.prompt = nullptr;
    state.live = nullptr;
  } else if (type == "reply") {
    if (!flag(message, "ok", true)) {
      state.notice = str(message, "cmd") + " refused: " + str(message, "error");
    } else if (const std::string cmd = str(message, "cmd");
               cmd == service::command_name(service::Command::kKey) ||
               cmd == service::command_name(service::Command::kAbort) ||
               cmd == service::command_name(service::Command::kAccept)) {
      state.notice.clear();
    }
  }
}

std::string render(const ConsoleState& state, const RenderOptions& options) {
  const int width = std::max(options.width, 20);
  std::vector<std::string> lines;
  lines.push_back(header(state.status));
  lines.emplace_back(static_cast<std::size_t>(width), '-');
  for (const auto& step : array(state.status, "steps")) {
    lines.push_back(" " + mark(str(step, "state")) + " " + str(step, "name"));
  }
  add_section(lines, state, width);
  if (!state.recent.empty()) {
    lines.emplace_back("");
    for (const auto& text : state.recent) {
      lines.push_back(" " + text);
    }
  }
  if (!state.notice.empty()) {
    lines.emplace_back("");
    lines.push_back("! " + state.notice);
  }
  lines.emplace_back(static_cast<std::size_t>(width), '-');
  lines.push_back(key_help(state));
  std::string screen;
  for (auto& line : lines) {
    if (line.size() > static_cast<std::size_t>(width)) {
      line.resize(static_cast<std::size_t>(width));
    }
    screen += line + '\n';
  }
  return screen;
}

std::optional<std::string> plain_line(const json& message) {
  const std::string type = str(message, "type");
  if (type == "status") {
    std::string line = "status: " + str(message, "state");
    if (const auto position = step_position(message); !position.empty()) {
      line += ", " + position;
    }
    return line;
  }
  if (type == "prompt") {
    return "prompt [" + str(message, "step") + "]: " + str(message, "text");
  }
  if (type == "live") {
    std::string line = "live [" + str(message, "step") + "]:";
    for (const auto& text : array(message, "lines")) {
      if (text.is_string()) {
        line += " " + text.get<std::string>() + ";";
      }
    }
    if (const auto progress = num(message, "progress")) {
      line += " " + fixed(100.0 * std::clamp(*progress, 0.0, 1.0), 0) + "%";
    }
    return line;
  }
  if (type == "message") {
    return message_text(message);
  }
  if (type == "fault") {
    return fault_text(message);
  }
  if (type == "review") {
    std::string line = std::string("review: ") + (flag(message, "pass", false) ? "pass" : "fail");
    for (const auto& gate : array(message, "gates")) {
      line += ";" + gate_line(gate).substr(1);
    }
    return line;
  }
  if (type == "done") {
    const std::string stored = str(message, "stored"), dir = str(message, "session_dir");
    return "done: " + str(message, "outcome") + ": " + str(message, "text") +
           (stored.empty() ? std::string() : " (stored on " + stored + ")") +
           (dir.empty() ? std::string() : " (session folder " + dir + ")");
  }
  if (type == "reply" && !flag(message, "ok", true)) {
    return "error: " + str(message, "cmd") + " refused: " + str(message, "error");
  }
  return std::nullopt;
}

std::string status_text(const json& status) {
  std::ostringstream out;
  out << "state:   " << str(status, "state") << '\n';
  out << "rig:     " << str(status, "rig") << '\n';
  if (const auto position = step_position(status); !position.empty()) {
    out << "step:    " << position << '\n';
  }
  const json& steps = array(status, "steps");
  if (!steps.empty()) {
    out << "steps:  ";
    for (const auto& step : steps) {
      out << ' ' << mark(str(step, "state")) << ' ' << str(step, "name");
    }
    out << '\n';
  }
  if (const auto elapsed = num(status, "elapsed_s")) {
    out << "elapsed: " << fixed(*elapsed, 1) << " s\n";
  }
  if (status.is_object() && status.contains("devices") && !status["devices"].empty()) {
    out << "devices: " << status["devices"].dump(-1, ' ', false, json::error_handler_t::replace) << '\n';
  }
  return out.str();
}

KeyAction on_key(ConsoleState& state, char key) {
  if (key == 'q' || key == 3 || key == 4) {
    return {std::nullopt, true};
  }
  if (state.confirm_abort) {
    state.confirm_abort = false;
    if (key == 'y') {
      return {service::to_json(service::plain_request(service::Command::kAbort)), false};
    }
    return {};
  }
  if (state.observe) {
    return {};
  }
  auto send_key = [](const char* name) {
    return KeyAction{service::to_json(service::key_request(name)), false};
  };
  switch (key) {
    case 'c':
    case ' ':
    case '\r':
    case '\n':
      return send_key("continue");
    case 'r':
      return send_key("redo");
    case 'a':
      state.confirm_abort = true;
      return {};
    case 'y':
      return send_key("accept");
    case 'n':
      return send_key("reject");
    case 's':
      return send_key("skip");
    default:
      return {};
  }
}

std::string progress_bar(double progress, int width) {
  const double p = std::isfinite(progress) ? std::clamp(progress, 0.0, 1.0) : 0.0;
  const int cells = std::max(width - 2, 1);
  const int filled = static_cast<int>(std::lround(p * cells));
  char percent[16];
  std::snprintf(percent, sizeof(percent), " %3d%%", static_cast<int>(std::lround(p * 100.0)));
  return "[" + std::string(static_cast<std::size_t>(filled), '#') +
         std::string(static_cast<std::size_t>(cells - filled), '-') + "]" + percent;
}

}  // namespace imucal::ctl
