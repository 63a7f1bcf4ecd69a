// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Per-sample time reconstruction for a FIFO-buffered IMU woken by a data-ready interrupt, in the
// manner of the Linux inv_mpu6050 IIO driver: the kernel timestamps each data-ready edge (with
// latency jitter), the host then reads k samples from the FIFO, and the chip's true sample
// period differs from nominal (internal oscillator off by up to several percent, drifting
// slowly with temperature).
//
// Model. Sample n of the chip is taken at t(n) = phi + (n - n_ref) * P, where P is the true
// period. An accepted edge that belongs to sample m is a measurement z = t(m) + latency + noise.
// A two-state Kalman filter over (phi, P) tracks phase and period: the period follows a random
// walk (the oscillator drift), the measurement noise is the edge jitter. Edges whose innovation
// is outside a gate, or whose interval to the previous accepted edge implies a period outside
// the bounded window around nominal, are rejected (late interrupts) and counted. Samples get
// t(n) from the updated state, so times are smooth (corrections are a small fraction of the
// jitter) and are then forced strictly increasing.
//
// Which sample an edge belongs to: the newest sample in the FIFO when it was read, unless the
// line's edge sequence says that more samples arrived between the edge and the FIFO read (then
// newest_index - edge_index = cumulative samples minus cumulative edges, normalised by its
// running minimum over recent batches, see docs/acquisition.md). The newest sample in the FIFO
// is the batch's last one plus FifoBatchTiming::samples_left: a reader that keeps frames back
// in the FIFO (the MPU-6000 driver keeps the newest) delivers them with the next batch.
//
// Without an edge (no data-ready line, or a wait that timed out) the read time stands in for
// it: the newest sample in the FIFO was taken on average half a period before the read, with a
// uniform spread of one period; without either the times are extrapolated
// (kImuFlagTimeEstimated).
//
// Gaps. A batch flagged FIFO reset / overflow / device reset, or a run of consecutive rejected
// edges (samples lost silently), re-anchors the phase on the new edge; the first sample after
// the gap gets kImuFlagGapBefore (and kImuFlagDeviceReset after a reset). The number of lost
// samples is estimated from the edge sequence when the line provides one, else from time.

#include <cstdint>
#include <deque>
#include <span>

#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::acq {

/// Timing of one FIFO read: the data-ready edge that triggered it, how many samples the read
/// returned and how many newer ones it left in the FIFO. The MPU-6000 driver's FIFO batch
/// converts to this one-to-one.
struct FifoBatchTiming {
  bool has_edge = true;             // false: read without a data-ready edge (polling, timeout)
  TimeNs edge_t_ns = 0;             // kernel timestamp of the data-ready edge (CLOCK_MONOTONIC)
  TimeNs read_t_ns = 0;             // host time just before the FIFO count was read (0: unknown)
  std::uint64_t edge_sequence = 0;  // the line's edge counter (see has_edge_sequence)
  bool has_edge_sequence = false;   // false: the line does not count edges reliably
  std::uint32_t sample_count = 0;   // samples read from the FIFO in this batch
  bool fifo_reset = false;          // the FIFO was reset before this batch (samples lost)
  bool fifo_overflow = false;       // the FIFO overflowed before this batch (samples lost)
  bool device_reset = false;        // the device was reset and reconfigured before this batch
  /// Samples newer than the batch's last that were in the FIFO when its count was read and were
  /// not read (kept back for the next read, or dropped with the FIFO). The edge and the read
  /// time refer to the newest of them; the batch's last sample is this many periods older.
  std::uint32_t samples_left = 0;
};

struct TimestamperOptions {
  double nominal_rate_hz = 1000.0;
  /// Mean latency from the sample instant to the kernel's edge timestamp; subtracted, so
  /// sample times refer to the chip's sampling instant (a platform constant; any error in it is
  /// a constant offset that the camera-IMU time offset absorbs).
  TimeNs edge_latency_ns = 0;
  /// Standard deviation of the edge timestamp jitter.
  TimeNs edge_jitter_ns = 30'000;
  /// Largest accepted deviation of the chip's period from nominal (fraction): the MPU-6000's
  /// internal oscillator is specified to a few percent over temperature.
  double max_period_error = 0.08;
  /// Oscillator drift: standard deviation of the relative period change over one second,
  /// in ppm (random-walk model). Larger tracks faster drift, smaller averages more jitter.
  double period_drift_ppm_per_sqrt_s = 20.0;
  /// Innovation gate in standard deviations of the predicted edge time.
  double gate_sigma = 5.0;
  /// This many consecutive rejected edges mean the sample count and time disagree for good
  /// (samples lost without a flag): re-anchor and flag a gap.
  int max_consecutive_rejects = 4;
  /// Batches over which the edge-to-sample association is normalised (see above).
  int association_window = 64;

  /// Checks ranges; the message names the field and what is accepted.
  [[nodiscard]] Status validate() const;
};

/// Counters for status output and tests.
struct TimestamperStats {
  std::uint64_t batches = 0;
  std::uint64_t samples = 0;
  std::uint64_t edges_accepted = 0;
  std::uint64_t edges_rejected = 0;    // outside the gate or the period window
  std::uint64_t gaps = 0;              // gaps flagged (reset, overflow, re-anchor)
  std::uint64_t resets = 0;            // batches with fifo_reset or device_reset
  std::uint64_t overflows = 0;         // batches with fifo_overflow
  std::uint64_t reanchors = 0;         // re-anchors after consecutive rejects
  std::uint64_t samples_lost = 0;      // estimated samples missing in gaps
  std::uint64_t monotonic_clamps = 0;  // times moved forward to stay strictly increasing
};

