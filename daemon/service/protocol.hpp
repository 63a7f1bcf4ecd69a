// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The control protocol's requests: one JSON object per line from a client (docs/service.md).
// parse_request is a pure function over untrusted bytes (fuzzed by fuzz_control_request).

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.hpp"
#include "core/session_messages.hpp"

namespace imucal::service {

enum class Command { kHello, kStatus, kSubscribe, kStart, kKey, kAbort, kAccept };
enum class Role { kObserver, kController };

struct Request {
  Command command = Command::kStatus;
  std::string client;              // hello: the client's name (printable, 64 bytes at most)
  Role role = Role::kObserver;     // hello
  std::vector<std::string> steps;  // start: empty = the configured steps
  // key (abort and accept set it too)
  session_msg::OperatorKey key = session_msg::OperatorKey::kContinue;
};

const char* command_name(Command command);
bool is_control(Command command);  // start, key, abort, accept: controller only

/// One request line (without its newline). Extra fields are ignored, so newer clients can add
/// some; a missing or mistyped required field is an error that names it.
Result<Request> parse_request(std::string_view line);

/// The request as its line's JSON object (parse_request's inverse): clients build their
/// requests here, so both ends share the protocol's words.
nlohmann::json to_json(const Request& request);

/// Requests as a client sends them: hello with its name and role, start with its steps (empty:
/// the configured ones), key with an operator key, and the commands without fields.
Request hello_request(std::string client, Role role);
Request start_request(std::vector<std::string> steps);
Request key_request(session_msg::OperatorKey key);
Request plain_request(Command command);

/// The "cmd" of a line that may not parse as a request, for its error reply ("" when none).
std::string command_of(std::string_view line);

/// {"type":"reply","cmd":cmd,"ok":true} or with ok:false and "error".
nlohmann::json make_reply(std::string_view cmd, const Status& status);

/// A reply as a client reads it (make_reply's inverse).
struct Reply {
  std::string cmd;
  bool ok = true;
  std::string error;  // when not ok
};
/// The reply a line holds; none when it is not a reply (a session message). A field of the wrong
/// kind reads as absent.
std::optional<Reply> parse_reply(const nlohmann::json& message);

/// One JSON line, newline included; invalid UTF-8 is replaced rather than thrown on.
std::string to_line(const nlohmann::json& message);

}  // namespace imucal::service
