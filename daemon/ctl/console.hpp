// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The operator console's model and renderer, free of terminals and sockets so tests check them
// as text: update() folds a service message into the state, render() draws the screen,
// on_key() turns a key press into a request. imucalctl attach drives them (attach.hpp).

#include <deque>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/session_messages.hpp"

namespace imucal::ctl {

/// A key that throws work away (abort, reject, skip, ending a step early, restart) asks first.
struct Confirm {
  std::string question;     // "End the motion step now, at 30 % of its time?"
  nlohmann::json request;   // sent on 'y'
  bool then_start = false;  // restart: start a new session once this one has ended
};

struct ConsoleState {
  std::optional<session_msg::Status> status;  // the last status (none until one arrives)
  std::optional<session_msg::Prompt> prompt;  // the prompt in force
  std::optional<session_msg::Live> live;      // the last live figures of the current step
  std::optional<session_msg::Review> review;  // the review in force
  std::size_t review_offset = 0;              // its first row shown when it does not fit (d, u)
  /// The largest first row the last render could show (render sets it), so that d stops at the
  /// review's end and u goes back at once.
  mutable std::size_t review_last_offset = 0;
  std::optional<session_msg::Done> done;  // the session's outcome
  std::deque<std::string> recent;         // the last messages and faults, oldest first
  std::string notice;                     // the last refusal from the service or local hint
  std::string lost;                       // why the connection to imucald ended (empty while connected)
  bool observe = false;                   // observer: keys other than q are not sent
  std::optional<Confirm> confirm;  // a destructive key was pressed; waiting for y (or anything else: no)
  bool start_after_done = false;   // restart: the abort is sent, the start follows the end
  std::vector<std::string> restart_steps;  // restart: the steps of the session restarted
  std::deque<nlohmann::json> outbox;       // requests update() made (a restart's start); attach sends them
  // The session clock (seconds, the messages' "t"): the latest seen, and the status's. The
  // header's elapsed time runs on between status messages from these.
  double clock_s = -1.0;
  double status_clock_s = -1.0;
  /// What the session has recorded (bytes; the service's status carries it every few seconds
  /// while a session runs, the engine's own status at step changes does not); -1: not yet said.
  std::int64_t recorded_bytes = -1;
  std::size_t max_recent = 5;
};

/// Folds one line from the service into the state: a reply to a request, or a session message
/// (decoded by core/session_messages.hpp). A message that does not decode (an unknown type, a
/// malformed field) is ignored.
void update(ConsoleState& state, const nlohmann::json& message);

struct RenderOptions {
  int width = 80;       // terminal columns; long lines wrap
  int height = 0;       // terminal rows; 0: no limit. The header and the keys always show; the
                        // step list folds to one line, the drawing and older messages go first.
  double idle_s = 0.0;  // wall time since the last message, added to a running session's elapsed
};

/// The whole screen as text: lines separated by '\n', with none after the last (a full terminal
/// would scroll), no terminal control codes.
std::string render(const ConsoleState& state, const RenderOptions& options = {});

/// The connection to imucald ended (`why`: the client's error): the screen keeps the last state
/// the service sent, under a header and a notice that say it is gone and what to do; no question
/// stays open and no key is offered.
void service_lost(ConsoleState& state, const std::string& why);

/// One line for a message when stdout is not a terminal; nothing for messages without news
/// (successful replies, unknown types).
std::optional<std::string> plain_line(const nlohmann::json& message);

/// A status message as a short multi-line text (imucalctl status); a line that is not a status
/// says so.
std::string status_text(const nlohmann::json& status);
std::string status_text(const session_msg::Status& status);

struct KeyAction {
  std::optional<nlohmann::json> request;  // to send to the service
  bool detach = false;
};

/// While a session runs: c, space, enter: continue (asks first when it ends a step before its
/// time); r: redo; y: accept; n: reject, s: skip, a: abort, R: restart (these ask y/n first).
/// With no session running: c, space, enter or R start one. q, Ctrl-C, Ctrl-D: detach. A pending
/// question takes one key: y sends its request, n or Esc declines; another key declines and then
/// acts as above.
KeyAction on_key(ConsoleState& state, char key);

/// True while a session runs (state running or review).
bool session_running(const ConsoleState& state);

/// A bar of `width` cells for progress in [0, 1], e.g. "[######----]  60%".
std::string progress_bar(double progress, int width);

}  // namespace imucal::ctl
