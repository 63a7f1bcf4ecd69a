// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The live view: the guided session served to a web browser over HTTP (Boost.Beast) on the
// service's one event loop (docs/service.md, "Live view"). One self-contained page; the session's
// messages and each camera's frames reach it as server-sent events; the frames themselves as
// PNG. Watching is open to whoever reaches the address (loopback by default); the operator's keys
// need the token. Nothing a client does can block the loop or the recording: reads and writes
// are asynchronous, a request is bounded in size and time, a stream that falls behind is closed,
// and frames are only ever dropped for the view.
//
// Served: GET / (the page), GET /events (the stream; ?snapshot=1: the state now, in a response
// that ends), GET /frame/<camera>.png and .json (a frame
// the server still keeps; ?seq=N, or the latest), GET /report/<i> (the i-th report the session's
// end named), POST /key/<name> (start, or an operator key; header X-Imucal-Token). Nothing else,
// and no path from a request ever reaches the file system.

#include <boost/asio/io_context.hpp>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/session_messages.hpp"
#include "core/view_frame.hpp"
#include "daemon/service/session_host.hpp"

namespace imucal::service {

struct LiveViewOptions {
  std::string address = "127.0.0.1";
  unsigned short port = 8421;  // 0: a free port (tests)
  /// A socket already listening (systemd's socket activation, imucald.socket): used instead of
  /// binding address and port, which then only name it. -1: none.
  int listen_fd = -1;
  std::string token;    // the keys' token; empty: every key is refused
  std::string version;  // imucald's, for the page
  std::string rig;      // the configuration's name
  std::vector<std::string> cameras;
  std::size_t max_clients = 64;                      // more connections are answered 503 and closed
  std::size_t max_header_bytes = 8192;               // a larger request head is answered 431
  std::size_t max_body_bytes = 4096;                 // a larger body is answered 413
  std::chrono::milliseconds request_timeout{10000};  // a request not whole by then is dropped
  std::size_t max_queued_bytes = 4 << 20;            // an event stream with more unsent is closed
  std::size_t frames_kept = 16;                      // per camera, for /frame/<camera>.png?seq=N
  std::size_t max_report_bytes = 64 << 20;
  std::function<void(const std::string&)> log;  // optional: why a client was dropped
};

/// The page the server sends for GET / (daemon/service/live_view_page.html, built in).
const std::string& live_view_page();

/// Whether `given` is the token, in time that does not depend on where they differ.
bool token_matches(const std::string& token, const std::string& given);

/// A new token: 32 hex digits from the system's random source.
[[nodiscard]] Result<std::string> make_token();

class LiveViewServer {
 public:
  /// Binds and listens; the errors name the address and what to do. The host must outlive the
  /// server.
  [[nodiscard]] static Result<std::unique_ptr<LiveViewServer>> create(boost::asio::io_context& io,
                                                                      LiveViewOptions options,
                                                                      SessionHost& host);
  ~LiveViewServer();
  LiveViewServer(const LiveViewServer&) = delete;
  LiveViewServer& operator=(const LiveViewServer&) = delete;

  /// A session message to every event stream (and kept for the streams that open later: the
  /// last live figures, review, result and end). Call on the io thread.
  void broadcast(const session_msg::SessionMessage& message);
  /// A camera's frame and its PNG: kept (the last frames_kept a camera) and announced to every
  /// event stream. Call on the io thread.
  void frame(ViewFrame frame, std::vector<std::uint8_t> png);
  /// Event streams open now, and one more while a snapshot was asked for in the last 3 s: while
  /// none, nobody watches and frames need not be made.
  std::size_t watchers() const;
  std::size_t clients() const;
  /// "http://127.0.0.1:8421/"
  std::string url() const;
  unsigned short port() const;
  /// Stops accepting and closes every connection.
  void close();

  class Impl;

 private:
  explicit LiveViewServer(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace imucal::service
