// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/gpio/fake/sim_data_ready.hpp"

#include <algorithm>
#include <cmath>

namespace imucal::fake {

SimDataReadyLine::SimDataReadyLine(SimTimeSource& time, DataReadyTiming timing)
    : time_(time), timing_(timing), rng_(timing.seed) {}

void SimDataReadyLine::raise(TimeNs true_t_ns) {
  ++raised_;
  ++sequence_;
  const double jitter = timing_.sigma_ns > 0 ? normal_(rng_) * static_cast<double>(timing_.sigma_ns) : 0.0;
  TimeNs latency = timing_.latency_ns + static_cast<TimeNs>(std::llround(jitter));
  latency = std::max<TimeNs>(latency, 0);
  TimeNs t_ns = true_t_ns + latency;
  // The kernel timestamps events in the order it services them.
  if (t_ns <= last_edge_t_ns_) t_ns = last_edge_t_ns_ + 1;
  last_edge_t_ns_ = t_ns;
  if (latencies_ns_.size() < kMaxLatencies) latencies_ns_.push_back(t_ns - true_t_ns);
  if (drop_remaining_ > 0) {
    --drop_remaining_;
    ++dropped_;
    return;
  }
  pending_.push_back({t_ns, sequence_});
}

Result<std::optional<drivers::DataReadyEdge>> SimDataReadyLine::wait(TimeNs timeout_ns) {
  if (timeout_ns < 0) return make_error(Errc::kInvalidArgument, "data-ready wait: negative timeout");
  const TimeNs deadline = time_.now_ns() + timeout_ns;
  for (;;) {
    if (!pending_.empty()) {
      const drivers::DataReadyEdge edge = pending_.front();
      if (edge.t_ns <= deadline) {
        pending_.pop_front();
        if (time_.now_ns() < edge.t_ns) time_.advance_to(edge.t_ns);
        return std::optional<drivers::DataReadyEdge>(edge);
      }
      time_.advance_to(deadline);
      return std::optional<drivers::DataReadyEdge>();
    }
    const TimeNs next = time_.next_event_ns();
    if (next > deadline) {
      time_.advance_to(deadline);
      if (pending_.empty()) return std::optional<drivers::DataReadyEdge>();
      continue;
    }
    time_.advance_to(std::max(next, time_.now_ns()));
    if (pending_.empty() && time_.next_event_ns() == next) {
      // Nothing happened at the announced event (e.g. the interrupt is disabled); step on.
      time_.advance_to(std::min(deadline, next + 1));
    }
  }
}

}  // namespace imucal::fake
