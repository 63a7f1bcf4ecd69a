// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A SessionHost for tests and a ControlServer running on its own thread, so tests talk to it
// through real sockets (the in-process client, imucalctl processes, a tmux pane).

#include <gtest/gtest.h>
#include <stdlib.h>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <chrono>
#include <filesystem>
#include <future>
#include <mutex>
#include <thread>

#include "daemon/service/control_server.hpp"

namespace imucal::test {

/// A fresh folder under /tmp, removed at the end of its scope. Short on purpose: a Unix socket
/// path holds at most 107 bytes, less than the build tree's scratch folders may need.
class SocketDir {
 public:
  SocketDir() {
    char name[] = "/tmp/imucal-svc-XXXXXX";
    if (::mkdtemp(name) != nullptr) {
      path = name;
    }
  }
  ~SocketDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
  SocketDir(const SocketDir&) = delete;
  SocketDir& operator=(const SocketDir&) = delete;
  std::string socket() const { return path + "/imucald.sock"; }
  std::string path;
};

/// A session host whose status and snapshot a test gives as the JSON it expects on the socket
/// (decoded here, as the service's own would be typed).
class TestHost : public service::SessionHost {
 public:
  session_msg::Status status() override {
    std::lock_guard lock(mutex_);
    return std::get<session_msg::Status>(typed(status_));
  }
  std::vector<session_msg::SessionMessage> snapshot() override {
    std::lock_guard lock(mutex_);
    std::vector<session_msg::SessionMessage> messages{typed(status_)};
    for (const auto& m : extra_snapshot_) messages.push_back(typed(m));
    return messages;
  }
  Status start(const std::vector<std::string>& steps) override {
    std::lock_guard lock(mutex_);
    starts_.push_back(steps);
    return {};
  }
  Status key(session_msg::OperatorKey key) override {
    std::lock_guard lock(mutex_);
    keys_.emplace_back(session_msg::key_name(key));
    if (key == session_msg::OperatorKey::kSkip) {
      return make_error(Errc::kInvalidArgument, "the step 'preflight' cannot be skipped");
    }
    return {};
  }

  void set_status(nlohmann::json status) {
    std::lock_guard lock(mutex_);
    status_ = std::move(status);
  }
  void set_snapshot_extra(std::vector<nlohmann::json> messages) {
    std::lock_guard lock(mutex_);
    extra_snapshot_ = std::move(messages);
  }
  std::vector<std::string> keys() {
    std::lock_guard lock(mutex_);
    return keys_;
  }
  std::vector<std::vector<std::string>> starts() {
    std::lock_guard lock(mutex_);
    return starts_;
  }

 private:
  /// A test's message, decoded; a test that gives one the decoder refuses is wrong.
  static session_msg::SessionMessage typed(const nlohmann::json& message) {
    auto m = session_msg::decode(message);
    if (!m.ok()) {
      ADD_FAILURE() << "the test host's message does not decode: " << m.error().message;
      return session_msg::Status{};
    }
    return *m;
  }
  std::mutex mutex_;
  nlohmann::json status_{{"type", "status"},
                         {"state", "running"},
                         {"rig", "sim"},
                         {"step", "poses"},
                         {"steps",
                          {{{"name", "preflight"}, {"state", "done"}},
                           {{"name", "still"}, {"state", "done"}},
                           {{"name", "poses"}, {"state", "active"}},
                           {{"name", "solve"}, {"state", "pending"}}}},
                         {"elapsed_s", 12.3}};
  std::vector<nlohmann::json> extra_snapshot_;
  std::vector<std::string> keys_;
  std::vector<std::vector<std::string>> starts_;
};

/// An io_context run by a thread of its own; call() runs a function on that thread and waits.
class IoThread {
 public:
  IoThread() : work_(io.get_executor()), thread_([this] { io.run(); }) {}
  ~IoThread() { stop(); }
  IoThread(const IoThread&) = delete;
  IoThread& operator=(const IoThread&) = delete;
  /// Runs f on the thread and returns its result.
  template <class F>
  auto call(F&& f) {
    std::packaged_task<decltype(f())()> task(std::forward<F>(f));
    auto future = task.get_future();
    boost::asio::post(io, [&task] { task(); });
    return future.get();
  }
  /// Lets the loop end and joins the thread (once).
  void stop() {
    if (!thread_.joinable()) return;
    work_.reset();
    io.stop();
    thread_.join();
  }
  boost::asio::io_context io;

 private:
  boost::asio::executor_work_guard<boost::asio::io_context::executor_type> work_;
  std::thread thread_;
};

/// A ControlServer on a thread of its own.
class TestService {
 public:
  explicit TestService(service::ControlServerOptions options) {
    loop_.call([&] {
      auto created = service::ControlServer::create(loop_.io, options, host);
      if (created) {
        server_ = std::move(*created);
      } else {
        error = created.error().message;
      }
    });
  }
  /// Runs f on the server's thread and returns its result.
  template <class F>
  auto call(F&& f) {
    return loop_.call(std::forward<F>(f));
  }

  ~TestService() {
    call([this] { server_.reset(); });
    loop_.stop();
  }
  TestService(const TestService&) = delete;
  TestService& operator=(const TestService&) = delete;

  bool ok() const { return error.empty(); }

  void broadcast(const nlohmann::json& message) {
    call([&] {
      if (server_) {
        server_->broadcast(message);
      }
    });
  }
  std::size_t clients() {
    return call([&] { return server_ ? server_->clients() : std::size_t{0}; });
  }
  void close() {
    call([&] {
      if (server_) {
        server_->close();
      }
    });
  }

  /// Waits (up to `limit`) until `condition` holds; for effects that cross processes.
  template <class F>
  static bool wait_for(F condition, std::chrono::milliseconds limit = std::chrono::seconds(20)) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (!condition()) {
      if (std::chrono::steady_clock::now() > end) {
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return true;
  }

  TestHost host;
  std::string error;

 private:
  // Declared first: destroyed last, after the server (whose handlers it runs) is gone.
  IoThread loop_;
  std::unique_ptr<service::ControlServer> server_;
};

}  // namespace imucal::test
