// SPDX-License-Identifier: BSD-3-Clause
#include "app/stream_stats.hpp"

#include <algorithm>
#include <cmath>
#include <span>

#include "calib/static_detector.hpp"

namespace imucal::app {

TimingAccumulator::TimingAccumulator(std::size_t median_window)
    : median_window_(std::max<std::size_t>(median_window, 4)) {
  window_.reserve(std::min<std::size_t>(median_window_, 4096));
}

void TimingAccumulator::add(TimeNs t_ns) {
  if (t_.count == 0) t_.t_first_ns = t_ns;
  t_.t_last_ns = t_ns;
  ++t_.count;
  window_.push_back(t_ns);
  if (!median_known_) {
    if (window_.size() < median_window_) return;
    t_.median_period_ns = median_interval_ns(window_);
    median_known_ = true;
  }
  judge(false);
}

// Judges the intervals from window_[next_] on whose neighbours are known (all that remain when
// `last`), then drops the timestamps no later judgement needs: the one before next_ and after.
void TimingAccumulator::judge(bool last) {
  const std::span<const TimeNs> w(window_);
  for (; next_ + (last ? 1 : 2) < w.size(); ++next_) {
    const TimeNs p = w[next_ + 1] - w[next_];
    if (p <= 0) ++t_.non_increasing;
    // step_lost_samples looks one timestamp back (when there is one) and two ahead.
    const std::size_t from = next_ == 0 ? 0 : next_ - 1;
    if (t_.median_period_ns > 0 && step_lost_samples(w.subspan(from), next_ - from, t_.median_period_ns))
      ++t_.gap_intervals;
    if (p > t_.longest_interval_ns) {
      t_.longest_interval_ns = p;
      t_.longest_interval_at_ns = w[next_ + 1];
    }
  }
  if (next_ > 1) {
    window_.erase(window_.begin(), window_.begin() + static_cast<std::ptrdiff_t>(next_ - 1));
    next_ = 1;
  }
}

StreamTiming TimingAccumulator::finish() {
  if (!median_known_) t_.median_period_ns = median_interval_ns(window_);
  median_known_ = true;
  judge(true);
  const TimeNs span_ns = t_.t_last_ns - t_.t_first_ns;
  if (t_.count >= 2 && span_ns > 0)
    t_.measured_rate_hz = static_cast<double>(t_.count - 1) / ns_to_s(span_ns);
  return t_;
}

StreamTiming timing_of(const std::vector<TimeNs>& times) {
  TimingAccumulator acc(std::max<std::size_t>(times.size(), 4));
  for (const TimeNs t : times) acc.add(t);
  return acc.finish();
}

std::string LogSummary::meta(const std::string& key) const {
  const auto it = metadata.find(key);
  return it == metadata.end() ? std::string() : it->second;
}

namespace {

ImuStreamStats imu_stats(const log::SessionLogReader& log, int id, const ImuStreamInfo& info) {
  ImuStreamStats st;
  st.id = id;
  st.info = info;
  TimingAccumulator times;
  const Status read = log.for_each_imu(id, log::kTimeMin, log::kTimeMax, [&](const ImuSample& s) {
    times.add(s.t_ns);
    if (s.flags & kImuFlagGapBefore) ++st.flagged_gap;
    if (s.flags & kImuFlagDeviceReset) ++st.flagged_reset;
    if (s.flags & (kImuFlagAccelSaturated | kImuFlagGyroSaturated)) ++st.flagged_saturated;
    if (s.flags & kImuFlagTimeEstimated) ++st.flagged_time_estimated;
    return true;
  });
  // A damaged stream still has statistics for what was read before the damage.
  if (!read.ok()) st.read_error = read.error().message;
  st.timing = times.finish();
  return st;
}

CameraStreamStats camera_stats(const log::SessionLogReader& log, int id, const CameraStreamInfo& info) {
  CameraStreamStats st;
  st.id = id;
  st.info = info;
  auto times = log.frame_times(id);
  st.timing = timing_of(times.ok() ? *times : std::vector<TimeNs>{});
  if (!times.ok()) st.read_error = times.error().message;
  // Every frame's image is read once and checked against its CRC (the reader skips and notes a
  // frame that fails it), so a frame listed here is a frame that can be used.
  std::int64_t intact = 0;
  const Status read = log.for_each_frame(id, log::kTimeMin, log::kTimeMax, [&](const CameraFrame&) {
    ++intact;
    return true;
  });
  if (!read.ok() && st.read_error.empty()) st.read_error = read.error().message;
  st.unusable_frames = std::max<std::int64_t>(0, st.timing.count - intact);
  return st;
}

void extend(LogSummary& s, const StreamTiming& t) {
  if (t.count == 0) return;
  s.t_start_ns = s.any_time ? std::min(s.t_start_ns, t.t_first_ns) : t.t_first_ns;
  s.t_end_ns = s.any_time ? std::max(s.t_end_ns, t.t_last_ns) : t.t_last_ns;
  s.any_time = true;
}

}  // namespace

LogSummary summarize_log(const log::SessionLogReader& reader) {
  LogSummary s;
  s.metadata = reader.metadata();
  for (const auto& [id, info] : reader.imu_streams()) {
    s.imu.push_back(imu_stats(reader, id, info));
    extend(s, s.imu.back().timing);
  }
  for (const auto& [id, info] : reader.camera_streams()) {
    s.cameras.push_back(camera_stats(reader, id, info));
    extend(s, s.cameras.back().timing);
  }
  if (auto events = reader.events(); events.ok()) {
    for (const auto& e : *events) ++s.events_by_kind[e.kind];
    s.event_count = static_cast<std::int64_t>(events->size());
  }
  s.health = reader.health();  // after the reads, which note damage they find
  return s;
}

Result<LogSummary> summarize_log(const std::string& path) {
  auto opened = log::SessionLogReader::open(path);
  if (!opened.ok()) return opened.error();
  return summarize_log(**opened);
}

Result<CleanRun> longest_clean_run(const std::vector<ImuSample>& s) {
  if (s.size() < 2) return make_error(Errc::kInsufficientData, "a clean run needs at least 2 samples");
  CleanRun run;
  std::vector<TimeNs> times(s.size());
  for (std::size_t i = 0; i < s.size(); ++i) times[i] = s[i].t_ns;
  const TimeNs median_ns = median_interval_ns(times);
  if (median_ns <= 0) return make_error(Errc::kCorrupt, "the timestamps do not increase");
  constexpr std::uint32_t kSaturated = kImuFlagAccelSaturated | kImuFlagGyroSaturated;
  constexpr std::uint32_t kBreak = kImuFlagGapBefore | kImuFlagDeviceReset | kSaturated;
  std::size_t run0 = 0;
  for (std::size_t i = 0; i <= s.size(); ++i) {
    const bool brk = i == s.size() || (s[i].flags & kBreak) ||
                     (i > 0 && (s[i].t_ns <= s[i - 1].t_ns || step_lost_samples(times, i - 1, median_ns)));
    if (!brk) continue;
    if (i < s.size()) ++run.breaks;
    if (i - run0 > run.end - run.begin) {
      run.begin = run0;
      run.end = i;
    }
    // A saturated sample itself is left out; after a gap or reset the sample starts the next run.
    run0 = (i < s.size() && (s[i].flags & kSaturated)) ? i + 1 : i;
  }
  // The run's mean interval: on a coarse or jittery clock the median interval is not the rate.
  const double period_ns = run.size() >= 2 ? static_cast<double>(times[run.end - 1] - times[run.begin]) /
                                                 static_cast<double>(run.size() - 1)
                                           : static_cast<double>(median_ns);
  run.period_ns = static_cast<TimeNs>(std::llround(period_ns));
  run.rate_hz = 1e9 / period_ns;
  return run;
}

std::optional<double> first_motion_s(const std::vector<Eigen::Vector3d>& accel, double rate_hz) {
  const auto var = calib::variance_magnitude_sq(accel, static_cast<std::size_t>(std::max(3.0, rate_hz)));
  if (var.empty()) return std::nullopt;
  std::vector<double> sorted = var;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                   sorted.end());
  const double median = sorted[sorted.size() / 2];
  for (std::size_t i = 0; i < var.size(); ++i) {
    if (var[i] > 25.0 * median) return static_cast<double>(i) / rate_hz;
  }
  return std::nullopt;
}

}  // namespace imucal::app
