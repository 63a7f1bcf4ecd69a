// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/service/protocol.hpp"

#include <algorithm>
#include <array>

#include "core/printable_text.hpp"

namespace imucal::service {
namespace {

/// The longest client name a hello may give, bytes: it is shown on terminals and in the log.
constexpr std::size_t kMaxClientNameBytes = 64;

using nlohmann::json;

struct CommandInfo {
  std::string_view name;
  Command command;
};

constexpr std::array<CommandInfo, 7> kCommands{{
    {"hello", Command::kHello},
    {"status", Command::kStatus},
    {"subscribe", Command::kSubscribe},
    {"start", Command::kStart},
    {"key", Command::kKey},
    {"abort", Command::kAbort},
    {"accept", Command::kAccept},
}};

Error invalid(std::string message) { return make_error(Errc::kInvalidArgument, std::move(message)); }

std::string known_commands() {
  std::string names;
  for (const auto& info : kCommands) {
    names += names.empty() ? "" : ", ";
    names += info.name;
  }
  return names;
}

Status parse_hello(const json& object, Request& request) {
  if (const auto it = object.find("client"); it != object.end()) {
    if (!it->is_string()) {
      return invalid("hello: \"client\" must be a string (the client's name)");
    }
    // The name reaches other clients' terminals ("another controller is attached (NAME)") and
    // the service's log: printable and bounded, or refused.
    const auto& name = it->get_ref<const std::string&>();
    if (name.size() > kMaxClientNameBytes || !is_printable_text(name)) {
      return invalid("hello: \"client\" must be printable text (no control characters) of at most " +
                     std::to_string(kMaxClientNameBytes) + " bytes");
    }
    request.client = name;
  }
  if (const auto it = object.find("role"); it != object.end()) {
    if (!it->is_string() || (*it != "observer" && *it != "controller")) {
      return invalid("hello: \"role\" must be \"observer\" or \"controller\"");
    }
    request.role = *it == "controller" ? Role::kController : Role::kObserver;
  }
  return {};
}

Status parse_start(const json& object, Request& request) {
  const auto it = object.find("steps");
  if (it == object.end() || it->is_null()) {
    return {};
  }
  if (!it->is_array()) {
    return invalid("start: \"steps\" must be an array of step names, e.g. [\"poses\",\"solve\"]");
  }
  for (const auto& step : *it) {
    if (!step.is_string() || step.get_ref<const std::string&>().empty()) {
      return invalid("start: every entry of \"steps\" must be a non-empty string");
    }
    request.steps.push_back(step.get<std::string>());
  }
  return {};
}

Status parse_key(const json& object, Request& request) {
  const auto it = object.find("key");
  if (it == object.end() || !it->is_string()) {
    return invalid("key: \"key\" must be a string, one of " + session_msg::key_list());
  }
  const auto key = session_msg::parse_key(it->get_ref<const std::string&>());
  if (!key.ok()) {
    return invalid("key: unknown key \"" + it->get<std::string>() + "\"; use one of " +
                   session_msg::key_list());
  }
  request.key = *key;
  return {};
}

}  // namespace

const char* command_name(Command command) {
  for (const auto& info : kCommands) {
    if (info.command == command) {
      return info.name.data();
    }
  }
  return "";
}

bool is_control(Command command) {
  return command == Command::kStart || command == Command::kKey || command == Command::kAbort ||
         command == Command::kAccept;
}

Result<Request> parse_request(std::string_view line) {
  const json object = json::parse(line.begin(), line.end(), nullptr, /*allow_exceptions=*/false);
  if (object.is_discarded()) {
    return invalid("the request is not valid JSON; send one JSON object per line, e.g. {\"cmd\":\"status\"}");
  }
  if (!object.is_object()) {
    return invalid("the request must be a JSON object with a \"cmd\" field, e.g. {\"cmd\":\"status\"}");
  }
  const auto cmd = object.find("cmd");
  if (cmd == object.end() || !cmd->is_string()) {
    return invalid("the request has no \"cmd\" string; known commands: " + known_commands());
  }
  const auto& name = cmd->get_ref<const std::string&>();
  const auto info =
      std::find_if(kCommands.begin(), kCommands.end(), [&](const auto& i) { return i.name == name; });
  if (info == kCommands.end()) {
    return invalid("unknown command \"" + name + "\"; known commands: " + known_commands());
  }
  Request request;
  request.command = info->command;
  switch (request.command) {
    case Command::kHello:
      IMUCAL_TRY(parse_hello(object, request));
      break;
    case Command::kStart:
      IMUCAL_TRY(parse_start(object, request));
      break;
    case Command::kKey:
      IMUCAL_TRY(parse_key(object, request));
      break;
    case Command::kAbort:
      request.key = session_msg::OperatorKey::kAbort;
      break;
    case Command::kAccept:
      request.key = session_msg::OperatorKey::kAccept;
      break;
    case Command::kStatus:
    case Command::kSubscribe:
      break;
  }
  return request;
}

json to_json(const Request& request) {
  json object{{"cmd", command_name(request.command)}};
  switch (request.command) {
    case Command::kHello:
      if (!request.client.empty()) object["client"] = request.client;
      object["role"] = request.role == Role::kController ? "controller" : "observer";
      break;
    case Command::kStart:
      if (!request.steps.empty()) object["steps"] = request.steps;
      break;
    case Command::kKey:
      object["key"] = session_msg::key_name(request.key);
      break;
    case Command::kStatus:
    case Command::kSubscribe:
    case Command::kAbort:
    case Command::kAccept:
      break;
  }
  return object;
}

Request hello_request(std::string client, Role role) {
  Request r;
  r.command = Command::kHello;
  r.client = std::move(client);
  r.role = role;
  return r;
}

Request start_request(std::vector<std::string> steps) {
  Request r;
  r.command = Command::kStart;
  r.steps = std::move(steps);
  return r;
}

Request key_request(session_msg::OperatorKey key) {
  Request r;
  r.command = Command::kKey;
  r.key = key;
  return r;
}

Request plain_request(Command command) {
  Request r;
  r.command = command;
  if (command == Command::kAbort) r.key = session_msg::OperatorKey::kAbort;
  if (command == Command::kAccept) r.key = session_msg::OperatorKey::kAccept;
  return r;
}

std::string command_of(std::string_view line) {
  const json object = json::parse(line.begin(), line.end(), nullptr, /*allow_exceptions=*/false);
  if (object.is_object()) {
    const auto cmd = object.find("cmd");
    if (cmd != object.end() && cmd->is_string()) {
      return cmd->get<std::string>();
    }
  }
  return {};
}

json make_reply(std::string_view cmd, const Status& status) {
  json reply{{"type", "reply"}, {"cmd", std::string(cmd)}, {"ok", status.ok()}};
  if (!status.ok()) {
    reply["error"] = status.error().message;
  }
  return reply;
}

std::optional<Reply> parse_reply(const json& message) {
  if (!message.is_object()) return std::nullopt;
  const auto text = [&](const char* key) {
    const auto it = message.find(key);
    return it != message.end() && it->is_string() ? it->get<std::string>() : std::string();
  };
  if (text("type") != "reply") return std::nullopt;
  Reply reply;
  reply.cmd = text("cmd");
  const auto ok = message.find("ok");
  reply.ok = ok == message.end() || !ok->is_boolean() || ok->get<bool>();
  reply.error = text("error");
  return reply;
}

std::string to_line(const json& message) {
  // Replace, not throw: a host's text may carry bytes from a device name or a file.
  std::string line = message.dump(-1, ' ', false, json::error_handler_t::replace);
  line += '\n';
  return line;
}

}  // namespace imucal::service
