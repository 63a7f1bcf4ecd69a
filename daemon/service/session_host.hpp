#pragma once
// What the control socket needs from the service: the guided session as seen from outside.
// imucald implements it around its session; tests implement it with a scripted host. Every
// call is made on the event loop's thread (docs/service.md).

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/result.hpp"

namespace imucal::service {

class SessionHost {
 public:
  virtual ~SessionHost() = default;
  /// {"type":"status","state":...,...}: the session's state now.
  virtual nlohmann::json status() = 0;
  /// The messages that bring a new observer up to date (status, the current prompt, ...).
  virtual std::vector<nlohmann::json> snapshot() = 0;
  /// Start a session with these steps; empty means the configured steps.
  virtual Status start(const std::vector<std::string>& steps) = 0;
  /// An operator key: "continue", "redo", "abort", "accept", "reject" or "skip".
  virtual Status key(const std::string& key) = 0;
};

}  // namespace imucal::service
