// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// imucalctl's side of the control socket: a blocking connection that writes request lines and
// reads message lines (docs/service.md).

#include <chrono>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"

namespace imucal::ctl {

/// How a connection failed, so imucalctl can say what to do about it.
enum class ConnectFailure { kNone, kNoService, kPermission, kOther };

class Connection {
 public:
  /// Connects to the service's socket. Errors say whether the service is absent or the user
  /// lacks permission, and what to do.
  static Result<Connection> open(const std::string& path, ConnectFailure* failure = nullptr);

  Connection(Connection&& other) noexcept;
  Connection& operator=(Connection&& other) noexcept;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection();

  Status send(const nlohmann::json& request);
  /// The next message: from the buffer, else reads, waiting up to `timeout` (forever when
  /// none). kNotFound when the service closed the connection, kTimeout when nothing came.
  Result<nlohmann::json> receive(std::optional<std::chrono::milliseconds> timeout = std::nullopt);
  /// A message already buffered, without reading.
  std::optional<nlohmann::json> buffered();
  /// One read of whatever is available (for a poll loop); kNotFound at end of stream.
  Status read_some();
  /// After a failed send: the reason of a refusal the service sent before closing (an error
  /// reply), read within 200 ms, or empty.
  std::string refusal();
  /// Sends a request and waits for its reply; messages that came before it go to `others`.
  /// The error of a refused request is the service's message.
  Result<nlohmann::json> request(const nlohmann::json& request, std::vector<nlohmann::json>* others = nullptr,
                                 std::chrono::milliseconds timeout = std::chrono::seconds(10));

  int fd() const { return fd_; }

 private:
  explicit Connection(int fd) : fd_(fd) {}
  int fd_ = -1;
  std::string input_;
};

}  // namespace imucal::ctl
