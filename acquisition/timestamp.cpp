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

void SampleTimestamper::anchor(double z_rel, std::int64_t edge_index, double var) {
  phi_ns_ = z_rel;
  n_ref_ = edge_index;
  c_pp_ = var;
  c_pt_ = 0.0;
  if (!initialized_) {
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
  // Samples newer than the batch that were in the FIFO at the read: the edge and the read time
  // refer to the newest of them, not to the batch's last sample.
  const auto left = static_cast<std::int64_t>(batch.samples_left);
  // The measurement: the edge, else the read time, else none.
  const bool has_measurement = batch.has_edge || batch.read_t_ns != 0;
  TimeNs z_abs = batch.edge_t_ns - options_.edge_latency_ns;
  double r_var = jitter_var_;
  if (!batch.has_edge) {
    z_abs = batch.read_t_ns - static_cast<TimeNs>(std::llround(0.5 * period_ns_));
    r_var = jitter_var_ + period_ns_ * period_ns_ / 12.0;
  }
  const bool use_sequence = batch.has_edge && batch.has_edge_sequence;

  bool gap = false;
  bool estimated = false;
  std::int64_t first_index = 0;

  if (!initialized_) {
    if (!has_measurement) {
      // Nothing to anchor on yet: nominal spacing after the last output is all there is.
      base_ns_ = have_out_ ? last_out_ns_ + ki * static_cast<TimeNs>(period_ns_) : 0;
      estimated = true;
    } else {
      base_ns_ = z_abs;
    }
    newest_ = ki - 1;
    if (has_measurement) {
      anchor(0.0, newest_ + left, r_var);
    } else {
      anchor(0.0, newest_, 1e12);  // base_ns_ is the newest delivered sample's time
      have_accepted_ = false;
    }
    initialized_ = has_measurement;
    first_index = 0;
    if (has_measurement) ++stats_.edges_accepted;
    if (use_sequence)
      assoc_history_.push_back(newest_ + left - static_cast<std::int64_t>(batch.edge_sequence));
  } else {
    const double z = static_cast<double>(z_abs - base_ns_);
    first_index = newest_ + 1;
    std::int64_t new_newest = newest_ + ki;
    std::int64_t edge_index = new_newest + left;  // the newest sample in the FIFO at the read
    bool anchored = false;

    if (lossy) {
      // Samples were lost. Count them from the edge sequence when it is available and
      // consistent with time, else from time; the newest sample in the FIFO is taken to be the
      // edge's.
      gap = true;
      std::int64_t lost = -1;
      if (use_sequence && !assoc_history_.empty()) {
        const std::int64_t cmin = *std::min_element(assoc_history_.begin(), assoc_history_.end());
        const std::int64_t seq_edge_index = static_cast<std::int64_t>(batch.edge_sequence) + cmin;
        const std::int64_t seq_lost = seq_edge_index - edge_index;
        const double dt = z - time_of(seq_edge_index);
        if (seq_lost >= 0 &&
            std::abs(dt) < 0.5 * period_ns_ + options_.gate_sigma * options_.edge_jitter_ns) {
          lost = seq_lost;
        }
      }
      const bool from_sequence = lost >= 0;
      bool ambiguous = false;
      if (!from_sequence) {
        lost = 0;
        if (has_measurement && edge_index > n_ref_) {
          predict_to(edge_index);
          lost = std::max<std::int64_t>(0, std::llround((z - phi_ns_) / period_ns_));
          // The count is trustworthy only while the prediction is much better than a period.
          ambiguous = std::sqrt(c_pp_ + r_var) > 0.25 * period_ns_;
        }
      }
      stats_.samples_lost += static_cast<std::uint64_t>(lost);
      first_index += lost;
      new_newest += lost;
      edge_index = new_newest + left;
      assoc_history_.clear();
      if (ambiguous) {
        predict_to(edge_index);
        anchor(z, edge_index, r_var);
        anchored = true;
        ++stats_.edges_accepted;
      }
    } else if (use_sequence) {
      if (have_sequence_ && batch.edge_sequence <= last_sequence_) {
        // The line's counter went backwards or stalled: it cannot be trusted for association.
        assoc_history_.clear();
      }
      assoc_history_.push_back(new_newest + left - static_cast<std::int64_t>(batch.edge_sequence));
      while (static_cast<int>(assoc_history_.size()) > options_.association_window)
        assoc_history_.pop_front();
      const std::int64_t cmin = *std::min_element(assoc_history_.begin(), assoc_history_.end());
      const std::int64_t lead = std::clamp<std::int64_t>(assoc_history_.back() - cmin, 0, ki + left - 1);
      edge_index = new_newest + left - lead;
    }

    if (!anchored && !has_measurement) {
      predict_to(edge_index);
      estimated = true;
    } else if (!anchored) {
      if (edge_index <= n_ref_) {
        // Cannot happen with consistent counters; treat like a rejected edge.
        estimated = true;
        ++stats_.edges_rejected;
      } else {
        predict_to(edge_index);
        const double nu = z - phi_ns_;
        const double s = c_pp_ + r_var;
        bool accept = std::abs(nu) <= options_.gate_sigma * std::sqrt(s);
        if (accept && have_accepted_ && edge_index > last_accepted_index_) {
          // Bounded window around nominal for the period implied by the edge interval.
          const double di = static_cast<double>(edge_index - last_accepted_index_);
          const double implied = (z - last_accepted_z_) / di;
          const double tol = options_.gate_sigma * 1.5 * std::sqrt(r_var) / di;
          accept = implied >= period_min_ns_ - tol && implied <= period_max_ns_ + tol;
        }
        if (accept) {
          const double k0 = c_pp_ / s;
          const double k1 = c_pt_ / s;
          phi_ns_ += k0 * nu;
          period_ns_ = std::clamp(period_ns_ + k1 * nu, period_min_ns_, period_max_ns_);
          const double pp = c_pp_, pt = c_pt_;
          c_pp_ = pp - k0 * pp;
          c_pt_ = pt - k0 * pt;
          c_tt_ = c_tt_ - k1 * pt;
          last_accepted_z_ = z;
          last_accepted_index_ = edge_index;
          have_accepted_ = true;
          consecutive_rejects_ = 0;
          ++stats_.edges_accepted;
        } else {
          ++stats_.edges_rejected;
          estimated = true;
          if (++consecutive_rejects_ >= options_.max_consecutive_rejects) {
            // Time and sample count disagree for good: samples were lost without a flag. When
            // the disagreement is a whole number of periods, shift the count and keep the
            // filter; otherwise start again from this edge.
            const std::int64_t lost = std::max<std::int64_t>(0, std::llround(nu / period_ns_));
            const double residual = nu - static_cast<double>(lost) * period_ns_;
            stats_.samples_lost += static_cast<std::uint64_t>(lost);
            first_index += lost;
            new_newest += lost;
            edge_index += lost;
            predict_to(edge_index);
            if (lost > 0 && std::abs(residual) <= options_.gate_sigma * std::sqrt(s)) {
              const double s2 = c_pp_ + r_var;
              const double k0 = c_pp_ / s2, k1 = c_pt_ / s2, nu2 = z - phi_ns_;
              phi_ns_ += k0 * nu2;
              period_ns_ = std::clamp(period_ns_ + k1 * nu2, period_min_ns_, period_max_ns_);
              const double pp = c_pp_, pt = c_pt_;
              c_pp_ = pp - k0 * pp;
              c_pt_ = pt - k0 * pt;
              c_tt_ = c_tt_ - k1 * pt;
              last_accepted_z_ = z;
              last_accepted_index_ = edge_index;
              consecutive_rejects_ = 0;
            } else {
              anchor(z, edge_index, r_var);
            }
            assoc_history_.clear();
            ++stats_.reanchors;
            gap = true;
            estimated = false;
          }
        }
      }
    }
    newest_ = new_newest;
  }

  if (use_sequence) {
    have_sequence_ = true;
    last_sequence_ = batch.edge_sequence;
  }
  if (gap) ++stats_.gaps;

  // Times of the batch's samples from the state; strictly increasing.
  const auto min_step = static_cast<TimeNs>(std::max(1.0, 0.5 * period_min_ns_));
  for (std::size_t i = 0; i < k; ++i) {
    const std::int64_t index = first_index + static_cast<std::int64_t>(i);
    TimeNs t = base_ns_ + static_cast<TimeNs>(std::llround(time_of(index)));
    if (have_out_ && t < last_out_ns_ + min_step) {
      t = last_out_ns_ + min_step;
      ++stats_.monotonic_clamps;
    }
    t_ns[i] = t;
    last_out_ns_ = t;
    have_out_ = true;
    if (estimated) flags[i] |= kImuFlagTimeEstimated;
  }
  if (gap) flags[0] |= kImuFlagGapBefore;
  if (reset) flags[0] |= kImuFlagDeviceReset;
  rebase();
  return {};
}

}  // namespace imucal::acq
