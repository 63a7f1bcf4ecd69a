// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The service's control socket: JSON lines over a Unix stream socket, on the service's one
// Boost.Asio event loop (docs/service.md). Any number of observers; at most one controller.
// Nothing a client does can block the loop: reads and writes are asynchronous, a line longer
// than max_line_bytes closes its connection, a client whose unsent output passes
// max_queued_bytes is dropped.

#include <boost/asio/io_context.hpp>
#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "core/result.hpp"
#include "daemon/service/session_host.hpp"

namespace imucal::service {

struct ControlServerOptions {
  std::string path;      // e.g. /run/imucal/imucald.sock; a stale socket file is replaced, a live one refused
  unsigned mode = 0660;  // chmod after bind
  std::string group;     // optional chown group
  std::size_t max_line_bytes = 64 * 1024;  // a longer request line closes the connection
  std::size_t max_queued_bytes = 4 << 20;  // per client; a peer that never reads is dropped
  // A connection being closed (after an error or the end of its input) may take this long to
  // read its last lines: a peer that never reads must not hold its descriptor forever.
  std::chrono::milliseconds close_timeout{5000};
  // More connections get an error reply and are closed. One place beyond it is kept for the
  // operator's console: a connection there may control, or ask for the status once (it is then
  // closed), but neither observe nor subscribe.
  std::size_t max_clients = 32;
  // A connection that sends nothing this long after connecting is closed with a reply saying
  // so: idle connections must not take the places the operator needs.
  std::chrono::milliseconds silent_timeout{10000};
  // When every place is taken (the reserved one included), a new connection is not refused while
  // another connection, not the controller, has sent nothing for this long: the longest silent
  // one (subscribers first) is closed with a reply saying why, and the new one takes its place.
  // So connections that asked once and stay open cannot lock the operator out.
  std::chrono::milliseconds evict_idle_after{30000};
  // A controller that has sent nothing for this long gives the role to another client that asks
  // for it (hello as controller, or a control command); it stays connected, as an observer, and
  // is told. imucalctl attach says hello again every minute, so a console in use never idles.
  std::chrono::milliseconds controller_idle_after{600000};
  std::function<void(const std::string&)> log;  // optional: why a connection was dropped

  Status validate() const;
};

class ControlServer {
 public:
  /// Binds and listens on options.path and starts accepting on `io`. Fails when another
  /// process listens there, the path is not a socket, or it cannot be bound, chmod-ed or
  /// chown-ed. The server and the host must outlive nothing but themselves: pending handlers
  /// find the server gone and do nothing.
  [[nodiscard]] static Result<std::unique_ptr<ControlServer>> create(boost::asio::io_context& io,
                                                                     const ControlServerOptions& options,
                                                                     SessionHost& host);
  ~ControlServer();
  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;

  /// Sends the session's `message` to every subscribed client, as its JSON line. Call on the io
  /// thread.
  void broadcast(const session_msg::SessionMessage& message);
  /// The same with a line already in JSON (a test's).
  void broadcast(const nlohmann::json& message);
  /// Connected clients.
  std::size_t clients() const;
  /// Stops accepting, closes every connection and removes the socket file.
  void close();

  class Impl;

 private:
  explicit ControlServer(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace imucal::service
