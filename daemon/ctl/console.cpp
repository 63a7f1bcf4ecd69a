#include "daemon/ctl/console.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/printable_text.hpp"
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

bool is_running(const json& status) {
  const std::string state = str(status, "state");
  return state == "running" || state == "review";
}

std::string header(const ConsoleState& state, double idle_s) {
  const json& status = state.status;
  if (!status.is_object()) {
    return "imucal  (waiting for the service's status)";
  }
  std::string line = "imucal  rig " + (str(status, "rig").empty() ? "?" : str(status, "rig"));
  line += "  |  " + (str(status, "state").empty() ? "?" : str(status, "state"));
  if (const auto position = step_position(status); !position.empty()) {
    line += "  |  " + position;
  }
  if (auto elapsed = num(status, "elapsed_s"); elapsed && str(status, "state") != "idle") {
    // Status comes at step changes; the session's clock (every message's "t") and the wall
    // time since the last message carry the elapsed time between them.
    if (is_running(status)) {
      if (state.status_clock_s >= 0.0 && state.clock_s > state.status_clock_s) {
        *elapsed += state.clock_s - state.status_clock_s;
      }
      *elapsed += std::clamp(idle_s, 0.0, 86400.0);
    }
    line += "  |  " + fixed(*elapsed, 0) + " s";
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
  if (state.confirm) {
    return state.confirm->question + "  y: yes  any other key: no";
  }
  if (state.observe) {
    return "observing (keys are not sent)  q detach";
  }
  if (state.status.is_object() && !is_running(state.status)) {
    return std::string(state.done.is_object() ? "c start the next session" : "c start a session") +
           "  q detach";
  }
  std::string help;
  for (const auto& key : array(state.prompt, "keys")) {
    if (key.is_string()) {
      if (const char* letter = key_letter(key.get<std::string>())) {
        help += std::string(letter) + " " + key.get<std::string>() + "  ";
      }
    }
  }
  if (state.status.is_object()) {
    help += "R restart  ";
  }
  return help + "q detach";
}

void add_recent(ConsoleState& state, std::string text) {
  state.recent.push_back(std::move(text));
  while (state.recent.size() > state.max_recent) {
    state.recent.pop_front();
  }
}

// `line` in pieces of at most `width` columns, broken at a space where one is near the end;
// continuation lines keep the line's indent and two more columns.
std::vector<std::string> wrap(const std::string& line, std::size_t width) {
  std::vector<std::string> out;
  if (line.size() <= width) {
    out.push_back(line);
    return out;
  }
  const std::size_t indent =
      std::min(line.find_first_not_of(' ') == std::string::npos ? 0 : line.find_first_not_of(' '),
               width / 3) +
      2;
  std::string rest = line;
  bool first = true;
  while (!rest.empty()) {
    const std::string lead = first ? std::string() : std::string(indent, ' ');
    const std::size_t room = width - lead.size();
    if (rest.size() <= room) {
      out.push_back(lead + rest);
      break;
    }
    std::size_t cut = rest.rfind(' ', room);
    if (cut == std::string::npos || cut < room / 2) cut = room;
    out.push_back(lead + rest.substr(0, cut));
    rest.erase(0, cut);
    rest.erase(0,
               rest.find_first_not_of(' ') == std::string::npos ? rest.size() : rest.find_first_not_of(' '));
    first = false;
  }
  return out;
}

// A part of the screen between the header and the keys.
struct Block {
  std::vector<std::string> lines;  // before wrapping
  bool wraps = true;               // a drawing is cut, never wrapped
};

Block steps_block(const ConsoleState& state, bool compact) {
  Block block;
  const json& steps = array(state.status, "steps");
  if (compact) {
    std::string line;
    for (const auto& step : steps) {
      line += (line.empty() ? " " : "  ") + mark(str(step, "state")) + " " + str(step, "name");
    }
    if (!line.empty()) block.lines.push_back(line);
    return block;
  }
  for (const auto& step : steps) {
    block.lines.push_back(" " + mark(str(step, "state")) + " " + str(step, "name"));
  }
  return block;
}

Block prompt_block(const ConsoleState& state) {
  Block block;
  if (state.prompt.is_object()) {
    block.lines = {"", ">> " + str(state.prompt, "text")};
  }
  return block;
}

Block art_block(const ConsoleState& state) {
  Block block;
  block.wraps = false;
  for (const auto& line : array(state.prompt, "art")) {
    if (line.is_string()) block.lines.push_back("   " + line.get<std::string>());
  }
  return block;
}

Block live_block(const ConsoleState& state, int width) {
  Block block;
  if (!state.live.is_object()) return block;
  block.lines.emplace_back("");
  for (const auto& line : array(state.live, "lines")) {
    if (line.is_string()) block.lines.push_back("   " + line.get<std::string>());
  }
  if (const auto progress = num(state.live, "progress")) {
    block.lines.push_back("   " + progress_bar(*progress, std::clamp(width - 12, 10, 50)));
  }
  return block;
}

Block review_block(const ConsoleState& state) {
  Block block;
  if (!state.review.is_object()) return block;
  block.lines.emplace_back("");
  block.lines.push_back(std::string("Review: ") + (flag(state.review, "pass", false) ? "PASS" : "FAIL"));
  for (const auto& gate : array(state.review, "gates")) {
    block.lines.push_back(gate_line(gate));
  }
  for (const auto& line : array(state.review, "lines")) {
    if (line.is_string()) block.lines.push_back("  " + line.get<std::string>());
  }
  return block;
}

Block done_block(const ConsoleState& state) {
  Block block;
  if (!state.done.is_object()) return block;
  block.lines.emplace_back("");
  block.lines.push_back("Session " + str(state.done, "outcome") + ": " + str(state.done, "text"));
  if (const std::string stored = str(state.done, "stored"); !stored.empty()) {
    block.lines.push_back("Stored on: " + stored);
  }
  if (const std::string dir = str(state.done, "session_dir"); !dir.empty()) {
    block.lines.push_back("Session folder: " + dir);
  }
  for (const auto& report : array(state.done, "reports")) {
    if (report.is_string()) block.lines.push_back("Report: " + report.get<std::string>());
  }
  return block;
}

Block recent_block(const ConsoleState& state, std::size_t keep) {
  Block block;
  if (state.recent.empty() || keep == 0) return block;
  block.lines.emplace_back("");
  const std::size_t skip = state.recent.size() > keep ? state.recent.size() - keep : 0;
  for (std::size_t i = skip; i < state.recent.size(); ++i) {
    block.lines.push_back(" " + state.recent[i]);
  }
  return block;
}

void put(std::vector<std::string>& out, const Block& block, std::size_t width) {
  for (const auto& line : block.lines) {
    if (!block.wraps) {
      out.push_back(line.size() > width ? line.substr(0, width) : line);
      continue;
    }
    for (auto& piece : wrap(line, width)) out.push_back(std::move(piece));
  }
}

// The middle of the screen. `level` says how much was given up to fit: 0 all, 1 the step list on
// one line, 2 without the drawing, then older messages one by one.
std::vector<std::string> middle(const ConsoleState& state, std::size_t width, int level, std::size_t recent) {
  std::vector<std::string> out;
  put(out, steps_block(state, level >= 1), width);
  put(out, prompt_block(state), width);
  if (level < 2) put(out, art_block(state), width);
  put(out, live_block(state, static_cast<int>(width)), width);
  put(out, review_block(state), width);
  put(out, done_block(state), width);
  put(out, recent_block(state, recent), width);
  return out;
}

}  // namespace

