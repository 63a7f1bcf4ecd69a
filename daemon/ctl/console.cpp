// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/ctl/console.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include "core/printable_text.hpp"
#include "core/text_format.hpp"
#include "daemon/service/protocol.hpp"

namespace imucal::ctl {
namespace {

/// The start of the notice for a poses step the operator tried to end too soon.
constexpr const char* kNotYetPoses = "Not yet: the poses step ends with at least ";

using nlohmann::json;
namespace msg = session_msg;

std::string step_text(const std::optional<msg::StepId>& step) { return step ? msg::step_name(*step) : ""; }

std::string mark(msg::StepState state) {
  switch (state) {
    case msg::StepState::kDone:
      return "[x]";
    case msg::StepState::kActive:
      return "[>]";
    case msg::StepState::kSkipped:
      return "[-]";
    case msg::StepState::kFailed:
      return "[!]";
    case msg::StepState::kPending:
      break;
  }
  return "[ ]";
}

std::string fault_text(const msg::Fault& message) {
  std::string text = "FAULT";
  if (message.step) {
    text += " [" + step_text(message.step) + "]";
  }
  text += ": " + message.text;
  if (!message.advice.empty()) {
    text += " -- " + message.advice;
  }
  return text;
}

std::string message_text(const msg::Message& message) {
  return std::string(msg::level_name(message.level)) + ": " + message.text;
}

// "step 3 of 5: poses" from the status's step list, or just the step's name.
std::string step_position(const msg::Status& status) {
  if (!status.step) return "";
  const std::string step = step_text(status.step);
  for (std::size_t i = 0; i < status.steps.size(); ++i) {
    if (status.steps[i].name == *status.step) {
      return "step " + std::to_string(i + 1) + " of " + std::to_string(status.steps.size()) + ": " + step;
    }
  }
  return "step: " + step;
}

bool is_running(const msg::Status& status) {
  return status.state == msg::SessionState::kRunning || status.state == msg::SessionState::kReview;
}

/// Bytes as "850 kB", "12.3 MB" or "1.42 GB" (decimal units, as df -H).
std::string recorded_text(std::int64_t bytes) {
  const double b = static_cast<double>(bytes);
  if (b < 1e6) return fixed(b / 1e3, 0) + " kB";
  if (b < 1e9) return fixed(b / 1e6, 1) + " MB";
  return fixed(b / 1e9, 2) + " GB";
}

std::string header(const ConsoleState& state, double idle_s) {
  if (!state.lost.empty()) {
    return "imucal  |  imucald is gone: below is the last it sent, no longer live";
  }
  if (!state.status) {
    return "imucal  (waiting for the service's status)";
  }
  const msg::Status& status = *state.status;
  std::string line = "imucal  rig " + (status.rig.empty() ? "?" : status.rig);
  line += "  |  " + std::string(msg::session_state_name(status.state));
  if (const auto position = step_position(status); !position.empty()) {
    line += "  |  " + position;
  }
  if (double elapsed = status.elapsed_s; std::isfinite(elapsed) && status.state != msg::SessionState::kIdle) {
    // Status comes at step changes; the session's clock (every message's "t") and the wall
    // time since the last message carry the elapsed time between them.
    if (is_running(status)) {
      if (state.status_clock_s >= 0.0 && state.clock_s > state.status_clock_s) {
        elapsed += state.clock_s - state.status_clock_s;
      }
      elapsed += std::clamp(idle_s, 0.0, 86400.0);
    }
    line += "  |  " + fixed(elapsed, 0) + " s";
  }
  // What the session has recorded, so that a session left at a prompt is seen to grow.
  if (state.recorded_bytes > 0 && status.state != msg::SessionState::kIdle) {
    line += "  |  " + recorded_text(state.recorded_bytes) + " recorded";
  }
  return line;
}

std::string gate_line(const msg::Review::Gate& gate) {
  std::string line = "  " + std::string(gate.pass ? "pass " : "FAIL ") + gate.name;
  // The decimals the service chose for the figure (a count has none); 3 from older services.
  const int d = gate.digits && *gate.digits >= 0 && *gate.digits <= 9 ? *gate.digits : 3;
  if (std::isfinite(gate.value)) {
    line += "  " + fixed(gate.value, d);
  } else {
    line += "  not determined";  // a figure that could not be computed (NaN travels as null)
  }
  if (std::isfinite(gate.limit)) {
    line += "  (limit " + fixed(gate.limit, d) + ")";
  }
  return line;
}

/// Rows one press of d or u scrolls the review by.
constexpr std::size_t kReviewScrollRows = 8;

/// The console's own keys; the operator's (c, r, a, y, n, s) are msg::key_letter's.
constexpr char kQuitKey = 'q', kRestartKey = 'R', kScrollDownKey = 'd', kScrollUpKey = 'u', kYesKey = 'y',
               kNoKey = 'n', kEscapeKey = 27, kCtrlC = 3, kCtrlD = 4;

std::string letter(char key) { return std::string(1, key); }

std::string key_help(const ConsoleState& state) {
  if (!state.lost.empty()) {
    return "imucalctl has ended; run it again once imucald is back";
  }
  if (state.confirm) {
    return state.confirm->question + "  " + letter(kYesKey) + ": yes  " + letter(kNoKey) +
           ": no  (another key: no, then its own action)";
  }
  if (state.observe) {
    return "observing (keys are not sent)  " + letter(kQuitKey) + " detach";
  }
  if (state.status && !is_running(*state.status)) {
    return letter(msg::key_letter(msg::OperatorKey::kContinue)) +
           (state.done ? " start the next session" : " start a session") + "  " + letter(kQuitKey) +
           " detach";
  }
  std::string help;
  if (state.prompt) {
    for (const msg::OperatorKey key : state.prompt->keys) {
      help += letter(msg::key_letter(key)) + " " + msg::key_name(key) + "  ";
    }
  }
  if (state.status) {
    help += letter(kRestartKey) + " restart  ";
  }
  return help + letter(kQuitKey) + " detach";
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
  if (!state.status) return block;
  const auto& steps = state.status->steps;
  if (compact) {
    std::string line;
    for (const auto& step : steps) {
      line += (line.empty() ? " " : "  ") + mark(step.state) + " " + msg::step_name(step.name);
    }
    if (!line.empty()) block.lines.push_back(line);
    return block;
  }
  for (const auto& step : steps) {
    block.lines.push_back(" " + mark(step.state) + " " + msg::step_name(step.name));
  }
  return block;
}

Block prompt_block(const ConsoleState& state) {
  Block block;
  if (state.prompt) {
    block.lines = {"", ">> " + state.prompt->text};
  }
  return block;
}

Block art_block(const ConsoleState& state) {
  Block block;
  block.wraps = false;
  if (!state.prompt) return block;
  for (const auto& line : state.prompt->art) block.lines.push_back("   " + line);
  return block;
}

Block live_block(const ConsoleState& state, int width) {
  Block block;
  if (!state.live) return block;
  block.lines.emplace_back("");
  for (const auto& line : state.live->lines) block.lines.push_back("   " + line);
  if (std::isfinite(state.live->progress)) {
    block.lines.push_back("   " + progress_bar(state.live->progress, std::clamp(width - 12, 10, 50)));
  }
  return block;
}

/// The review: its verdict, gates and lines, wrapped to `width`. When more rows than `rows` are
/// needed, a window of them from state.review_offset on, with a line that says where it is and
/// which keys scroll (the operator must be able to read all of what the write stores).
Block review_block(const ConsoleState& state, std::size_t width, std::size_t rows) {
  Block block;
  block.wraps = false;  // wrapped here, so that the window counts screen rows
  if (!state.review) return block;
  block.lines.emplace_back("");
  block.lines.push_back(std::string("Review: ") + (state.review->pass ? "PASS" : "FAIL"));
  std::vector<std::string> body;
  for (const auto& gate : state.review->gates)
    for (auto& piece : wrap(gate_line(gate), width)) body.push_back(std::move(piece));
  for (const auto& line : state.review->lines)
    for (auto& piece : wrap("  " + line, width)) body.push_back(std::move(piece));
  if (body.size() <= rows) {
    state.review_last_offset = 0;
    block.lines.insert(block.lines.end(), body.begin(), body.end());
    return block;
  }
  const std::size_t shown = std::max<std::size_t>(rows, 2) - 1;  // one row says where this is
  state.review_last_offset = body.size() - shown;
  const std::size_t first = std::min(state.review_offset, state.review_last_offset);
  block.lines.insert(block.lines.end(), body.begin() + static_cast<std::ptrdiff_t>(first),
                     body.begin() + static_cast<std::ptrdiff_t>(first + shown));
  block.lines.push_back("  -- review rows " + std::to_string(first + 1) + "-" +
                        std::to_string(first + shown) + " of " + std::to_string(body.size()) +
                        (first + shown < body.size() ? "; d: more" : "") + (first > 0 ? "; u: back" : "") +
                        " --");
  return block;
}

Block done_block(const ConsoleState& state) {
  Block block;
  if (!state.done) return block;
  const msg::Done& done = *state.done;
  block.lines.emplace_back("");
  block.lines.push_back("Session " + std::string(msg::outcome_name(done.outcome)) + ": " + done.text);
  if (done.stored && !done.stored->empty()) {
    block.lines.push_back("Stored on: " + *done.stored);
  }
  if (done.session_dir && !done.session_dir->empty()) {
    block.lines.push_back("Session folder: " + *done.session_dir);
  }
  for (const auto& report : done.reports) block.lines.push_back("Report: " + report);
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
/// A coverage as text rows, one mark a cell (coverage_block).
std::vector<std::string> coverage_grid(const session_msg::CameraCoverage& coverage) {
  std::vector<std::string> out;
  if (coverage.cols <= 0 || coverage.rows <= 0 ||
      coverage.cells.size() !=
          static_cast<std::size_t>(coverage.cols) * static_cast<std::size_t>(coverage.rows))
    return out;
  const std::int64_t most = *std::max_element(coverage.cells.begin(), coverage.cells.end());
  static constexpr char kMarks[] = {'.', ':', '+', '#'};
  for (int r = 0; r < coverage.rows; ++r) {
    std::string line;
    for (int c = 0; c < coverage.cols; ++c) {
      const std::int64_t n = coverage.cells[static_cast<std::size_t>(r * coverage.cols + c)];
      if (n <= 0 || most <= 0) {
        line += ' ';
        continue;
      }
      // Quarters of the most-seen cell's count: a cell seen at all shows at least '.'.
      const auto level = std::min<std::int64_t>(3, (4 * n - 1) / most);
      line += kMarks[level];
    }
    out.push_back(line);
  }
  return out;
}

/// Each camera's coverage in the motion step (the live view's, in text): a grid over its image,
/// each cell a mark from ' ' (no corner seen) through '.', ':', '+' to '#' (the most-seen cells),
/// the cameras side by side, and a line each with the spans across, down, in size and in tilt.
/// `grid`: false when the screen is short (only the spans).
Block coverage_block(const ConsoleState& state, bool grid) {
  Block block;
  block.wraps = false;  // a grid is cut, never wrapped
  std::vector<std::string>& out = block.lines;
  const auto* motion = state.live ? std::get_if<msg::MotionFigures>(&state.live->figures) : nullptr;
  if (!motion || motion->coverage.empty()) return block;
  const auto& cov = motion->coverage;
  const auto name = [&](std::size_t i) {
    const bool named =
        state.status && state.status->service && i < state.status->service->devices.cameras.size();
    return named ? state.status->service->devices.cameras[i].name : "cam" + std::to_string(i);
  };
  const auto pct = [](double v) {
    return fixed(100.0 * std::clamp(std::isfinite(v) ? v : 0.0, 0.0, 1.0), 0) + "%";
  };
  if (grid) {
    std::vector<std::vector<std::string>> grids;
    std::size_t rows = 0;
    for (const auto& c : cov) {
      grids.push_back(coverage_grid(c));
      rows = std::max(rows, grids.back().size());
    }
    std::string title = "  where the target was seen:";
    for (std::size_t i = 0; i < cov.size(); ++i) {
      const std::size_t w = grids[i].empty() ? 0 : grids[i][0].size() + 2;
      std::string n = name(i).substr(0, std::max<std::size_t>(w, 4));
      title += "  " + n + std::string(w > n.size() ? w - n.size() : 0, ' ');
    }
    out.push_back(title);
    for (std::size_t r = 0; r < rows; ++r) {
      std::string line(std::string("  where the target was seen:").size(), ' ');
      for (const auto& g : grids) {
        const std::string cells = r < g.size() ? g[r] : std::string(g.empty() ? 0 : g[0].size(), ' ');
        const std::size_t pad = std::max<std::size_t>(cells.size() + 2, 4) - (cells.size() + 2);
        line += "  |" + cells + "|" + std::string(pad, ' ');
      }
      out.push_back(line);
    }
  }
  for (std::size_t i = 0; i < cov.size(); ++i) {
    const auto& c = cov[i];
    out.push_back("  " + name(i) + ": across " + pct(c.x) + ", down " + pct(c.y) + ", size " + pct(c.size) +
                  ", tilt " + pct(c.skew) + " (" + std::to_string(c.views) + " views)");
  }
  return block;
}

std::vector<std::string> middle(const ConsoleState& state, std::size_t width, int level, std::size_t recent,
                                std::size_t review_rows = std::numeric_limits<std::size_t>::max()) {
  std::vector<std::string> out;
  put(out, steps_block(state, level >= 1), width);
  put(out, prompt_block(state), width);
  if (level < 2) put(out, art_block(state), width);
  put(out, live_block(state, static_cast<int>(width)), width);
  put(out, coverage_block(state, level < 2), width);
  put(out, review_block(state, width, review_rows), width);
  put(out, done_block(state), width);
  put(out, recent_block(state, recent), width);
  return out;
}

void update_reply(ConsoleState& state, const service::Reply& reply) {
  if (!reply.ok) {
    if (state.start_after_done && reply.cmd == service::command_name(service::Command::kAbort)) {
      state.start_after_done = false;  // nothing to abort: start at once
      state.outbox.push_back(service::to_json(service::start_request(state.restart_steps)));
    }
    state.notice = reply.cmd + " refused: " + reply.error;
  } else if (reply.cmd == service::command_name(service::Command::kKey) ||
             reply.cmd == service::command_name(service::Command::kAbort) ||
             reply.cmd == service::command_name(service::Command::kStart) ||
             reply.cmd == service::command_name(service::Command::kAccept)) {
    state.notice.clear();
  }
}

/// What the console does with each kind of session message.
struct Fold {
  ConsoleState& state;
  void operator()(const msg::Status& m) const {
    if (!state.status || m.step != state.status->step) {
      state.live.reset();  // figures of the previous step are no longer news
    }
    if (state.status && (m.step != state.status->step || m.state != state.status->state)) {
      // A question about the step that ended ("End the poses step now?") and the notice about
      // it ("Not done: ...", a refusal) no longer apply.
      state.confirm.reset();
      state.notice.clear();
    }
    if (m.state == msg::SessionState::kRunning || m.state == msg::SessionState::kIdle) {
      state.review.reset();
    }
    if (m.state == msg::SessionState::kRunning) {
      state.done.reset();
    }
    if (m.service) state.recorded_bytes = m.service->recorded_bytes;
    state.status = m;
  }
  void operator()(const msg::Prompt& m) const {
    if (!state.live || m.step != state.live->step) {
      state.live.reset();
    }
    state.prompt = m;
  }
  void operator()(const msg::Live& m) const {
    state.live = m;
    // "Not yet: the poses step ends with at least ..." no longer applies once there are enough.
    const auto* poses = std::get_if<msg::PoseFigures>(&m.figures);
    if (poses && poses->poses >= poses->poses_needed && state.notice.rfind(kNotYetPoses, 0) == 0)
      state.notice.clear();
  }
  void operator()(const msg::Message& m) const { add_recent(state, message_text(m)); }
  void operator()(const msg::Fault& m) const { add_recent(state, fault_text(m)); }
  void operator()(const msg::Review& m) const {
    state.review = m;
    state.review_offset = 0;
  }
  void operator()(const msg::Done& m) const {
    state.done = m;
    state.prompt.reset();
    state.live.reset();
    if (state.start_after_done) {
      state.start_after_done = false;  // restart: the session ended, the next one starts
      state.outbox.push_back(service::to_json(service::start_request(state.restart_steps)));
    }
  }
  template <typename Other>
  void operator()(const Other&) const {}  // the log's bookkeeping: nothing to show
};

}  // namespace

void update(ConsoleState& state, const json& message) {
  if (const auto reply = service::parse_reply(message)) {
    update_reply(state, *reply);
    return;
  }
  const auto decoded = msg::decode(message);
  if (!decoded.ok()) return;
  const bool is_status = std::holds_alternative<msg::Status>(*decoded);
  if (const auto t = msg::time_of(*decoded); t && std::isfinite(*t)) {
    if (is_status || state.status_clock_s < 0.0) state.status_clock_s = *t;
    state.clock_s = *t;
  } else if (is_status) {
    state.status_clock_s = -1.0;  // a status without the clock (a snapshot): the next message's
  }
  std::visit(Fold{state}, *decoded);
}

void service_lost(ConsoleState& state, const std::string& why) {
  state.lost = why.empty() ? "the connection ended" : why;
  state.confirm.reset();
  state.start_after_done = false;
  state.outbox.clear();
  const bool running = state.status && is_running(*state.status) && !state.done;
  state.notice = state.lost + ": imucald stopped or restarted" +
                 (running ? ", and the session it was running ended with it (what it recorded stays in "
                            "its session folder; the stored calibration is unchanged)"
                          : "") +
                 ". See why with `systemctl status imucald` and `journalctl -u imucald`, then run "
                 "imucalctl again.";
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
    if (mid.size() > room && state.review) {
      // The review in a window of the rows left (d and u scroll it), rather than cut at the end.
      // Everything but the window: middle() with a window of one row and its marker, less those.
      const std::size_t others = middle(state, width, level, recent, 0).size() - 2;
      const std::size_t rows = room > others ? room - others : 0;
      mid = middle(state, width, level, recent, std::max<std::size_t>(rows, 3));
    }
    if (mid.size() > room) {
      mid.resize(room);
      if (room > 0) mid.back() = "  ... (more than fits: a larger terminal shows it all)";
    }
  }
  // The service's text (prompts, messages, a controller's name in a refusal) reaches the terminal
  // only with its control characters replaced: no escape sequence of a client's gets through.
  // Lines are separated, not ended, by '\n': a newline after the last row of a full terminal
  // would scroll the screen by one and push the header out.
  std::string screen;
  for (const auto* part : {&top, &mid, &bottom}) {
    for (const auto& line : *part) {
      if (!screen.empty()) screen += '\n';
      screen += printable_text(line.size() > width ? line.substr(0, width) : line);
    }
  }
  return screen;
}

namespace {

/// One line per kind of session message; none for the log's bookkeeping.
struct PlainLine {
  std::optional<std::string> operator()(const msg::Status& m) const {
    std::string line = "status: " + std::string(msg::session_state_name(m.state));
    if (const auto position = step_position(m); !position.empty()) {
      line += ", " + position;
    }
    return line;
  }
  std::optional<std::string> operator()(const msg::Prompt& m) const {
    return "prompt [" + step_text(m.step) + "]: " + m.text;
  }
  std::optional<std::string> operator()(const msg::Live& m) const {
    std::string line = "live [" + step_text(m.step) + "]:";
    for (const auto& text : m.lines) line += " " + text + ";";
    if (std::isfinite(m.progress)) {
      line += " " + fixed(100.0 * std::clamp(m.progress, 0.0, 1.0), 0) + "%";
    }
    return line;
  }
  std::optional<std::string> operator()(const msg::Message& m) const { return message_text(m); }
  std::optional<std::string> operator()(const msg::Fault& m) const { return fault_text(m); }
  std::optional<std::string> operator()(const msg::Review& m) const {
    std::string line = std::string("review: ") + (m.pass ? "pass" : "fail");
    for (const auto& gate : m.gates) line += ";" + gate_line(gate).substr(1);
    return line;
  }
  std::optional<std::string> operator()(const msg::Done& m) const {
    const std::string stored = m.stored.value_or(""), dir = m.session_dir.value_or("");
    std::string reports;
    for (const auto& report : m.reports) reports += (reports.empty() ? " (report " : ", ") + report;
    return "done: " + std::string(msg::outcome_name(m.outcome)) + ": " + m.text +
           (stored.empty() ? std::string() : " (stored on " + stored + ")") +
           (dir.empty() ? std::string() : " (session folder " + dir + ")") +
           (reports.empty() ? "" : reports + ")");
  }
  template <typename Other>
  std::optional<std::string> operator()(const Other&) const {
    return std::nullopt;
  }
};

std::optional<std::string> plain_line_of(const json& message) {
  if (const auto reply = service::parse_reply(message)) {
    if (reply->ok) return std::nullopt;
    return "error: " + reply->cmd + " refused: " + reply->error;
  }
  const auto decoded = msg::decode(message);
  if (!decoded.ok()) return std::nullopt;
  return std::visit(PlainLine{}, *decoded);
}

}  // namespace

std::optional<std::string> plain_line(const json& message) {
  auto line = plain_line_of(message);
  if (line) *line = printable_text(*line);
  return line;
}

std::string status_text(const json& status) {
  const auto decoded = msg::decode(status);
  if (!decoded.ok() || !std::holds_alternative<msg::Status>(*decoded)) {
    return printable_text("the service's status cannot be read (" +
                              (decoded.ok() ? std::string("not a status") : decoded.error().message) + ")\n",
                          true);
  }
  return status_text(std::get<msg::Status>(*decoded));
}

std::string status_text(const msg::Status& status) {
  std::ostringstream out;
  out << "state:   " << msg::session_state_name(status.state) << '\n';
  out << "rig:     " << status.rig << '\n';
  if (const auto position = step_position(status); !position.empty()) {
    out << "step:    " << position << '\n';
  }
  if (!status.steps.empty()) {
    out << "steps:  ";
    for (const auto& step : status.steps) {
      out << ' ' << mark(step.state) << ' ' << msg::step_name(step.name);
    }
    out << '\n';
  }
  if (std::isfinite(status.elapsed_s)) {
    out << "elapsed: " << fixed(status.elapsed_s, 1) << " s\n";
  }
  if (status.service) {
    // The devices, one line each, in words (`status --json` has the fields).
    const msg::ServiceDevices& d = status.service->devices;
    out << "imu:     " << (d.imu.sim ? "virtual rig, " : "") << msg::device_state_name(d.imu.state);
    if (d.imu.rate_hz > 0.0) out << ", " << fixed(d.imu.rate_hz, 0) << " Hz";
    out << ", " << d.imu.samples << " samples, " << d.imu.faults
        << (d.imu.faults == 1 ? " fault" : " faults");
    if (!d.imu.gyro_offsets.empty()) out << ", gyro offset registers " << d.imu.gyro_offsets;
    if (!d.imu.error.empty()) out << "; error: " << d.imu.error;
    out << '\n';
    for (const auto& c : d.cameras) {
      out << "camera:  " << c.name << " " << msg::device_state_name(c.state) << ", " << c.frames
          << " frames, " << c.faults << (c.faults == 1 ? " fault" : " faults");
      if (!c.error.empty()) out << "; error: " << c.error;
      out << '\n';
    }
    if (!d.storage.empty()) out << "storage: " << d.storage << '\n';
    if (!status.service->session_dir.empty()) {
      out << "session: " << status.service->session_dir;
      if (status.service->recorded_bytes > 0)
        out << " (" << recorded_text(status.service->recorded_bytes) << " recorded)";
      out << '\n';
    }
    if (!status.service->version.empty()) out << "service: imucald " << status.service->version << '\n';
    if (status.service->live_view)
      out << "live view: " << status.service->live_view->url << " (its keys need the token in "
          << status.service->live_view->token_file << ")\n";
  }
  return printable_text(out.str(), true);
}

bool session_running(const ConsoleState& state) { return state.status && is_running(*state.status); }

KeyAction on_key(ConsoleState& state, char key) {
  if (key == kQuitKey || key == kCtrlC || key == kCtrlD) {
    return {std::nullopt, true};
  }
  if (state.confirm) {
    // The answer is one key: y or n (or Esc). Another key also declines, and then does what it
    // does without a question pending (`a` asks to abort), rather than being swallowed.
    Confirm confirm = std::move(*state.confirm);
    state.confirm.reset();
    if (key == kYesKey) {
      state.start_after_done = confirm.then_start;
      if (confirm.then_start) {
        // R restarts the session it ends: the same steps, not the configured ones.
        state.restart_steps.clear();
        if (state.status)
          for (const auto& s : state.status->steps) state.restart_steps.push_back(msg::step_name(s.name));
      }
      return {confirm.request, false};
    }
    state.notice = "Not done: " + confirm.question;
    if (key == kNoKey || key == kEscapeKey) return {};
  }
  if (state.review && (key == kScrollDownKey || key == kScrollUpKey)) {
    // Scrolling the review is the console's own: an observer may do it too.
    const std::size_t at = std::min(state.review_offset, state.review_last_offset);
    state.review_offset = key == kScrollDownKey ? std::min(at + kReviewScrollRows, state.review_last_offset)
                                                : at - std::min(at, kReviewScrollRows);
    return {};
  }
  if (state.observe) {
    return {};
  }
  auto key_request = [](msg::OperatorKey key) { return service::to_json(service::key_request(key)); };
  auto ask = [&state](std::string question, json request, bool then_start = false) {
    state.confirm = Confirm{std::move(question), std::move(request), then_start};
    return KeyAction{};
  };
  // Space and Enter are c's; R (restart) is the console's own.
  const bool go_on = key == ' ' || key == '\r' || key == '\n';
  const std::optional<msg::OperatorKey> op = go_on ? msg::OperatorKey::kContinue : msg::key_of_letter(key);
  if (state.status && !is_running(*state.status)) {
    if (op == msg::OperatorKey::kContinue || key == kRestartKey) {
      state.notice.clear();
      return {service::to_json(service::plain_request(service::Command::kStart)), false};
    }
    state.notice = "No session is running: press " + letter(msg::key_letter(msg::OperatorKey::kContinue)) +
                   " to start one";
    return {};
  }
  if (key == kRestartKey) {
    return ask("Restart: abort this session and start a new one?",
               service::to_json(service::plain_request(service::Command::kAbort)), true);
  }
  if (!op) return {};
  const std::string step = state.status && state.status->step ? step_text(state.status->step)
                           : state.prompt                     ? step_text(state.prompt->step)
                                                              : std::string();
  std::optional<double> progress;
  if (state.live && step_text(state.live->step) == step && std::isfinite(state.live->progress))
    progress = state.live->progress;
  switch (*op) {
    case msg::OperatorKey::kContinue:
      // The service ends the poses step only with its fewest poses: do not offer what it refuses.
      if (const auto* poses = state.live && step_text(state.live->step) == step
                                  ? std::get_if<msg::PoseFigures>(&state.live->figures)
                                  : nullptr;
          poses && poses->poses < poses->poses_needed) {
        state.notice = kNotYetPoses + std::to_string(poses->poses_needed) + " poses (" +
                       std::to_string(poses->poses) +
                       " so far); turn the rig to a new orientation and hold it still";
        return {};
      }
      // Going on before the step's own end throws its remaining time away: ask.
      if (progress && *progress < 0.999 && step != "preflight") {
        return ask(
            "End the " + step + " step now, at " + fixed(100.0 * std::clamp(*progress, 0.0, 1.0), 0) + " %?",
            key_request(msg::OperatorKey::kContinue));
      }
      return {key_request(msg::OperatorKey::kContinue), false};
    case msg::OperatorKey::kRedo:
      return {key_request(msg::OperatorKey::kRedo), false};
    case msg::OperatorKey::kAbort:
      return ask("Abort the session? What was recorded is kept, nothing is written.",
                 service::to_json(service::plain_request(service::Command::kAbort)));
    case msg::OperatorKey::kAccept:
      return {key_request(msg::OperatorKey::kAccept), false};
    case msg::OperatorKey::kReject:
      return ask("Reject this calibration? Nothing is written; the results stay in the session folder.",
                 key_request(msg::OperatorKey::kReject));
    case msg::OperatorKey::kSkip:
      return ask("Skip the " + (step.empty() ? std::string("current") : step) +
                     " step? What it recorded is not used.",
                 key_request(msg::OperatorKey::kSkip));
  }
  return {};
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
