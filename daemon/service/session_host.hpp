// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the control socket needs from the service: the guided session as seen from outside.
// imucald implements it around its session; tests implement it with a scripted host. Every
// call is made on the event loop's thread (docs/service.md).

#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/session_messages.hpp"

namespace imucal::service {

class SessionHost {
 public:
  virtual ~SessionHost() = default;
  /// The session's state now.
  virtual session_msg::Status status() = 0;
  /// The messages that bring a new observer up to date (status, the current prompt, ...).
  virtual std::vector<session_msg::SessionMessage> snapshot() = 0;
  /// Start a session with these steps; empty means the configured steps.
  virtual Status start(const std::vector<std::string>& steps) = 0;
  /// An operator key.
  virtual Status key(session_msg::OperatorKey key) = 0;
};

}  // namespace imucal::service
