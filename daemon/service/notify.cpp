// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/service/notify.hpp"

#include <systemd/sd-daemon.h>

#include <algorithm>

namespace imucal::service {

void Notifier::notify(const std::string& state) {
  // sd_notify returns 0 without NOTIFY_SOCKET and < 0 when the socket is gone; the service
  // keeps running either way (systemd's own watchdog will notice a silent service).
  if (::sd_notify(0, state.c_str()) > 0) {
    ++sent_;
  }
}

void Notifier::ready() { notify("READY=1"); }

void Notifier::status(const std::string& text) {
  // A newline would start another assignment in the notify message (e.g. a forged READY=1).
  std::string line = text;
  std::replace(line.begin(), line.end(), '\n', ' ');
  notify("STATUS=" + line);
}

void Notifier::stopping() { notify("STOPPING=1"); }

void Notifier::watchdog() { notify("WATCHDOG=1"); }

std::optional<std::chrono::microseconds> Notifier::watchdog_interval() const {
  uint64_t usec = 0;
  if (::sd_watchdog_enabled(0, &usec) > 0 && usec > 0) {
    return std::chrono::microseconds(usec);
  }
  return std::nullopt;
}

WatchdogPinger::WatchdogPinger(boost::asio::io_context& io, Notifier& notifier, std::function<bool()> healthy)
    : notifier_(notifier), healthy_(std::move(healthy)), timer_(io) {}

bool WatchdogPinger::start() {
  const auto interval = notifier_.watchdog_interval();
  if (!interval) {
    return false;
  }
  period_ = *interval / 2;
  notifier_.watchdog();
  schedule();
  return true;
}

void WatchdogPinger::stop() { timer_.cancel(); }

void WatchdogPinger::schedule() {
  timer_.expires_after(period_);
  timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) {
      return;  // stopped or destroyed: `this` may be gone
    }
    if (!healthy_ || healthy_()) {
      notifier_.watchdog();
    }
    schedule();
  });
}

std::optional<int> listening_socket_from_systemd() {
  const int n = sd_listen_fds(1);
  if (n < 1) return std::nullopt;
  for (int fd = SD_LISTEN_FDS_START; fd < SD_LISTEN_FDS_START + n; ++fd)
    if (sd_is_socket(fd, AF_UNSPEC, SOCK_STREAM, 1) > 0) return fd;
  return std::nullopt;
}

}  // namespace imucal::service