void update(ConsoleState& state, const json& message) {
  const std::string type = str(message, "type");
  if (const auto t = num(message, "t"); t && std::isfinite(*t)) {
    if (type == "status" || state.status_clock_s < 0.0) state.status_clock_s = *t;
    state.clock_s = *t;
  } else if (type == "status") {
    state.status_clock_s = -1.0;  // a status without the clock (a snapshot): the next message's
  }
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
    if (state.start_after_done) {
      state.start_after_done = false;  // restart: the session ended, the next one starts
      state.outbox.push_back(service::to_json(service::plain_request(service::Command::kStart)));
    }
  } else if (type == "reply") {
    if (!flag(message, "ok", true)) {
      if (state.start_after_done && str(message, "cmd") == service::command_name(service::Command::kAbort)) {
        state.start_after_done = false;  // nothing to abort: start at once
        state.outbox.push_back(service::to_json(service::plain_request(service::Command::kStart)));
      }
      state.notice = str(message, "cmd") + " refused: " + str(message, "error");
    } else if (const std::string cmd = str(message, "cmd");
               cmd == service::command_name(service::Command::kKey) ||
               cmd == service::command_name(service::Command::kAbort) ||
               cmd == service::command_name(service::Command::kStart) ||
               cmd == service::command_name(service::Command::kAccept)) {
      state.notice.clear();
    }
  }
}

