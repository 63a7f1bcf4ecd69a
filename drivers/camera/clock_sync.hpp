// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Mapping a device's own clock onto the host's CLOCK_MONOTONIC.
//
// A GenICam camera stamps its frames on its own oscillator (nanoseconds since it powered up, or
// wall-clock time for Aravis's fake camera). The host sees each frame some time later: the
// receive time is the true time plus a latency that is never negative (exposure readout,
// transfer, interrupt, scheduling) and varies from frame to frame. Fitting host ~ device by least
// squares would put the line in the middle of that latency, with its jitter; the line we want
// lies under every pair: host = device + offset + drift * (device - t0), the lower envelope.
//
// Method: the pairs of a sliding window (by count and by device-time span) are taken as points
// (device time, host - device). The window is cut into 4 equal stretches of device time and
// the lowest point of each is kept: these sample the lower envelope along the whole window.
// The drift is the least-squares slope through them; the offset then puts the line under every
// point, through the lowest one. Late pairs never pull the line up, one quick pair per stretch
// is enough to pin it, and unlike the exact lower convex hull (whose edge can join two nearby
// points and tilt) the slope always rests on the whole window. While the window spans too
// little device time for a slope to mean anything, the drift is held (at its last fitted value,
// 0 at first) and only the offset follows the lowest delay.
//
// What the mapping cannot see: the smallest latency in the window. Mapped times are the device
// stamps moved to the host clock, late by the path's minimum latency (for GigE Vision typically
// tens of microseconds on a direct link); the offset is estimated from the pairs, not measured.
//
// Device clock resets (power cycle, a timestamp latch reset, a wall-clock step for the fake
// camera) are detected and the fit restarts from the new pairs: a device time that goes
// backwards, a pair that lies clearly below the line (no latency explains it), or several pairs
// in a row clearly above it (a backward jump smaller than the frame interval). "Clearly" scales
// with the latency jitter seen (ClockSyncOptions); a jump smaller than that is not told apart
// from latency, and the window absorbs it as it slides.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <vector>

#include "core/time.hpp"

namespace imucal::drivers::camera {

struct ClockSyncOptions {
  std::size_t window_pairs = 512;                   // pairs kept at most
  TimeNs window_span_ns = 60 * kNsPerSecond;        // device-time span kept at most
  std::size_t min_pairs_for_drift = 16;             // fewer pairs: the drift is held, not fitted
  TimeNs min_span_for_drift_ns = 2 * kNsPerSecond;  // shorter window: the drift is held
  double max_drift_ppm = 1000.0;  // a fitted drift beyond this is not believed (held instead)
  std::size_t envelope_bins = 4;  // stretches of the window whose lowest delays give the drift
  // Clock jumps. A pair below the line by more than the largest of jump_ahead_ns, the largest
  // delay in the window and the threshold below is a forward jump (latency cannot be negative;
  // the first pairs' delays bound how far a quick frame may lower the line). A run of
  // jump_confirm_pairs pairs above the line by more than the larger of jump_threshold_ns and
  // jump_median_factor times the window's median delay is a backward jump (a single late frame
  // is latency).
  TimeNs jump_ahead_ns = 20'000'000;
  TimeNs jump_threshold_ns = 2'000'000;
  double jump_median_factor = 4.0;
  std::size_t jump_confirm_pairs = 8;
};

/// The fit's state, for logs and status.
struct ClockSyncState {
  bool valid = false;             // at least one pair was added since the last restart
  TimeNs offset_ns = 0;           // host - device at the newest pair's device time
  double drift_ppm = 0.0;         // how much faster the device clock runs than the host's
  bool drift_fitted = false;      // false while the window is too short (drift held)
  std::size_t samples = 0;        // pairs in the window
  TimeNs span_ns = 0;             // device-time span of the window
  TimeNs residual_median_ns = 0;  // receive delays above the envelope: median ...
  TimeNs residual_max_ns = 0;     // ... and largest (the latency jitter the fit sees)
  std::uint64_t resets = 0;       // device clock resets detected since construction
};

class ClockSync {
 public:
  explicit ClockSync(ClockSyncOptions options = {}) : options_(options) {}

  /// Adds one pair: a device timestamp and the host's CLOCK_MONOTONIC time when the frame
  /// arrived. Returns true when the pair revealed a device clock reset (the fit restarted).
  bool add(TimeNs device_ns, TimeNs host_ns);
  /// The host time of a device timestamp (the device time itself before any pair).
  TimeNs to_host(TimeNs device_ns) const;
  ClockSyncState state() const;
  /// Forgets every pair (a new stream); the reset count is kept.
  void clear();

 private:
  struct Pair {
    TimeNs device_ns;
    TimeNs host_ns;
  };
  // host - device of a pair relative to the reference pair, in ns.
  double delay(const Pair& p) const;
  double residual(TimeNs device_ns, TimeNs host_ns) const;
  bool is_jump(TimeNs device_ns, TimeNs host_ns);
  void restart(std::vector<Pair> pairs);
  void trim();
  void refit();
  void fit_held_drift();
  void update_median_delay();

  ClockSyncOptions options_;
  std::deque<Pair> window_;
  std::vector<Pair> late_;  // consecutive pairs above the line by more than the jump threshold
  Pair ref_{0, 0};          // reference pair: the line is relative to it
  double a_ns_ = 0.0;       // line: delay(device) = a + b * (device - ref.device)
  double b_ = 0.0;
  double held_b_ = 0.0;           // the last believed slope
  double median_delay_ns_ = 0.0;  // median of the window's delays above the line
  double max_delay_ns_ = 0.0;     // and the largest
  bool drift_fitted_ = false;
  std::uint64_t resets_ = 0;
};

}  // namespace imucal::drivers::camera
