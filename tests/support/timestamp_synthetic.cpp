// SPDX-License-Identifier: BSD-3-Clause
#include "tests/support/timestamp_synthetic.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "core/imu.hpp"

namespace imucal::acq {

SyntheticTiming generate_synthetic_timing(const SyntheticTimingOptions& o) {
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.0, 1.0);

  // True sample instants and edge stamps.
  const double nominal_ns = 1e9 / o.nominal_rate_hz;
  std::vector<TimeNs> t;
  std::vector<TimeNs> edge;
  const auto n_est = static_cast<std::size_t>(o.duration_s * o.nominal_rate_hz * 1.1) + 16;
  t.reserve(n_est);
  edge.reserve(n_est);
  double t_rel_ns = 0.0;
  const double end_ns = o.duration_s * 1e9;
  while (t_rel_ns < end_ns) {
    const TimeNs ti = o.start_ns + static_cast<TimeNs>(std::llround(t_rel_ns));
    double lat =
        static_cast<double>(o.latency_mean_ns) + static_cast<double>(o.latency_sigma_ns) * gauss(rng);
    lat = std::max(0.0, lat);
    if (o.spike_probability > 0.0 && uni(rng) < o.spike_probability) lat += static_cast<double>(o.spike_ns);
    t.push_back(ti);
    edge.push_back(ti + static_cast<TimeNs>(std::llround(lat)));
    const double ts = t_rel_ns * 1e-9;
    const double ppm = o.rate_offset_ppm + o.drift_ppm_per_s * ts +
                       o.wander_ppm * std::sin(2.0 * std::numbers::pi * ts / o.wander_period_s);
    t_rel_ns += nominal_ns * (1.0 + ppm * 1e-6);
  }

  SyntheticTiming out;
  const auto n = static_cast<std::int64_t>(t.size());
  std::int64_t last_read = -1;  // newest sample index already read (or discarded)
  std::int64_t wake = o.samples_per_read - 1;
  std::size_t next_stall = 0;
  bool pending_reset = false;
  std::vector<double> stalls = o.stall_at_s;
  std::sort(stalls.begin(), stalls.end());
  while (wake < n) {
    if (o.missed_edge_probability > 0.0 && uni(rng) < o.missed_edge_probability) {
      ++wake;  // the host sleeps through this edge and wakes at the next
      continue;
    }
    TimeNs r = edge[static_cast<std::size_t>(wake)] + o.read_delay_ns;
    if (o.late_read_probability > 0.0 && uni(rng) < o.late_read_probability) r += o.late_read_ns;
    if (next_stall < stalls.size() && r >= o.start_ns + s_to_ns(stalls[next_stall])) {
      r += o.stall_ns;
      ++next_stall;
    }
    // Samples in the FIFO at the read.
    std::int64_t newest = wake;
    while (newest + 1 < n && t[static_cast<std::size_t>(newest + 1)] <= r) ++newest;
    if (newest - last_read > o.fifo_capacity_samples) {
      // Overflow: the driver resets the FIFO and reports an empty, flagged batch.
      SyntheticBatch b;
      b.timing.edge_t_ns = edge[static_cast<std::size_t>(wake)];
      b.timing.edge_sequence = static_cast<std::uint64_t>(wake) + 1000;
      b.timing.has_edge_sequence = o.edge_sequence;
      b.timing.sample_count = 0;
      b.timing.fifo_overflow = true;
      b.timing.fifo_reset = true;
      out.batches.push_back(std::move(b));
      out.samples_lost += static_cast<std::uint64_t>(newest - last_read);
      last_read = newest;
      wake = newest + o.samples_per_read;
      pending_reset = true;
      continue;
    }
    SyntheticBatch b;
    b.timing.edge_t_ns = edge[static_cast<std::size_t>(wake)];
    b.timing.edge_sequence = static_cast<std::uint64_t>(wake) + 1000;
    b.timing.has_edge_sequence = o.edge_sequence;
    b.timing.sample_count = static_cast<std::uint32_t>(newest - last_read);
    b.timing.fifo_reset = pending_reset;
    pending_reset = false;
    for (std::int64_t i = last_read + 1; i <= newest; ++i)
      b.true_t_ns.push_back(t[static_cast<std::size_t>(i)]);
    out.batches.push_back(std::move(b));
    last_read = newest;
    wake = newest + o.samples_per_read;
  }
  return out;
}

TimingErrorSummary evaluate_timestamper(SampleTimestamper& timestamper, const SyntheticTiming& timing,
                                        double settle_s, std::vector<std::uint32_t>* flags_out) {
  TimingErrorSummary s;
  std::vector<TimeNs> est;
  std::vector<std::uint32_t> flags;
  double sum2 = 0.0, sum2_all = 0.0, sum2_dt = 0.0, sum2_anchored = 0.0;
  std::size_t n_settled = 0, n_all = 0, n_dt = 0, n_anchored = 0;
  TimeNs t0 = -1;
  TimeNs prev_est = 0, prev_true = 0;
  bool have_prev = false;
  if (flags_out) flags_out->clear();
  for (const auto& b : timing.batches) {
    est.assign(b.timing.sample_count, 0);
    flags.assign(b.timing.sample_count, 0);
    if (!timestamper.process(b.timing, est, flags).ok()) {
      s.strictly_increasing = false;
      return s;
    }
    for (std::size_t i = 0; i < est.size(); ++i) {
      const TimeNs truth = b.true_t_ns[i];
      if (t0 < 0) t0 = truth;
      const double e = static_cast<double>(est[i] - truth);
      sum2_all += e * e;
      ++n_all;
      if (static_cast<double>(truth - t0) >= settle_s * 1e9) {
        sum2 += e * e;
        ++n_settled;
        s.max_abs_ns = std::max(s.max_abs_ns, std::abs(e));
        if ((flags[i] & kImuFlagTimeEstimated) == 0) {
          sum2_anchored += e * e;
          ++n_anchored;
        }
      }
      if (have_prev) {
        if (est[i] <= prev_est) s.strictly_increasing = false;
        if ((flags[i] & kImuFlagGapBefore) == 0) {
          const double de = static_cast<double>((est[i] - prev_est) - (truth - prev_true));
          sum2_dt += de * de;
          ++n_dt;
        }
      }
      if (flags[i] & kImuFlagGapBefore) ++s.gap_flags;
      prev_est = est[i];
      prev_true = truth;
      have_prev = true;
      if (flags_out) flags_out->push_back(flags[i]);
    }
  }
  s.samples = n_all;
  if (n_settled > 0) s.rms_ns = std::sqrt(sum2 / static_cast<double>(n_settled));
  if (n_anchored > 0) s.rms_anchored_ns = std::sqrt(sum2_anchored / static_cast<double>(n_anchored));
  if (n_all > 0) s.rms_all_ns = std::sqrt(sum2_all / static_cast<double>(n_all));
  if (n_dt > 0) s.interval_rms_ns = std::sqrt(sum2_dt / static_cast<double>(n_dt));
  return s;
}

}  // namespace imucal::acq
