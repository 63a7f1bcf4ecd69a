// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The MPU-6000's data-ready interrupt as seen by the host: rising edges with a kernel
// timestamp on CLOCK_MONOTONIC. Implementations: the libgpiod 1.6 line (real GPIO chip) and
// the simulated line in drivers/sim (edges with configurable latency jitter).

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::drivers {

struct DataReadyEdge {
  TimeNs t_ns = 0;             // kernel timestamp of the rising edge, CLOCK_MONOTONIC
  std::uint64_t sequence = 0;  // counts edges seen by the line (gaps show missed events)
};

class DataReadyLine {
 public:
  virtual ~DataReadyLine() = default;

  /// Waits up to `timeout_ns` for the next rising edge. Returns nullopt on timeout.
  [[nodiscard]] virtual Result<std::optional<DataReadyEdge>> wait(TimeNs timeout_ns) = 0;

  /// A file descriptor that becomes readable when an edge is pending (for an event loop),
  /// or -1 if the line cannot provide one (then poll with wait()).
  virtual int fd() const { return -1; }

  virtual std::string name() const = 0;
};

}  // namespace imucal::drivers
