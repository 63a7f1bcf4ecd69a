// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// imucald as a process on the virtual rig, for the tests that run it (test_imucald.cpp,
// test_imucald_live_view.cpp): its configuration, the process, its session log.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::test {

inline bool has(const std::string& text, const std::string& fragment) {
  return text.find(fragment) != std::string::npos;
}

inline bool wait_for(const std::function<bool()>& done, double seconds = 120.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return done();
}

/// A rig configuration in `dir` with its storage there too; `extra` is appended (a session
/// section); `camera` replaces the camera's size and rate.
inline std::string write_config(const std::string& dir, const std::string& extra = "",
                                const std::string& camera = "") {
  std::ifstream in(source_path("config/rig.yaml"));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!camera.empty())
    text = std::regex_replace(text, std::regex("    width: 640\n    height: 480\n    rate_hz: 20\n"), camera);
  text = std::regex_replace(text, std::regex("path: /var/lib/imucal/calibration.bin"),
                            "path: " + dir + "/eeprom.bin");
  text = std::regex_replace(text, std::regex("target: checkerboard-7x6.yaml"),
                            "target: " + source_path("config/checkerboard-7x6.yaml"));
  const std::string path = dir + "/rig.yaml";
  std::ofstream(path) << text << extra;
  return path;
}

/// A socket path short enough for sun_path (107 bytes): the scratch folders are deeper.
inline std::string short_socket_path() {
  char tmpl[] = "/tmp/imucald-test-XXXXXX";
  if (!::mkdtemp(tmpl)) return "/tmp/imucald-test.sock";
  return std::string(tmpl) + "/s.sock";
}

/// imucald started with fork/exec; killed (SIGKILL) if still running at the end.
class Daemon {
 public:
  Daemon(const std::string& dir, const std::vector<std::string>& extra, const std::string& config = "")
      : socket_(short_socket_path()) {
    std::vector<std::string> args = {IMUCALD_PATH,   "--config", config.empty() ? write_config(dir) : config,
                                     "--socket",     socket_,    "--state-dir",
                                     dir + "/state", "--sim",    "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    pid_ = ::fork();
    if (pid_ == 0) {
      const std::string log = dir + "/imucald.log";
      (void)!std::freopen(log.c_str(), "w", stderr);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      std::_Exit(127);
    }
  }
  ~Daemon() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      (void)wait();
    }
  }
  const std::string& socket() const { return socket_; }
  pid_t pid() const { return pid_; }
  bool ready() const { return std::filesystem::exists(socket_); }
  /// Waits for the process; its exit status, or 128 + signal.
  int wait() {
    int status = 0;
    ::waitpid(pid_, &status, 0);
    exited_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  /// Waits at most `seconds` for the process; its exit status as wait() gives it, or -1 while it
  /// still runs (the destructor then kills it).
  int wait_for_exit(double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > end) return -1;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    exited_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

 private:
  std::string socket_;
  pid_t pid_ = -1;
  bool exited_ = false;
};

inline std::string session_log(const std::string& dir) {
  const auto sessions = std::filesystem::path(dir) / "state" / "sessions";
  if (!std::filesystem::exists(sessions)) return "";
  for (const auto& e : std::filesystem::directory_iterator(sessions))
    return (e.path() / "session.imulog").string();
  return "";
}

inline std::string all_events(const std::string& log) {
  auto reader = log::SessionLogReader::open(log);
  if (!reader.ok()) return "";
  auto events = (*reader)->events();
  std::string out;
  if (events.ok())
    for (const auto& e : *events) out += e.message + "\n";
  return out;
}

}  // namespace imucal::test
