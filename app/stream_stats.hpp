// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Timing statistics of the streams of a session log (rates, gaps, durations, flagged samples)
// and the longest clean run of an IMU stream, for `imucal info`, `imucal allan` and the rig
// service's health reports.

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "log/session_log.hpp"

namespace imucal::app {

/// Timing statistics of one stream, from its timestamps.
struct StreamTiming {
  std::int64_t count = 0;
  TimeNs t_first_ns = 0;
  TimeNs t_last_ns = 0;
  TimeNs median_period_ns = 0;
  double measured_rate_hz = 0.0;   // (count - 1) over the span
  std::int64_t gap_intervals = 0;  // intervals that lost samples (step_lost_samples, core/time.hpp)
  TimeNs longest_interval_ns = 0;
  TimeNs longest_interval_at_ns = 0;  // timestamp of the sample that ends the longest interval
  std::int64_t non_increasing = 0;    // intervals <= 0 (duplicate or backwards timestamps)

  double duration_s() const { return ns_to_s(t_last_ns - t_first_ns); }
};

/// Statistics of timestamps given one at a time, in recording order, in bounded memory: the
/// median interval is that of the first `median_window` timestamps (all of them in a shorter
/// stream), and every interval is then judged against it as it comes. A log of any length
/// costs 8 bytes per timestamp of that window, not per timestamp.
class TimingAccumulator {
 public:
  static constexpr std::size_t kDefaultMedianWindow = std::size_t{1} << 20;  // 17 min at 1 kHz

  explicit TimingAccumulator(std::size_t median_window = kDefaultMedianWindow);

  void add(TimeNs t_ns);
  /// The statistics of every timestamp added.
  StreamTiming finish();

 private:
  void judge(bool last);

  std::size_t median_window_;
  bool median_known_ = false;
  std::vector<TimeNs> window_;  // the first timestamps, then the last few still to be judged
  std::size_t next_ = 0;        // index in window_ of the next interval's start to judge
  StreamTiming t_;
};

/// Statistics of `times` (in recording order).
StreamTiming timing_of(const std::vector<TimeNs>& times);

struct ImuStreamStats {
  int id = 0;
  ImuStreamInfo info;
  StreamTiming timing;
  std::int64_t flagged_gap = 0;  // samples flagged as following a gap
  std::int64_t flagged_reset = 0;
  std::int64_t flagged_saturated = 0;  // accel or gyro
  std::int64_t flagged_time_estimated = 0;
  std::string read_error;  // empty when the whole stream was read
};

struct CameraStreamStats {
  int id = 0;
  CameraStreamInfo info;
  StreamTiming timing;
  /// Frames listed whose image is unreadable or fails its CRC (timing counts them).
  std::int64_t unusable_frames = 0;
  std::string read_error;
};

/// What a session log holds: streams with their statistics, events, health, metadata.
struct LogSummary {
  std::map<std::string, std::string> metadata;
  log::SessionLogHealth health;
  std::vector<ImuStreamStats> imu;
  std::vector<CameraStreamStats> cameras;
  std::int64_t event_count = 0;
  std::map<std::string, std::int64_t> events_by_kind;
  bool any_time = false;  // some stream has a sample; t_start_ns / t_end_ns are meaningful
  TimeNs t_start_ns = 0;  // earliest sample or frame of any stream
  TimeNs t_end_ns = 0;    // latest

  /// A metadata value, empty when absent.
  std::string meta(const std::string& key) const;
};

/// Summarises an open log. Read errors of a stream are recorded in its read_error, not failed.
LogSummary summarize_log(const log::SessionLogReader& reader);

/// Opens `path` and summarises it; fails only when the log cannot be opened.
[[nodiscard]] Result<LogSummary> summarize_log(const std::string& path);

/// The longest run of samples without a gap, a device reset, saturation or a timestamp that
/// jumps or steps back: what the Allan deviation can use, as it needs even sampling.
struct CleanRun {
  std::size_t begin = 0;  // [begin, end) into the samples
  std::size_t end = 0;
  int breaks = 0;        // how many places the stream is broken
  TimeNs period_ns = 0;  // mean sample interval over the run
  double rate_hz = 0.0;  // 1 / period

  std::size_t size() const { return end - begin; }
};

/// The longest clean run of `samples` (at least 2). Errc::kCorrupt when the median interval
/// is not positive (the timestamps do not increase).
[[nodiscard]] Result<CleanRun> longest_clean_run(const std::vector<ImuSample>& samples);

/// Where a recording that should be still moves: the time (s from the first of `accel`, in
/// m/s^2 at `rate_hz`) of the first one-second window whose accel variance exceeds 25 times
/// the median window's, or nothing when it is still throughout. Motion inflates every figure
/// of the Allan deviation.
std::optional<double> first_motion_s(const std::vector<Eigen::Vector3d>& accel, double rate_hz);

}  // namespace imucal::app
