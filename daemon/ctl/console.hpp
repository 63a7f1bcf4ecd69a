#pragma once
// The operator console's model and renderer, free of terminals and sockets so tests check them
// as text: update() folds a service message into the state, render() draws the screen,
// on_key() turns a key press into a request. imucalctl attach drives them (attach.hpp).

#include <deque>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

namespace imucal::ctl {

struct ConsoleState {
  nlohmann::json status;           // the last {"type":"status"} (null until one arrives)
  nlohmann::json prompt;           // the prompt in force (null when none)
  nlohmann::json live;             // the last live figures of the current step
  nlohmann::json review;           // the review in force
  nlohmann::json done;             // the session's outcome
  std::deque<std::string> recent;  // the last messages and faults, oldest first
  std::string notice;              // the last refusal from the service or local hint
  bool observe = false;            // observer: keys other than q are not sent
  bool confirm_abort = false;      // 'a' was pressed; waiting for y/n
  std::size_t max_recent = 5;
};

/// Folds one service message into the state; unknown types and malformed fields are ignored.
void update(ConsoleState& state, const nlohmann::json& message);

struct RenderOptions {
  int width = 80;  // terminal columns; lines are cut to fit
};

/// The whole screen as text (lines separated by '\n', no terminal control codes).
std::string render(const ConsoleState& state, const RenderOptions& options = {});

/// One line for a message when stdout is not a terminal; nothing for messages without news
/// (successful replies, unknown types).
std::optional<std::string> plain_line(const nlohmann::json& message);

/// A status message as a short multi-line text (imucalctl status).
std::string status_text(const nlohmann::json& status);

struct KeyAction {
  std::optional<nlohmann::json> request;  // to send to the service
  bool detach = false;
};

/// c, space, enter: continue; r: redo; a: abort (asks y/n first); y: accept; n: reject;
/// s: skip; q, Ctrl-C, Ctrl-D: detach.
KeyAction on_key(ConsoleState& state, char key);

/// A bar of `width` cells for progress in [0, 1], e.g. "[######----]  60%".
std::string progress_bar(double progress, int width);

}  // namespace imucal::ctl