std::string render(const ConsoleState& state, const RenderOptions& options) {
  const std::size_t width = static_cast<std::size_t>(std::max(options.width, 20));
  std::vector<std::string> top;
  for (auto& line : wrap(header(state, options.idle_s), width)) top.push_back(std::move(line));
  top.emplace_back(width, '-');
  std::vector<std::string> bottom;
  if (!state.notice.empty()) {
    for (auto& line : wrap("! " + state.notice, width)) bottom.push_back(std::move(line));
  }
  bottom.emplace_back(width, '-');
  for (auto& line : wrap(key_help(state), width)) bottom.push_back(std::move(line));

  std::vector<std::string> mid = middle(state, width, 0, state.recent.size());
  if (options.height > 0) {
    // What fits between the header and the keys: fold the steps, drop the drawing, then the
    // oldest messages, then cut the end (the keys still show).
    const std::size_t rows = static_cast<std::size_t>(std::max(options.height, 4));
    const std::size_t room = rows > top.size() + bottom.size() ? rows - top.size() - bottom.size() : 0;
    int level = 0;
    std::size_t recent = state.recent.size();
    while (mid.size() > room) {
      if (level < 2) {
        ++level;
      } else if (recent > 0) {
        --recent;
      } else {
        break;
      }
      mid = middle(state, width, level, recent);
    }
    if (mid.size() > room) {
      mid.resize(room);
      if (room > 0) mid.back() = "  ... (more than fits: a larger terminal shows it all)";
    }
  }
  // The service's text (prompts, messages, a controller's name in a refusal) reaches the terminal
  // only with its control characters replaced: no escape sequence of a client's gets through.
  std::string screen;
  for (const auto* part : {&top, &mid, &bottom}) {
    for (const auto& line : *part)
      screen += printable_text(line.size() > width ? line.substr(0, width) : line) + '\n';
  }
  return screen;
}

namespace {

std::optional<std::string> plain_line_of(const json& message) {
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
    std::string reports;
    for (const auto& report : array(message, "reports")) {
      if (report.is_string()) reports += (reports.empty() ? " (report " : ", ") + report.get<std::string>();
    }
    return "done: " + str(message, "outcome") + ": " + str(message, "text") +
           (stored.empty() ? std::string() : " (stored on " + stored + ")") +
           (dir.empty() ? std::string() : " (session folder " + dir + ")") +
           (reports.empty() ? "" : reports + ")");
  }
  if (type == "reply" && !flag(message, "ok", true)) {
    return "error: " + str(message, "cmd") + " refused: " + str(message, "error");
  }
  return std::nullopt;
}

}  // namespace

std::optional<std::string> plain_line(const json& message) {
  auto line = plain_line_of(message);
  if (line) *line = printable_text(*line);
  return line;
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
  return printable_text(out.str(), true);
}

bool session_running(const ConsoleState& state) { return is_running(state.status); }

KeyAction on_key(ConsoleState& state, char key) {
  if (key == 'q' || key == 3 || key == 4) {
    return {std::nullopt, true};
  }
  if (state.confirm) {
    Confirm confirm = std::move(*state.confirm);
    state.confirm.reset();
    if (key != 'y') {
      state.notice = "Not done: " + confirm.question;
      return {};
    }
    state.start_after_done = confirm.then_start;
    return {confirm.request, false};
  }
  if (state.observe) {
    return {};
  }
  auto key_request = [](const char* name) { return service::to_json(service::key_request(name)); };
  auto ask = [&state](std::string question, json request, bool then_start = false) {
    state.confirm = Confirm{std::move(question), std::move(request), then_start};
    return KeyAction{};
  };
  const bool start_key = key == 'c' || key == ' ' || key == '\r' || key == '\n' || key == 'R';
  if (state.status.is_object() && !is_running(state.status)) {
    if (start_key) {
      state.notice.clear();
      return {service::to_json(service::plain_request(service::Command::kStart)), false};
    }
    state.notice = "No session is running: press c to start one";
    return {};
  }
  const std::string step =
      str(state.status, "step").empty() ? str(state.prompt, "step") : str(state.status, "step");
  const auto progress = str(state.live, "step") == step ? num(state.live, "progress") : std::nullopt;
  switch (key) {
    case 'c':
    case ' ':
    case '\r':
    case '\n':
      // Going on before the step's own end throws its remaining time away: ask.
      if (progress && *progress < 0.999 && step != "preflight") {
        return ask(
            "End the " + step + " step now, at " + fixed(100.0 * std::clamp(*progress, 0.0, 1.0), 0) + " %?",
            key_request("continue"));
      }
      return {key_request("continue"), false};
    case 'r':
      return {key_request("redo"), false};
    case 'a':
      return ask("Abort the session? What was recorded is kept, nothing is written.",
                 service::to_json(service::plain_request(service::Command::kAbort)));
    case 'R':
      return ask("Restart: abort this session and start a new one?",
                 service::to_json(service::plain_request(service::Command::kAbort)), true);
    case 'y':
      return {key_request("accept"), false};
    case 'n':
      return ask("Reject this calibration? Nothing is written; the results stay in the session folder.",
                 key_request("reject"));
    case 's':
      return ask("Skip the " + (step.empty() ? std::string("current") : step) +
                     " step? What it recorded is not used.",
                 key_request("skip"));
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