class SampleTimestamper {
 public:
  explicit SampleTimestamper(const TimestamperOptions& options);

  /// Assigns a time to every sample of one batch, oldest first. `t_ns` and `flags` must have
  /// batch.sample_count elements; flags are OR-ed into `flags` (kImuFlagGapBefore,
  /// kImuFlagDeviceReset, kImuFlagTimeEstimated). Fails only on a size mismatch.
  [[nodiscard]] Status process(const FifoBatchTiming& batch, std::span<TimeNs> t_ns,
                               std::span<std::uint32_t> flags);

  /// Current estimate of the chip's sample period (nominal until the first edges).
  double period_ns() const { return period_ns_; }
  /// Estimated relative deviation of the chip's rate from nominal, in ppm (+ = slower chip).
  double period_error_ppm() const { return (period_ns_ / nominal_period_ns_ - 1.0) * 1e6; }
  const TimestamperStats& stats() const { return stats_; }
  const TimestamperOptions& options() const { return options_; }

 private:
  /// What a batch offers to measure time with: its data-ready edge, else its read time.
  struct Measurement {
    bool present = false;       // an edge or a read time
    TimeNs z_abs = 0;           // time of the newest sample in the FIFO (latency removed)
    double var = 0.0;           // variance of z_abs, ns^2
    bool use_sequence = false;  // the line's edge counter can place the edge among the samples
  };
  /// Where one batch's samples fall in the chip's sample sequence.
  struct Placement {
    std::int64_t left = 0;         // samples newer than the batch left in the FIFO
    std::int64_t first_index = 0;  // the batch's first sample
    std::int64_t newest = 0;       // the batch's last sample
    std::int64_t edge_index = 0;   // the sample the measurement belongs to
    bool gap = false;              // samples were lost before the batch
    bool estimated = false;        // times extrapolated, not measured
    bool anchored = false;         // the measurement already re-anchored the state
    bool by_sequence = false;      // the edge's sample is known from the line's edge numbers
  };

  Measurement measure(const FifoBatchTiming& batch) const;
  // The steps of process(), after the helpers of the kernel's inv_sensors_timestamp.c: the
  // first batch anchors the filter; later ones are aligned with the sample sequence (lost
  // samples counted, the edge associated with its sample), then the edge updates phase and
  // period if it passes the gate and the period window; finally every sample gets its time.
  void start(const FifoBatchTiming& batch, const Measurement& m, std::int64_t k, Placement& p);
  void align(const FifoBatchTiming& batch, const Measurement& m, bool lossy, std::int64_t k, Placement& p);
  void count_lost_samples(const FifoBatchTiming& batch, const Measurement& m, double z, Placement& p);
  std::int64_t associate_edge(std::uint64_t sequence, std::int64_t k, const Placement& p);
  void update_with_edge(double z, double r_var, Placement& p);
  bool period_in_window(double z, std::int64_t edge_index, double r_var) const;
  void correct(double nu, double s);
  void resync_after_rejects(double z, double nu, double s, double r_var, Placement& p);
  void assign_times(const Placement& p, std::span<TimeNs> t_ns, std::span<std::uint32_t> flags);

  /// Restarts the phase at `edge_index`; the period keeps its estimate, and its variance unless
  /// `forget_period` (or before the first anchor) sets it back to the prior.
  void anchor(double z_rel, std::int64_t edge_index, double var, bool forget_period = false);
  void predict_to(std::int64_t index);
  void rebase();
  double time_of(std::int64_t index) const {
    return phi_ns_ + static_cast<double>(index - n_ref_) * period_ns_;
  }

  TimestamperOptions options_;
  double nominal_period_ns_;
  double jitter_var_;  // R, ns^2
  double period_q_;    // period random-walk variance per sample, ns^2
  double period_min_ns_;
  double period_max_ns_;

  bool initialized_ = false;
  TimeNs base_ns_ = 0;   // filter times are relative to this
  double phi_ns_ = 0.0;  // time of sample n_ref_, relative to base_ns_
  double period_ns_ = 0.0;
  double c_pp_ = 0.0, c_pt_ = 0.0, c_tt_ = 0.0;  // covariance: phase, phase-period, period
  std::int64_t n_ref_ = 0;                       // sample index the state refers to
  std::int64_t newest_ = -1;                     // index of the newest sample delivered
  TimeNs last_out_ns_ = 0;
  bool have_out_ = false;
  bool pending_reset_ = false;
  bool pending_loss_ = false;

  // Last accepted edge, for the bounded period window.
  bool have_accepted_ = false;
  double last_accepted_z_ = 0.0;
  std::int64_t last_accepted_index_ = 0;
  int consecutive_rejects_ = 0;
  double last_rejected_nu_ = 0.0;  // the innovation of the last rejected edge

  // Edge-to-sample association: newest_index - edge_sequence per batch.
  bool have_sequence_ = false;
  std::uint64_t last_sequence_ = 0;
  std::deque<std::int64_t> assoc_history_;

  TimestamperStats stats_;
};

}  // namespace imucal::acq
