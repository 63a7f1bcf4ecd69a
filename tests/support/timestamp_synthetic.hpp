// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A synthetic data-ready / FIFO timing generator with ground truth, for testing and measuring
// the timestamper (tests/acquisition/test_timestamp.cpp, tests/bench/bench_acquisition.cpp).
//
// Chip: sample n is taken at t(n); the period is nominal * (1 + (offset + drift(t)) * 1e-6),
// drift(t) = drift_ppm_per_s * t + wander_ppm * sin(2 pi t / wander_period_s).
// Line: every sample raises an edge stamped t(n) + latency, latency ~ N(mean, sigma) (clipped
// at 0), plus rare late-interrupt spikes. Host: waits for the edge of the N-th new sample
// (missing it with some probability and waking at the next one), reads the FIFO shortly after
// the edge (sometimes late, so the read returns a burst), and resets the FIFO when it would
// have overflowed (the next batch is flagged). Deterministic under a seed.

#include <cstdint>
#include <vector>

#include "acquisition/timestamp.hpp"
#include "core/time.hpp"

namespace imucal::acq {

struct SyntheticTimingOptions {
  std::uint64_t seed = 1;
  double duration_s = 20.0;
  double nominal_rate_hz = 1000.0;
  double rate_offset_ppm = 20'000.0;  // the chip's period is this much longer than nominal
  double drift_ppm_per_s = 20.0;
  double wander_ppm = 200.0;
  double wander_period_s = 30.0;
  TimeNs latency_mean_ns = 100'000;
  TimeNs latency_sigma_ns = 30'000;
  double spike_probability = 0.0;  // an edge stamped late by spike_ns
  TimeNs spike_ns = 1'000'000;
  int samples_per_read = 1;       // the host reads the FIFO every N samples
  TimeNs read_delay_ns = 20'000;  // edge timestamp to FIFO read
  double missed_edge_probability = 0.0;
  double late_read_probability = 0.0;  // the read happens late_read_ns late (a burst)
  TimeNs late_read_ns = 3'000'000;
  int fifo_capacity_samples = 73;  // 1024-byte FIFO, 14-byte accel+temp+gyro records
  /// Host stalls: at these times (s) the host stops reading for stall_ns (FIFO overflows).
  std::vector<double> stall_at_s;
  TimeNs stall_ns = 50'000'000;
  bool edge_sequence = true;  // the line counts edges
  TimeNs start_ns = 5 * kNsPerSecond;
};

struct SyntheticBatch {
  FifoBatchTiming timing;
  std::vector<TimeNs> true_t_ns;  // true sample instants of the batch's samples
};

struct SyntheticTiming {
  std::vector<SyntheticBatch> batches;
  std::uint64_t samples_lost = 0;  // samples discarded by FIFO resets
};

[[nodiscard]] SyntheticTiming generate_synthetic_timing(const SyntheticTimingOptions& options);

/// Errors of reconstructed times against the truth.
struct TimingErrorSummary {
  double rms_ns = 0.0;           // over samples from settle_s on
  double max_abs_ns = 0.0;       // over samples from settle_s on
  double rms_all_ns = 0.0;       // over every sample
  double rms_anchored_ns = 0.0;  // from settle_s on, without samples flagged kImuFlagTimeEstimated
  double interval_rms_ns = 0.0;  // RMS error of consecutive-sample intervals (smoothness)
  std::size_t samples = 0;
  bool strictly_increasing = true;
  std::uint32_t gap_flags = 0;  // samples carrying kImuFlagGapBefore
};

/// Runs a timestamper over the generated batches and compares with the truth, ignoring the
/// first settle_s seconds for rms_ns/max_abs_ns. Also returns the flags per sample.
[[nodiscard]] TimingErrorSummary evaluate_timestamper(SampleTimestamper& timestamper,
                                                      const SyntheticTiming& timing, double settle_s,
                                                      std::vector<std::uint32_t>* flags_out = nullptr);

}  // namespace imucal::acq
