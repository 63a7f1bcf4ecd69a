// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A client of imucald's live view over loopback TCP, for its tests and its benchmark: plain
// HTTP exchanges, and the event stream (GET /events) read on a thread of its own, as a browser
// reads it.
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace imucal::test {

/// The loopback address at `port` (0: any port).
inline sockaddr_in loopback(int port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  return a;
}

/// A TCP port free on the loopback now (bound and released; a server binds it next).
inline int free_loopback_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a = loopback(0);
  socklen_t len = sizeof a;
  int port = 0;
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
    port = ntohs(a.sin_port);
  ::close(fd);
  return port;
}

/// A connection to `port` on the loopback whose reads time out after `timeout_s`; -1 when
/// nothing listens.
inline int connect_loopback(int port, int timeout_s) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  const sockaddr_in a = loopback(port);
  timeval tv{timeout_s, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

/// One HTTP exchange on the loopback: the whole response (the server closes after it), or ""
/// when nothing answers.
inline std::string http_exchange(int port, const std::string& request) {
  const int fd = connect_loopback(port, 10);
  if (fd < 0) return "";
  std::string out;
  if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(request.size())) {
    char buf[8192];
    for (ssize_t n; (n = ::recv(fd, buf, sizeof buf, 0)) > 0;) out.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return out;
}

/// The event stream read on a thread of its own until stop(): `on_events` is called on that
/// thread with the events (each "event: ...\ndata: ..." block) that arrived together.
class EventStreamReader {
 public:
  using Handler = std::function<void(const std::vector<std::string>& events)>;
  EventStreamReader(int port, Handler on_events)
      : port_(port), on_events_(std::move(on_events)), thread_([this] { run(); }) {}
  ~EventStreamReader() { stop(); }
  EventStreamReader(const EventStreamReader&) = delete;
  EventStreamReader& operator=(const EventStreamReader&) = delete;
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }

 private:
  void run() {
    const int fd = connect_loopback(port_, 1);
    if (fd < 0) return;
    const std::string req = "GET /events HTTP/1.1\r\nHost: x\r\n\r\n";
    (void)::send(fd, req.data(), req.size(), MSG_NOSIGNAL);
    std::string pending;
    char buf[65536];
    std::vector<std::string> events;
    while (!stop_) {
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      if (n == 0) break;
      if (n < 0) continue;  // the read's timeout: look at stop_ again
      pending.append(buf, static_cast<std::size_t>(n));
      events.clear();
      for (auto end = pending.find("\n\n"); end != std::string::npos; end = pending.find("\n\n")) {
        events.push_back(pending.substr(0, end));
        pending.erase(0, end + 2);
      }
      if (!events.empty()) on_events_(events);
    }
    ::close(fd);
  }

  int port_;
  Handler on_events_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

/// A browser watching: the event stream read as it comes and, with `fetch`, the latest frame's
/// PNG fetched once the events that came together are read (as the page does: a frame that came
/// meanwhile is skipped, never the stream). The counts move after the fetch, so that a caller
/// waiting for frames() also waits for the PNG. While one watches, the service makes frames for
/// the view.
class Watcher {
 public:
  Watcher(int port, bool fetch)
      : port_(port),
        fetch_(fetch),
        reader_(port, [this](const std::vector<std::string>& events) { on(events); }) {}
  /// Stops watching; the PNGs fetched.
  long stop() {
    reader_.stop();
    return pngs_;
  }
  /// Frames announced on the stream.
  long frames() const { return frames_; }
  /// PNG fetches not answered 200 (the server's connection limit).
  long refused() const { return refused_; }

 private:
  void on(const std::vector<std::string>& events) {
    std::string latest;  // "camera.png?seq=S" of the last frame announced so far
    long announced = 0;
    for (const std::string& ev : events) {
      // {"camera":N,...,"seq":S,...}: keys in order; the corners between them can be long.
      if (ev.rfind("event: frame\n", 0) != 0) continue;
      ++announced;
      const auto c = ev.find("\"camera\":"), q = ev.find("\"seq\":");
      if (c == std::string::npos || q == std::string::npos) continue;
      latest = std::to_string(std::atol(ev.c_str() + c + 9)) +
               ".png?seq=" + std::to_string(std::atol(ev.c_str() + q + 6));
    }
    if (fetch_ && !latest.empty()) {
      const std::string png = http_exchange(port_, "GET /frame/" + latest + " HTTP/1.1\r\nHost: x\r\n\r\n");
      ++(png.rfind("HTTP/1.1 200", 0) == 0 ? pngs_ : refused_);
    }
    frames_ += announced;
  }
  int port_;
  bool fetch_;
  std::atomic<long> frames_{0}, pngs_{0}, refused_{0};
  EventStreamReader reader_;  // last: its thread calls on() until it is stopped
};

}  // namespace imucal::test
