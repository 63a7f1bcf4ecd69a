// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A simulated data-ready line with a real file descriptor, for the real-time virtual rig
// (sim/realtime.hpp) and the event-loop acquisition: an eventfd in semaphore mode whose count
// is the number of readable edges, as libgpiod's line event fd is readable while events are
// pending. Each edge carries a kernel-like timestamp (the chip's true sample time plus a
// latency with Gaussian jitter, clipped at zero) and becomes readable only once it is released
// at or after that timestamp.

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>

#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/gpio/data_ready_line.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"

namespace imucal::fake {

/// Thread-safe: raise() and release() come from the emulator's side, wait() from the
/// acquisition.
class RealtimeDataReadyLine final : public drivers::DataReadyLine {
 public:
  [[nodiscard]] static Result<std::unique_ptr<RealtimeDataReadyLine>> create(DataReadyTiming timing);
  ~RealtimeDataReadyLine() override;
  RealtimeDataReadyLine(const RealtimeDataReadyLine&) = delete;
  RealtimeDataReadyLine& operator=(const RealtimeDataReadyLine&) = delete;

  /// The chip raised INT at `true_t_ns` (CLOCK_MONOTONIC): an edge is scheduled at its
  /// timestamp (true time plus latency, strictly increasing).
  void raise(TimeNs true_t_ns);
  /// Makes the scheduled edges with timestamps up to `now_ns` readable. Returns the timestamp
  /// of the next scheduled edge, or SimTimeSource::kNever.
  TimeNs release(TimeNs now_ns);
  /// Called by wait() before it looks for edges, to bring the chip up to the present. A kernel
  /// timestamps every edge when it happens, however late the reader is; the ticker thread that
  /// plays the chip can be descheduled, so a reader catches the chip up itself.
  void set_catch_up(std::function<void()> catch_up) { catch_up_ = std::move(catch_up); }

  [[nodiscard]] Result<std::optional<drivers::DataReadyEdge>> wait(TimeNs timeout_ns) override;
  int fd() const override { return fd_; }
  std::string name() const override { return "sim-data-ready-rt"; }

  std::uint64_t raised() const;

 private:
  RealtimeDataReadyLine(int fd, DataReadyTiming timing);

  int fd_ = -1;
  DataReadyTiming timing_;
  mutable std::mutex mutex_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::deque<drivers::DataReadyEdge> scheduled_;  // not yet readable
  std::deque<drivers::DataReadyEdge> ready_;      // readable, counted in the eventfd
  std::function<void()> catch_up_;
  TimeNs last_edge_t_ns_ = 0;
  std::uint64_t sequence_ = 0;
};

}  // namespace imucal::fake
