// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/camera/clock_sync.hpp"

#include <algorithm>
#include <cmath>

namespace imucal::drivers::camera {

namespace {

struct Point {
  double x;  // device time since the reference pair, ns
  double y;  // delay relative to the reference pair, ns
};

}  // namespace

double ClockSync::delay(const Pair& p) const {
  // Differences first, in integers: device times can be wall-clock nanoseconds (~1.8e18), far
  // beyond a double's exact range.
  return static_cast<double>((p.host_ns - p.device_ns) - (ref_.host_ns - ref_.device_ns));
}

double ClockSync::residual(TimeNs device_ns, TimeNs host_ns) const {
  const double x = static_cast<double>(device_ns - ref_.device_ns);
  return delay({device_ns, host_ns}) - (a_ns_ + b_ * x);
}

TimeNs ClockSync::to_host(TimeNs device_ns) const {
  if (window_.empty()) return device_ns;
  const double x = static_cast<double>(device_ns - ref_.device_ns);
  return device_ns + (ref_.host_ns - ref_.device_ns) + static_cast<TimeNs>(std::llround(a_ns_ + b_ * x));
}

bool ClockSync::is_jump(TimeNs device_ns, TimeNs host_ns) {
  if (window_.empty()) return false;
  if (device_ns <= window_.back().device_ns) {
    late_.clear();
    return true;  // the device clock went backwards (or stood still)
  }
  const double r = residual(device_ns, host_ns);
  const double threshold = std::max(static_cast<double>(options_.jump_threshold_ns),
                                    options_.jump_median_factor * median_delay_ns_);
  // Below the line by more than any delay seen so far: the line rests on the lowest delay yet,
  // so a quicker frame alone lowers it by at most the spread of the delays.
  if (r < -std::max({threshold, max_delay_ns_, static_cast<double>(options_.jump_ahead_ns)})) {
    late_.clear();
    return true;  // earlier than the line allows: the device clock jumped forward
  }
  if (r > threshold) {
    // Later than usual: a long latency, or the device clock jumped back by less than a frame
    // interval. Only a run of such pairs is taken as a jump.
    late_.push_back({device_ns, host_ns});
    return late_.size() >= options_.jump_confirm_pairs;
  }
  late_.clear();
  return false;
}

bool ClockSync::add(TimeNs device_ns, TimeNs host_ns) {
  if (is_jump(device_ns, host_ns)) {
    ++resets_;
    std::vector<Pair> fresh;
    fresh.swap(late_);
    if (fresh.empty()) fresh.push_back({device_ns, host_ns});
    restart(std::move(fresh));
    return true;
  }
  // A late pair of a run not yet confirmed is still a pair of the current clock as far as
  // anyone knows; it joins the window and cannot pull the envelope up.
  window_.push_back({device_ns, host_ns});
  trim();
  refit();
  update_median_delay();
  return false;
}

void ClockSync::restart(std::vector<Pair> pairs) {
  window_.assign(pairs.begin(), pairs.end());
  ref_ = window_.front();
  held_b_ = 0.0;
  refit();
  update_median_delay();
}

void ClockSync::clear() {
  window_.clear();
  late_.clear();
  a_ns_ = 0.0;
  b_ = 0.0;
  held_b_ = 0.0;
  median_delay_ns_ = 0.0;
  max_delay_ns_ = 0.0;
  drift_fitted_ = false;
}

void ClockSync::trim() {
  while (window_.size() > options_.window_pairs ||
         (window_.size() > 2 &&
          window_.back().device_ns - window_.front().device_ns > options_.window_span_ns)) {
    window_.pop_front();
  }
  // Keep the reference near the data so that x and the line's constants stay small; the line is
  // re-expressed by refit().
  ref_ = window_.front();
}

void ClockSync::fit_held_drift() {
  b_ = held_b_;
  double a = INFINITY;
  for (const Pair& p : window_) {
    a = std::min(a, delay(p) - b_ * static_cast<double>(p.device_ns - ref_.device_ns));
  }
  a_ns_ = a;
  drift_fitted_ = false;
}

void ClockSync::refit() {
  const TimeNs span = window_.back().device_ns - window_.front().device_ns;
  if (window_.size() < std::max<std::size_t>(options_.min_pairs_for_drift, 2) ||
      span < options_.min_span_for_drift_ns) {
    fit_held_drift();
    return;
  }
  // The lowest delay in each of `bins` equal stretches of device time: the lower envelope,
  // sampled along the whole window.
  const std::size_t bins = std::max<std::size_t>(options_.envelope_bins, 2);
  std::vector<Point> minima(bins, Point{0.0, INFINITY});
  const auto span_d = static_cast<double>(span);
  for (const Pair& p : window_) {
    const Point q{static_cast<double>(p.device_ns - ref_.device_ns), delay(p)};
    const auto i = std::min(bins - 1, static_cast<std::size_t>(q.x / span_d * static_cast<double>(bins)));
    if (q.y < minima[i].y) minima[i] = q;
  }
  // Least squares through the minima: the slope.
  double n = 0.0, sx = 0.0, sy = 0.0;
  for (const Point& m : minima) {
    if (!std::isfinite(m.y)) continue;
    n += 1.0;
    sx += m.x;
    sy += m.y;
  }
  double sxx = 0.0, sxy = 0.0;
  for (const Point& m : minima) {
    if (!std::isfinite(m.y)) continue;
    sxx += (m.x - sx / n) * (m.x - sx / n);
    sxy += (m.x - sx / n) * (m.y - sy / n);
  }
  const double slope = sxy / sxx;
  if (n < 2.0 || !std::isfinite(slope) || std::abs(slope) * 1e6 > options_.max_drift_ppm) {
    fit_held_drift();
    return;
  }
  held_b_ = slope;
  fit_held_drift();  // the offset: the smallest delay under that slope
  drift_fitted_ = true;
}

void ClockSync::update_median_delay() {
  std::vector<double> r;
  r.reserve(window_.size());
  for (const Pair& p : window_) r.push_back(residual(p.device_ns, p.host_ns));
  const auto mid = r.begin() + static_cast<std::ptrdiff_t>(r.size() / 2);
  std::nth_element(r.begin(), mid, r.end());
  median_delay_ns_ = *mid;
  max_delay_ns_ = *std::max_element(r.begin(), r.end());
}

ClockSyncState ClockSync::state() const {
  ClockSyncState s;
  s.resets = resets_;
  if (window_.empty()) return s;
  s.valid = true;
  s.offset_ns = to_host(window_.back().device_ns) - window_.back().device_ns;
  // host = device * (1 + b) + c, so the device runs 1 / (1 + b) times as fast as the host.
  s.drift_ppm = (1.0 / (1.0 + b_) - 1.0) * 1e6;
  s.drift_fitted = drift_fitted_;
  s.samples = window_.size();
  s.span_ns = window_.back().device_ns - window_.front().device_ns;
  std::vector<TimeNs> r;
  r.reserve(window_.size());
  for (const Pair& p : window_) r.push_back(p.host_ns - to_host(p.device_ns));
  const auto mid = r.begin() + static_cast<std::ptrdiff_t>(r.size() / 2);
  std::nth_element(r.begin(), mid, r.end());
  s.residual_median_ns = *mid;
  s.residual_max_ns = *std::max_element(r.begin(), r.end());
  return s;
}

}  // namespace imucal::drivers::camera
