// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Readiness, status and watchdog messages to systemd (sd_notify), for a Type=notify unit with
// WatchdogSec=. Every call is a no-op when the service was not started by systemd
// (NOTIFY_SOCKET unset), so the same binary runs by hand.

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <functional>
#include <optional>
#include <string>

namespace imucal::service {

class Notifier {
 public:
  /// READY=1: the control socket is listening.
  void ready();
  /// STATUS=text: one line shown by systemctl status (newlines become spaces).
  void status(const std::string& text);
  /// STOPPING=1: the service has begun to shut down.
  void stopping();
  /// The watchdog period systemd expects pings within (WatchdogSec=), or none when disabled.
  /// Ping at half of it.
  std::optional<std::chrono::microseconds> watchdog_interval() const;
  /// WATCHDOG=1.
  void watchdog();

  /// Messages systemd accepted; 0 when NOTIFY_SOCKET is unset. For status output and tests.
  unsigned sent() const { return sent_; }

 private:
  void notify(const std::string& state);
  unsigned sent_ = 0;
};

/// The listening TCP socket systemd passed (socket activation: imucald.socket, docs/service.md
/// "Live view"), or none. Taken once: the variables that name it are removed, so that no child
/// process inherits them.
std::optional<int> listening_socket_from_systemd();

/// Pings the watchdog from the service's event loop at half the period systemd expects, while
/// `healthy` (when given) says the service works. A stuck loop or an unhealthy service stops
/// the pings, and systemd restarts it (WatchdogSec=, Restart=on-failure).
class WatchdogPinger {
 public:
  WatchdogPinger(boost::asio::io_context& io, Notifier& notifier, std::function<bool()> healthy = {});
  ~WatchdogPinger() { stop(); }
  WatchdogPinger(const WatchdogPinger&) = delete;
  WatchdogPinger& operator=(const WatchdogPinger&) = delete;

  /// Starts pinging; false (and nothing scheduled) when systemd set no watchdog.
  bool start();
  void stop();

 private:
  void schedule();
  Notifier& notifier_;
  std::function<bool()> healthy_;
  boost::asio::steady_timer timer_;
  std::chrono::microseconds period_{0};
};

}  // namespace imucal::service
