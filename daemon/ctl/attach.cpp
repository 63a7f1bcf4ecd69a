// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/ctl/attach.hpp"

#include <poll.h>
#include <sys/ioctl.h>
#include <sys/signalfd.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <string>
#include <utility>

#include "core/printable_text.hpp"
#include "daemon/ctl/console.hpp"
#include "daemon/service/protocol.hpp"

namespace imucal::ctl {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

// Redraw at most ten times a second: live figures may come faster than a person reads.
constexpr auto kRedrawInterval = std::chrono::milliseconds(100);

void write_all(int fd, const std::string& text) {
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) {
      continue;
    }
    if (n <= 0) {
      return;
    }
    done += static_cast<std::size_t>(n);
  }
}

// Keys without Enter and without echo; output processing stays on so '\n' still returns the
// carriage. Signals stay enabled: Ctrl-C arrives through the signalfd and detaches cleanly.
class RawTerminal {
 public:
  explicit RawTerminal(int fd) : fd_(fd) {
    if (::isatty(fd) == 0 || ::tcgetattr(fd, &saved_) != 0) {
      return;
    }
    termios raw = saved_;
    raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);
    raw.c_cc[VMIN] = 1;
    raw.c_cc[VTIME] = 0;
    active_ = ::tcsetattr(fd, TCSANOW, &raw) == 0;
  }
  ~RawTerminal() {
    if (active_) {
      ::tcsetattr(fd_, TCSANOW, &saved_);
    }
  }
  RawTerminal(const RawTerminal&) = delete;
  RawTerminal& operator=(const RawTerminal&) = delete;

 private:
  int fd_;
  termios saved_{};
  bool active_ = false;
};

// The signals that end or redraw the console, delivered as readable bytes instead of handlers,
// so the terminal is restored by the same code path as a 'q'.
class SignalFd {
 public:
  SignalFd() {
    sigemptyset(&set_);
    for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGWINCH}) {
      sigaddset(&set_, sig);
    }
    ::sigprocmask(SIG_BLOCK, &set_, &old_);
    fd_ = ::signalfd(-1, &set_, SFD_CLOEXEC);
  }
  ~SignalFd() {
    if (fd_ >= 0) {
      ::close(fd_);
    }
    ::sigprocmask(SIG_SETMASK, &old_, nullptr);
  }
  SignalFd(const SignalFd&) = delete;
  SignalFd& operator=(const SignalFd&) = delete;
  int fd() const { return fd_; }
  int next() const {
    signalfd_siginfo info{};
    return ::read(fd_, &info, sizeof(info)) == static_cast<ssize_t>(sizeof(info))
               ? static_cast<int>(info.ssi_signo)
               : 0;
  }

 private:
  sigset_t set_{};
  sigset_t old_{};
  int fd_ = -1;
};

// Columns and rows of the terminal (80 x 24 when it does not say).
std::pair<int, int> terminal_size() {
  winsize ws{};
  if (::ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0 && ws.ws_row > 0) {
    return {ws.ws_col, ws.ws_row};
  }
  return {80, 24};
}

// The elapsed time in the header moves on once a second while a session runs.
constexpr auto kTick = std::chrono::seconds(1);

// A controlling console says hello again this often, so that the service never takes it for an
// idle controller (ControlServerOptions::controller_idle_after) while the operator watches.
constexpr auto kKeepAlive = std::chrono::seconds(60);

class Console {
 public:
  Console(Connection& connection, bool observe, bool tty)
      : connection_(connection), tty_(tty), last_draw_(Clock::now() - kRedrawInterval) {
    state_.observe = observe;
  }

  void show(const json& message) {
    update(state_, message);
    last_message_ = Clock::now();
    send_outbox();
    if (tty_) {
      dirty_ = true;
    } else if (auto line = plain_line(message)) {
      write_all(STDOUT_FILENO, *line + '\n');
    }
  }

  // False when the operator detached.
  bool key(char c) {
    const KeyAction action = on_key(state_, c);
    if (action.detach) {
      return false;
    }
    if (action.request) {
      send(*action.request);
    }
    dirty_ = true;
    return true;
  }

  // A request update() made (the start that follows a restart's abort).
  void send_outbox() {
    while (!state_.outbox.empty()) {
      send(state_.outbox.front());
      state_.outbox.pop_front();
    }
  }

  void redraw_now() { dirty_ = true, last_draw_ = Clock::now() - kRedrawInterval; }

  // The service went away: draws the last screen at once, marked as such (false without a
  // terminal, where the caller prints the reason).
  bool lost(const std::string& why) {
    service_lost(state_, why);
    if (!tty_) return false;
    const auto [width, height] = terminal_size();
    write_all(STDOUT_FILENO, "\x1b[H\x1b[2J" + render(state_, {width, height, 0.0}));
    return true;
  }

