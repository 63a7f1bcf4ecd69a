// SPDX-License-Identifier: BSD-3-Clause
// imucalctl: talks to the imucald service over its control socket (docs/service.md).
//
//   imucalctl [--socket PATH] status [--json] | start [--steps a,b,c] | abort | accept |
//             attach [--observe]
//
// Exit codes: 0 done; 1 the service refused the request or went away; 2 bad command line;
// 3 the service is not running (no socket, nobody listening); 4 permission denied on the socket.
#include <sys/un.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/closest_word.hpp"
#include "core/printable_text.hpp"
#include "core/version.hpp"
#include "daemon/ctl/attach.hpp"
#include "daemon/ctl/client.hpp"
#include "daemon/ctl/console.hpp"
#include "daemon/service/protocol.hpp"

namespace {

using imucal::ctl::ConnectFailure;
using imucal::ctl::Connection;
using nlohmann::json;
namespace service = imucal::service;

constexpr int kRefused = 1;  // also: the service went away
constexpr int kNoService = 3;
constexpr int kPermission = 4;

/// Why `path` cannot name a Unix socket (empty, or longer than sockaddr_un holds), or empty.
std::string socket_path_problem(const std::string& path) {
  constexpr std::size_t kMax = sizeof(sockaddr_un::sun_path) - 1;
  if (path.empty()) return "the socket path is empty";
  if (path.size() > kMax) {
    return "the socket path is " + std::to_string(path.size()) + " bytes; a Unix socket takes at most " +
           std::to_string(kMax);
  }
  return {};
}

std::string default_socket() {
  const char* env = std::getenv("IMUCAL_SOCKET");
  return env != nullptr && *env != '\0' ? env : "/run/imucal/imucald.sock";
}

int fail(const std::string& message, int code) {
  std::fprintf(stderr, "imucalctl: %s\n", imucal::printable_text(message).c_str());  // the service's words
  return code;
}

// Connects or says why not; the exit code tells scripts which of the two common causes it was.
int connect(const std::string& path, std::optional<Connection>& connection) {
  ConnectFailure failure = ConnectFailure::kNone;
  auto opened = Connection::open(path, &failure);
  if (!opened) {
    const int code = failure == ConnectFailure::kNoService    ? kNoService
                     : failure == ConnectFailure::kPermission ? kPermission
                                                              : kRefused;
    return fail(opened.error().message, code);
  }
  connection.emplace(std::move(*opened));
  return 0;
}

int run_status(Connection& connection, bool as_json) {
  std::vector<json> messages;
  if (auto reply =
          connection.request(service::to_json(service::plain_request(service::Command::kStatus)), &messages);
      !reply) {
    return fail(reply.error().message, kRefused);
  }
  // The status message follows its reply.
  auto status = connection.receive(std::chrono::seconds(10));
  if (!status) {
    return fail(status.error().message, kRefused);
  }
  if (as_json) {
    std::printf("%s\n", status->dump(2, ' ', false, json::error_handler_t::replace).c_str());
  } else {
    std::fputs(imucal::ctl::status_text(*status).c_str(), stdout);
  }
  return 0;
}

// A control request: claims the controller role for this connection, then sends it; `done` is
// printed once the service accepted it.
int run_control(Connection& connection, const json& request, const char* done) {
  const service::Request hello = service::hello_request("imucalctl", service::Role::kController);
  if (auto reply = connection.request(service::to_json(hello)); !reply) {
    return fail(reply.error().message, kRefused);
  }
  if (auto reply = connection.request(request); !reply) {
    return fail(reply.error().message, kRefused);
  }
  std::printf("%s\n", done);
  return 0;
}

/// The first word of the command line that is not an option (nor --socket's value) when it names
/// no subcommand: "unknown command 'stauts'; did you mean 'status'?" and the commands (worded by
/// core/closest_word.hpp). Empty when there is no such word. This is the walk of
/// daemon/common/unknown_command.hpp for one level and this program's one option with a value:
/// daemon/ctl may not use daemon/common (tests/check_layering.sh).
std::string unknown_command_message(const CLI::App& app, int argc, char** argv) {
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
    names.push_back(sub->get_name());
  for (int i = 1; i < argc; ++i) {
    const std::string word = argv[i];
    if (word == "--socket") {
      ++i;  // its value
      continue;
    }
    if (word.empty() || word[0] == '-') continue;
    if (std::find(names.begin(), names.end(), word) != names.end()) return {};
    return imucal::unknown_command_text(word, names, "imucalctl");
  }
  return {};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"imucalctl: control and watch the imucald calibration service"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("imucalctl ") + imucal::kVersion);
  app.footer(
      "Examples:\n"
      "  imucalctl attach              the operator console (c starts a session, q detaches)\n"
      "  imucalctl status              the session's state and the rig's devices\n"
      "  imucalctl start --steps preflight,poses,solve\n"
      "  IMUCAL_SOCKET=/tmp/s.sock imucalctl status --json");
  std::string socket_path = default_socket();
  app.add_option("--socket", socket_path, "the service's control socket (env IMUCAL_SOCKET)")
      ->capture_default_str()
      ->check(socket_path_problem);

