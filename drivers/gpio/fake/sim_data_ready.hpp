// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A simulated data-ready line: the emulated chip raises its INT pin at a true host time, the
// "kernel" timestamps the edge after a latency with Gaussian jitter, and wait() hands edges out
// in order, advancing simulated time as a real wait would let real time pass.

#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/gpio/data_ready_line.hpp"

namespace imucal::fake {

/// The owner of simulated host time (the emulated chip): everything that happens in the
/// simulation happens inside advance_to().
class SimTimeSource {
 public:
  virtual ~SimTimeSource() = default;
  virtual TimeNs now_ns() const = 0;
  /// Host time of the next internal event (a sample), or kNever.
  virtual TimeNs next_event_ns() const = 0;
  virtual void advance_to(TimeNs host_t_ns) = 0;

  static constexpr TimeNs kNever = std::numeric_limits<TimeNs>::max();
};

struct DataReadyTiming {
  TimeNs latency_ns = 20'000;  // mean interrupt latency (edge to kernel timestamp)
  TimeNs sigma_ns = 30'000;    // Gaussian jitter; the latency is clipped at 0
  std::uint64_t seed = 1;
};

class SimDataReadyLine : public drivers::DataReadyLine {
 public:
  /// `time` is borrowed and must outlive the line.
  explicit SimDataReadyLine(SimTimeSource& time, DataReadyTiming timing = {});

  /// The chip raised INT at `true_t_ns` (host clock). Edges stay in order (monotonic timestamps).
  void raise(TimeNs true_t_ns);

  /// Fault: the host loses the next `n` edges. The sequence number still counts them (as the
  /// kernel's line event sequence does), so a reader sees the gap.
  void drop_next(int n) { drop_remaining_ += n; }

  [[nodiscard]] Result<std::optional<drivers::DataReadyEdge>> wait(TimeNs timeout_ns) override;
  std::string name() const override { return "sim-data-ready"; }

  std::uint64_t raised() const { return raised_; }
  std::uint64_t dropped() const { return dropped_; }
  /// Latency (edge timestamp minus true time) of the first kMaxLatencies edges raised, for tests.
  /// Bounded: a virtual rig that runs for days (the service's) must not grow with it.
  const std::vector<TimeNs>& latencies_ns() const { return latencies_ns_; }
  static constexpr std::size_t kMaxLatencies = 100'000;

 private:
  SimTimeSource& time_;
  DataReadyTiming timing_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::deque<drivers::DataReadyEdge> pending_;
  TimeNs last_edge_t_ns_ = std::numeric_limits<TimeNs>::min();
  std::uint64_t sequence_ = 0;
  std::uint64_t raised_ = 0;
  std::uint64_t dropped_ = 0;
  int drop_remaining_ = 0;
  std::vector<TimeNs> latencies_ns_;
};

}  // namespace imucal::fake
