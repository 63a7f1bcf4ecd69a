// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/timestamp.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/imu.hpp"

namespace imucal::acq {

Status TimestamperOptions::validate() const {
  auto bad = [](const std::string& what) {
    return make_error(Errc::kInvalidArgument, "timestamper: " + what);
  };
  if (!(nominal_rate_hz > 0.0 && nominal_rate_hz <= 100'000.0)) {
    return bad("nominal_rate_hz must be in (0, 100000], got " + std::to_string(nominal_rate_hz));
  }
  if (edge_latency_ns < 0) return bad("edge_latency_ns must be >= 0");
  if (edge_jitter_ns <= 0) return bad("edge_jitter_ns must be > 0 (use 1 for an ideal line)");
  if (!(max_period_error > 0.0 && max_period_error < 0.5)) {
    return bad("max_period_error must be in (0, 0.5), got " + std::to_string(max_period_error));
  }
  if (!(period_drift_ppm_per_sqrt_s >= 0.0)) return bad("period_drift_ppm_per_sqrt_s must be >= 0");
  if (!(gate_sigma >= 2.0)) return bad("gate_sigma must be >= 2");
  if (max_consecutive_rejects < 1) return bad("max_consecutive_rejects must be >= 1");
  if (association_window < 1) return bad("association_window must be >= 1");
  return {};
}

SampleTimestamper::SampleTimestamper(const TimestamperOptions& options)
    : options_(options),
      nominal_period_ns_(1e9 / options.nominal_rate_hz),
      jitter_var_(static_cast<double>(options.edge_jitter_ns) * static_cast<double>(options.edge_jitter_ns)),
      period_q_(0.0),
      period_min_ns_(nominal_period_ns_ * (1.0 - options.max_period_error)),
      period_max_ns_(nominal_period_ns_ * (1.0 + options.max_period_error)),
      period_ns_(nominal_period_ns_) {
  const double sd_per_s = options.period_drift_ppm_per_sqrt_s * 1e-6 * nominal_period_ns_;
  period_q_ = sd_per_s * sd_per_s / options.nominal_rate_hz;
}

void SampleTimestamper::anchor(double z_rel, std::int64_t edge_index, double var, bool forget_period) {
  phi_ns_ = z_rel;
  n_ref_ = edge_index;
  c_pp_ = var;
  c_pt_ = 0.0;
  if (!initialized_ || forget_period) {
    // The period's prior: anywhere in the window around nominal. A re-anchor after rejected
    // edges forgets what it knew of the period too: the estimate may be what made the edges
    // disagree (late edges taken in bent it), and with its small variance kept every later
    // edge would be rejected again.
    const double sd = options_.max_period_error * nominal_period_ns_ / 2.0;
    c_tt_ = sd * sd;
  }
  have_accepted_ = true;
  last_accepted_z_ = z_rel;
  last_accepted_index_ = edge_index;
  consecutive_rejects_ = 0;
}

void SampleTimestamper::predict_to(std::int64_t index) {
  const double d = static_cast<double>(index - n_ref_);
  if (d <= 0.0) return;
  phi_ns_ += d * period_ns_;
  const double q = period_q_;
  c_pp_ += 2.0 * d * c_pt_ + d * d * c_tt_ + q * d * d * d / 3.0;
  c_pt_ += d * c_tt_ + q * d * d / 2.0;
  c_tt_ += q * d;
  n_ref_ = index;
}

void SampleTimestamper::rebase() {
  if (std::abs(phi_ns_) < 1e9) return;
  const auto shift = static_cast<TimeNs>(std::llround(phi_ns_));
  base_ns_ += shift;
  phi_ns_ -= static_cast<double>(shift);
  last_accepted_z_ -= static_cast<double>(shift);
}

Status SampleTimestamper::process(const FifoBatchTiming& batch, std::span<TimeNs> t_ns,
                                  std::span<std::uint32_t> flags) {
  const std::size_t k = batch.sample_count;
  if (t_ns.size() != k || flags.size() != k) {
    return make_error(Errc::kInternal, "timestamper: output spans (" + std::to_string(t_ns.size()) + ", " +
                                           std::to_string(flags.size()) + ") do not match the batch's " +
                                           std::to_string(k) + " samples");
  }
  ++stats_.batches;
  if (batch.fifo_reset || batch.device_reset) ++stats_.resets;
  if (batch.fifo_overflow) ++stats_.overflows;
  // A reset or overflow reported with an empty read applies to the next samples.
  pending_reset_ = pending_reset_ || batch.fifo_reset || batch.device_reset;
  pending_loss_ = pending_loss_ || batch.fifo_overflow;
  if (k == 0) return {};  // an edge whose FIFO read found nothing: nothing to time
  stats_.samples += k;

  const bool reset = pending_reset_;
  const bool lossy = pending_reset_ || pending_loss_;
  pending_reset_ = false;
  pending_loss_ = false;
  const auto ki = static_cast<std::int64_t>(k);
  const Measurement m = measure(batch);
  Placement p;
  // Samples newer than the batch that were in the FIFO at the read: the edge and the read time
  // refer to the newest of them, not to the batch's last sample.
  p.left = static_cast<std::int64_t>(batch.samples_left);
  if (!initialized_) {
    start(batch, m, ki, p);
  } else {
    align(batch, m, lossy, ki, p);
  }
  if (m.use_sequence) {
    have_sequence_ = true;
    last_sequence_ = batch.edge_sequence;
  }
  if (p.gap) ++stats_.gaps;
  assign_times(p, t_ns, flags);
  if (p.gap) flags[0] |= kImuFlagGapBefore;
  if (reset) flags[0] |= kImuFlagDeviceReset;
  rebase();
  return {};
}

SampleTimestamper::Measurement SampleTimestamper::measure(const FifoBatchTiming& batch) const {
  Measurement m;
  m.present = batch.has_edge || batch.read_t_ns != 0;
  m.z_abs = batch.edge_t_ns - options_.edge_latency_ns;
  m.var = jitter_var_;
  if (!batch.has_edge) {
    // The newest sample in the FIFO was taken on average half a period before the read, spread
    // uniformly over one period.
    m.z_abs = batch.read_t_ns - static_cast<TimeNs>(std::llround(0.5 * period_ns_));
    m.var = jitter_var_ + period_ns_ * period_ns_ / 12.0;
  }
  m.use_sequence = batch.has_edge && batch.has_edge_sequence;
  return m;
}

void SampleTimestamper::start(const FifoBatchTiming& batch, const Measurement& m, std::int64_t k,
                              Placement& p) {
  if (!m.present) {
    // Nothing to anchor on yet: nominal spacing after the last output is all there is.
    base_ns_ = have_out_ ? last_out_ns_ + k * static_cast<TimeNs>(period_ns_) : 0;
    p.estimated = true;
  } else {
    base_ns_ = m.z_abs;
  }
  newest_ = k - 1;
  if (m.present) {
    anchor(0.0, newest_ + p.left, m.var);
  } else {
    anchor(0.0, newest_, 1e12);  // base_ns_ is the newest delivered sample's time
    have_accepted_ = false;
  }
  initialized_ = m.present;
  p.first_index = 0;
  if (m.present) ++stats_.edges_accepted;
  if (m.use_sequence)
    assoc_history_.push_back(newest_ + p.left - static_cast<std::int64_t>(batch.edge_sequence));
}

void SampleTimestamper::align(const FifoBatchTiming& batch, const Measurement& m, bool lossy, std::int64_t k,
                              Placement& p) {
  const double z = static_cast<double>(m.z_abs - base_ns_);
  p.first_index = newest_ + 1;
  p.newest = newest_ + k;
  p.edge_index = p.newest + p.left;  // the newest sample in the FIFO at the read
  if (lossy) {
    count_lost_samples(batch, m, z, p);
  } else if (m.use_sequence) {
    p.edge_index = associate_edge(batch.edge_sequence, k, p);
    p.by_sequence = true;
  }

  if (p.anchored) {
    // The measurement re-anchored the state while the lost samples were counted.
  } else if (!m.present) {
    predict_to(p.edge_index);
    p.estimated = true;
  } else if (p.edge_index <= n_ref_) {
    // Cannot happen with consistent counters; treat like a rejected edge.
    p.estimated = true;
    ++stats_.edges_rejected;
  } else {
    update_with_edge(z, m.var, p);
  }
  newest_ = p.newest;
}

void SampleTimestamper::count_lost_samples(const FifoBatchTiming& batch, const Measurement& m, double z,
                                           Placement& p) {
  // Samples were lost. Count them from the edge sequence when it is available and consistent
  // with time, else from time; the newest sample in the FIFO is taken to be the edge's.
  p.gap = true;
  std::int64_t lost = -1;
  if (m.use_sequence && !assoc_history_.empty()) {
    const std::int64_t cmin = *std::min_element(assoc_history_.begin(), assoc_history_.end());
    const std::int64_t seq_edge_index = static_cast<std::int64_t>(batch.edge_sequence) + cmin;
    const std::int64_t seq_lost = seq_edge_index - p.edge_index;
    const double dt = z - time_of(seq_edge_index);
    if (seq_lost >= 0 && std::abs(dt) < 0.5 * period_ns_ + options_.gate_sigma * options_.edge_jitter_ns) {
      lost = seq_lost;
    }
  }
  const bool from_sequence = lost >= 0;
  bool ambiguous = false;
  if (!from_sequence) {
    lost = 0;
    if (m.present && p.edge_index > n_ref_) {
      predict_to(p.edge_index);
      lost = std::max<std::int64_t>(0, std::llround((z - phi_ns_) / period_ns_));
      // The count is trustworthy only while the prediction is much better than a period.
      ambiguous = std::sqrt(c_pp_ + m.var) > 0.25 * period_ns_;
    }
  }
  stats_.samples_lost += static_cast<std::uint64_t>(lost);
  p.first_index += lost;
  p.newest += lost;
  p.edge_index = p.newest + p.left;
  assoc_history_.clear();
  if (ambiguous) {
    predict_to(p.edge_index);
    anchor(z, p.edge_index, m.var);
    p.anchored = true;
    ++stats_.edges_accepted;
  }
}

std::int64_t SampleTimestamper::associate_edge(std::uint64_t sequence, std::int64_t k, const Placement& p) {
  if (have_sequence_ && sequence <= last_sequence_) {
    // The line's counter went backwards or stalled: it cannot be trusted for association.
    assoc_history_.clear();
  }
  assoc_history_.push_back(p.newest + p.left - static_cast<std::int64_t>(sequence));
  while (static_cast<int>(assoc_history_.size()) > options_.association_window) assoc_history_.pop_front();
  const std::int64_t cmin = *std::min_element(assoc_history_.begin(), assoc_history_.end());
  const std::int64_t lead = std::clamp<std::int64_t>(assoc_history_.back() - cmin, 0, k + p.left - 1);
  return p.newest + p.left - lead;
}

void SampleTimestamper::update_with_edge(double z, double r_var, Placement& p) {
  predict_to(p.edge_index);
  const double nu = z - phi_ns_;
  const double s = c_pp_ + r_var;
  const bool accept =
      std::abs(nu) <= options_.gate_sigma * std::sqrt(s) && period_in_window(z, p.edge_index, r_var);
  if (accept) {
    correct(nu, s);
    last_accepted_z_ = z;
    last_accepted_index_ = p.edge_index;
    have_accepted_ = true;
    consecutive_rejects_ = 0;
    ++stats_.edges_accepted;
    return;
  }
  ++stats_.edges_rejected;
  p.estimated = true;
  // Edges of known samples stamped late together (an interrupt held off) arrive later than
  // predicted by less and less, a period at a time, until they are on time again: no reason to
  // start again from one of them.
  const bool catching_up =
      p.by_sequence && nu > 0.0 && consecutive_rejects_ > 0 && nu < last_rejected_nu_ - 0.5 * period_ns_;
  last_rejected_nu_ = nu;
  if (catching_up) return;
  if (++consecutive_rejects_ >= options_.max_consecutive_rejects) resync_after_rejects(z, nu, s, r_var, p);
}

bool SampleTimestamper::period_in_window(double z, std::int64_t edge_index, double r_var) const {
  if (!have_accepted_ || edge_index <= last_accepted_index_) return true;
  // Bounded window around nominal for the period implied by the edge interval.
  const double di = static_cast<double>(edge_index - last_accepted_index_);
  const double implied = (z - last_accepted_z_) / di;
  const double tol = options_.gate_sigma * 1.5 * std::sqrt(r_var) / di;
  return implied >= period_min_ns_ - tol && implied <= period_max_ns_ + tol;
}

void SampleTimestamper::correct(double nu, double s) {
  const double k0 = c_pp_ / s;
  const double k1 = c_pt_ / s;
  phi_ns_ += k0 * nu;
  period_ns_ = std::clamp(period_ns_ + k1 * nu, period_min_ns_, period_max_ns_);
  const double pp = c_pp_, pt = c_pt_;
  c_pp_ = pp - k0 * pp;
  c_pt_ = pt - k0 * pt;
  c_tt_ = c_tt_ - k1 * pt;
}

void SampleTimestamper::resync_after_rejects(double z, double nu, double s, double r_var, Placement& p) {
  // Time and sample count disagree for good: samples were lost without a flag. When the
  // disagreement is a whole number of periods, shift the count and keep the filter; otherwise
  // start again from this edge.
  const std::int64_t lost = std::max<std::int64_t>(0, std::llround(nu / period_ns_));
  const double residual = nu - static_cast<double>(lost) * period_ns_;
  stats_.samples_lost += static_cast<std::uint64_t>(lost);
  p.first_index += lost;
  p.newest += lost;
  p.edge_index += lost;
  predict_to(p.edge_index);
  if (lost > 0 && std::abs(residual) <= options_.gate_sigma * std::sqrt(s)) {
    correct(z - phi_ns_, c_pp_ + r_var);
    last_accepted_z_ = z;
    last_accepted_index_ = p.edge_index;
    consecutive_rejects_ = 0;
  } else {
    anchor(z, p.edge_index, r_var, /*forget_period=*/true);
  }
  assoc_history_.clear();
  ++stats_.reanchors;
  p.gap = true;
  p.estimated = false;
}

void SampleTimestamper::assign_times(const Placement& p, std::span<TimeNs> t_ns,
                                     std::span<std::uint32_t> flags) {
  // Times of the batch's samples from the state; strictly increasing.
  const auto min_step = static_cast<TimeNs>(std::max(1.0, 0.5 * period_min_ns_));
  for (std::size_t i = 0; i < t_ns.size(); ++i) {
    const std::int64_t index = p.first_index + static_cast<std::int64_t>(i);
    TimeNs t = base_ns_ + static_cast<TimeNs>(std::llround(time_of(index)));
    if (have_out_ && t < last_out_ns_ + min_step) {
      t = last_out_ns_ + min_step;
      ++stats_.monotonic_clamps;
    }
    t_ns[i] = t;
    last_out_ns_ = t;
    have_out_ = true;
    if (p.estimated) flags[i] |= kImuFlagTimeEstimated;
  }
}

}  // namespace imucal::acq