  // Says hello as controller again when a keep-alive is due; returns the poll timeout until the
  // next one (-1 for an observer, which needs none).
  int keep_alive_if_due() {
    if (state_.observe) return -1;
    const auto now = Clock::now();
    if (now >= next_keep_alive_) {
      send(service::to_json(service::hello_request("imucalctl", service::Role::kController)));
      next_keep_alive_ = now + kKeepAlive;
    }
    return static_cast<int>(std::chrono::ceil<std::chrono::milliseconds>(next_keep_alive_ - now).count());
  }

  // Draws when due; returns the poll timeout until the next draw (-1: nothing pending).
  int draw_if_due() {
    const auto now = Clock::now();
    if (tty_ && session_running(state_) && now - last_draw_ >= kTick) {
      dirty_ = true;
    }
    if (!tty_ || !dirty_) {
      return tty_ && session_running(state_)
                 ? static_cast<int>(
                       std::chrono::ceil<std::chrono::milliseconds>(kTick - (now - last_draw_)).count())
                 : -1;
    }
    if (now - last_draw_ < kRedrawInterval) {
      return static_cast<int>(
          std::chrono::ceil<std::chrono::milliseconds>(kRedrawInterval - (now - last_draw_)).count());
    }
    const auto [width, height] = terminal_size();
    const double idle = std::chrono::duration<double>(now - last_message_).count();
    write_all(STDOUT_FILENO, "\x1b[H\x1b[2J" + render(state_, {width, height, idle}));
    last_draw_ = now;
    dirty_ = false;
    return session_running(state_) ? static_cast<int>(std::chrono::milliseconds(kTick).count()) : -1;
  }

 private:
  void send(const json& request) {
    if (auto sent = connection_.send(request); !sent) {
      state_.notice = sent.error().message;
    }
  }

  Connection& connection_;
  ConsoleState state_;
  bool tty_;
  bool dirty_ = true;
  Clock::time_point last_draw_;
  Clock::time_point last_message_ = Clock::now();
  Clock::time_point next_keep_alive_ = Clock::now() + kKeepAlive;
};

// The poll loop over the service, the keyboard and the signals.
int run(Connection& connection, Console& console) {
  SignalFd signals;
  RawTerminal terminal(STDIN_FILENO);
  bool keyboard = true;
  for (;;) {
    // Messages that arrived with the last read (or with the subscribe reply) come first: poll
    // only reports new bytes.
    while (auto message = connection.buffered()) {
      console.show(*message);
    }
    const int draw = console.draw_if_due();
    const int keep_alive = console.keep_alive_if_due();
    const int timeout = draw < 0 ? keep_alive : keep_alive < 0 ? draw : std::min(draw, keep_alive);
    pollfd fds[3] = {
        {connection.fd(), POLLIN, 0}, {signals.fd(), POLLIN, 0}, {keyboard ? STDIN_FILENO : -1, POLLIN, 0}};
    if (::poll(fds, 3, timeout) < 0 && errno != EINTR) {
      return 1;
    }
    if ((fds[0].revents & (POLLIN | POLLHUP | POLLERR)) != 0) {
      if (auto read = connection.read_some(); !read) {
        // The last screen stays, marked as no longer live, with what to do; a pipe gets the line.
        if (!console.lost(read.error().message)) {
          std::fprintf(stderr, "imucalctl: %s\n", printable_text(read.error().message).c_str());
        }
        return 1;
      }
    }
    if ((fds[1].revents & POLLIN) != 0) {
      if (signals.next() != SIGWINCH) {
        return 0;
      }
      console.redraw_now();
    }
    if ((fds[2].revents & (POLLIN | POLLHUP)) != 0) {
      char keys[64];
      const ssize_t n = ::read(STDIN_FILENO, keys, sizeof(keys));
      if (n <= 0) {
        keyboard = false;  // stdin closed: keep showing what the service sends
      }
      for (ssize_t i = 0; i < n; ++i) {
        if (!console.key(keys[i])) {
          return 0;
        }
      }
    }
  }
}

}  // namespace

int attach(Connection& connection, const AttachOptions& options) {
  const bool tty = ::isatty(STDOUT_FILENO) != 0;
  Console console(connection, options.observe, tty);
  std::vector<json> early;
  const service::Request hello = service::hello_request(
      "imucalctl", options.observe ? service::Role::kObserver : service::Role::kController);
  auto replied = connection.request(service::to_json(hello), &early);
  if (replied) {
    replied =
        connection.request(service::to_json(service::plain_request(service::Command::kSubscribe)), &early);
  }
  if (!replied) {
    std::fprintf(stderr, "imucalctl: %s\n", printable_text(replied.error().message).c_str());
    return 1;
  }
  for (const auto& message : early) {
    console.show(message);
  }
  const int code = run(connection, console);
  if (tty) {
    write_all(STDOUT_FILENO, "\n");
  }
  return code;
}

}  // namespace imucal::ctl