  bool as_json = false;
  auto* status = app.add_subcommand("status", "print the session's state");
  status->add_flag("--json", as_json, "print the status message as JSON");
  status->footer("Example:\n  imucalctl status --json | jq .state");

  std::vector<std::string> steps;
  auto* start = app.add_subcommand("start", "start a calibration session");
  start->add_option("--steps", steps, "the steps to run, comma separated (default: the configured ones)")
      ->delimiter(',');
  start->footer(
      "Examples:\n  imucalctl start\n  imucalctl start --steps preflight,warmup,poses,solve,review,write");

  auto* abort = app.add_subcommand("abort", "abort the running session");
  abort->footer("Example:\n  imucalctl abort    (what was recorded is kept, nothing is written)");
  auto* accept = app.add_subcommand("accept", "accept the result under review (it is written to the rig)");
  accept->footer("Example:\n  imucalctl status && imucalctl accept");

  bool observe = false;
  auto* attach = app.add_subcommand("attach", "the operator console: prompts, live figures, keys");
  attach->add_flag("--observe", observe, "watch only; another console may control");
  attach->footer(
      "Examples:\n  imucalctl attach\n  imucalctl attach --observe    (watch a session another console "
      "controls)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are parse "errors" with code 0; everything else is a bad command line.
    // A mistyped command would otherwise be "A subcommand is required": name the nearest one.
    if (e.get_exit_code() != 0) {
      if (const std::string unknown = unknown_command_message(app, argc, argv); !unknown.empty()) {
        std::fprintf(stderr, "imucalctl: %s\n", imucal::printable_text(unknown).c_str());
        return 2;
      }
    }
    return app.exit(e) == 0 ? 0 : 2;
  }

  // The path from IMUCAL_SOCKET is checked as the option is: either way a command-line matter.
  if (const std::string problem = socket_path_problem(socket_path); !problem.empty()) {
    std::fprintf(stderr, "imucalctl: %s (IMUCAL_SOCKET)\n", problem.c_str());
    return 2;
  }
  std::optional<Connection> connection;
  if (const int code = connect(socket_path, connection); code != 0) {
    return code;
  }
  if (status->parsed()) {
    return run_status(*connection, as_json);
  }
  if (start->parsed()) {
    return run_control(*connection, service::to_json(service::start_request(steps)),
                       "session started: 'imucalctl attach' follows it, 'imucalctl status' shows its state");
  }
  if (abort->parsed()) {
    return run_control(*connection, service::to_json(service::plain_request(service::Command::kAbort)),
                       "session aborted: what was recorded is kept, nothing is written");
  }
  if (accept->parsed()) {
    return run_control(
        *connection, service::to_json(service::plain_request(service::Command::kAccept)),
        "result accepted: the service writes it to the rig ('imucalctl status' shows the outcome)");
  }
  return imucal::ctl::attach(*connection, {observe});
}
