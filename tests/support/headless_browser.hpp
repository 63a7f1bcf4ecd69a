// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Headless Chromium driven through its DevTools protocol on a pipe (--remote-debugging-pipe: the
// browser reads commands on its fd 3 and answers on its fd 4, each message a JSON text ended by a
// NUL byte), for tests that follow a page in real time: a stream that never ends, a service that
// restarts under it. (--dump-dom runs a page in virtual time, which a stream holds still.)
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string>

namespace imucal::test {

class HeadlessBrowser {
 public:
  /// Starts chromium with its profile in `profile_dir`; its stderr goes to `log_path`.
  HeadlessBrowser(const std::string& profile_dir, const std::string& log_path) {
    int to_browser[2], from_browser[2];
    if (::pipe2(to_browser, O_CLOEXEC) != 0) return;
    if (::pipe2(from_browser, O_CLOEXEC) != 0) {
      ::close(to_browser[0]);
      ::close(to_browser[1]);
      return;
    }
    pid_ = ::fork();
    if (pid_ == 0) {
      // Above 4 first, so that moving one end onto 3 or 4 cannot close the other.
      const int in = ::fcntl(to_browser[0], F_DUPFD_CLOEXEC, 10),
                out = ::fcntl(from_browser[1], F_DUPFD_CLOEXEC, 10);
      ::dup2(in, 3);
      ::dup2(out, 4);
      (void)!std::freopen(log_path.c_str(), "w", stderr);
      (void)!std::freopen("/dev/null", "w", stdout);
      const std::string profile = "--user-data-dir=" + profile_dir;
      ::execlp("chromium", "chromium", "--headless", "--no-sandbox", "--disable-gpu",
               "--remote-debugging-pipe", "--no-first-run", profile.c_str(), "about:blank",
               static_cast<char*>(nullptr));
      std::_Exit(127);
    }
    ::close(to_browser[0]);
    ::close(from_browser[1]);
    write_fd_ = to_browser[1];
    read_fd_ = from_browser[0];
  }
  ~HeadlessBrowser() {
    if (pid_ > 0) {
      (void)call("Browser.close", {}, false, 5.0);
      int status = 0;
      for (int i = 0; i < 50 && ::waitpid(pid_, &status, WNOHANG) == 0; ++i) ::usleep(100'000);
      if (::waitpid(pid_, &status, WNOHANG) == 0) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
      }
    }
    if (write_fd_ >= 0) ::close(write_fd_);
    if (read_fd_ >= 0) ::close(read_fd_);
  }
  HeadlessBrowser(const HeadlessBrowser&) = delete;
  HeadlessBrowser& operator=(const HeadlessBrowser&) = delete;

  /// Opens `url` in a new tab and attaches to it; false (with error() set) when the browser does
  /// not answer.
  bool open(const std::string& url) {
    const auto target = call("Target.createTarget", {{"url", url}}, false);
    if (!target.contains("targetId")) return false;
    const auto attached =
        call("Target.attachToTarget", {{"targetId", target["targetId"]}, {"flatten", true}}, false);
    if (!attached.contains("sessionId")) return false;
    session_ = attached["sessionId"].get<std::string>();
    return true;
  }

  /// The value of a JavaScript expression in the page, as JSON; null when it threw or the browser
  /// did not answer (error() says which).
  nlohmann::json evaluate(const std::string& expression) {
    const auto r = call("Runtime.evaluate", {{"expression", expression}, {"returnByValue", true}}, true);
    if (r.contains("exceptionDetails")) {
      error_ = r["exceptionDetails"].dump();
      return nullptr;
    }
    return r.contains("result") && r["result"].contains("value") ? r["result"]["value"] : nlohmann::json();
  }
  /// evaluate() as text: a string as it is, anything else as JSON.
  std::string text(const std::string& expression) {
    const auto v = evaluate(expression);
    return v.is_string() ? v.get<std::string>() : v.dump();
  }
  const std::string& error() const { return error_; }

 private:
  /// One command and its answer's "result" ({} on error, with error() set).
  nlohmann::json call(const std::string& method, const nlohmann::json& params, bool in_page,
                      double timeout_s = 30.0) {
    if (write_fd_ < 0) {
      error_ = "chromium did not start";
      return nlohmann::json::object();
    }
    nlohmann::json m = {{"id", ++id_}, {"method", method}, {"params", params}};
    if (in_page) m["sessionId"] = session_;
    std::string wire = m.dump();
    wire.push_back('\0');
    for (std::size_t sent = 0; sent < wire.size();) {
      const ssize_t n = ::write(write_fd_, wire.data() + sent, wire.size() - sent);
      if (n <= 0) {
        error_ = "chromium's pipe is closed";
        return nlohmann::json::object();
      }
      sent += static_cast<std::size_t>(n);
    }
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (true) {
      // Events (messages without our id) are skipped.
      for (auto nul = pending_.find('\0'); nul != std::string::npos; nul = pending_.find('\0')) {
        const auto reply = nlohmann::json::parse(pending_.substr(0, nul), nullptr, false);
        pending_.erase(0, nul + 1);
        if (!reply.is_object() || reply.value("id", -1) != id_) continue;
        if (reply.contains("error")) {
          error_ = reply["error"].dump();
          return nlohmann::json::object();
        }
        return reply.value("result", nlohmann::json::object());
      }
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now())
              .count();
      pollfd p{read_fd_, POLLIN, 0};
      if (left <= 0 || ::poll(&p, 1, static_cast<int>(left)) <= 0) {
        error_ = method + ": no answer from chromium in " + std::to_string(timeout_s) + " s";
        return nlohmann::json::object();
      }
      char buf[65536];
      const ssize_t n = ::read(read_fd_, buf, sizeof buf);
      if (n <= 0) {
        error_ = "chromium closed its pipe (see its log)";
        return nlohmann::json::object();
      }
      pending_.append(buf, static_cast<std::size_t>(n));
    }
  }

  pid_t pid_ = -1;
  int write_fd_ = -1, read_fd_ = -1;
  int id_ = 0;
  std::string session_, pending_, error_;
};

}  // namespace imucal::test
