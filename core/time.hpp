// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Time is int64 nanoseconds on CLOCK_MONOTONIC. Names carry the unit (t_ns, period_ns).
// Doubles in seconds appear only inside estimators, converted at the boundary with these.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <ctime>
#include <span>
#include <vector>

namespace imucal {

using TimeNs = std::int64_t;

inline constexpr TimeNs kNsPerSecond = 1'000'000'000;

/// Timestamps are accepted within +-2^62 ns (146 years either side of the clock's zero), so the
/// difference of any two fits an int64. Inputs outside it are refused where they enter (dataset
/// parsers, the session log writer and reader).
inline constexpr TimeNs kTimeLimitNs = TimeNs{1} << 62;
constexpr bool time_in_range(TimeNs t_ns) { return t_ns >= -kTimeLimitNs && t_ns <= kTimeLimitNs; }

constexpr double ns_to_s(TimeNs t_ns) { return static_cast<double>(t_ns) * 1e-9; }

/// Seconds to nanoseconds, rounded to the nearest nanosecond.
inline TimeNs s_to_ns(double t_s) { return static_cast<TimeNs>(std::llround(t_s * 1e9)); }

inline TimeNs monotonic_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

/// The median interval between consecutive times (the upper median for an even count), the
/// robust sample period of a stream with gaps; 0 for fewer than two times.
inline TimeNs median_interval_ns(std::span<const TimeNs> t_ns) {
  if (t_ns.size() < 2) return 0;
  std::vector<TimeNs> dt(t_ns.size() - 1);
  for (std::size_t i = 1; i < t_ns.size(); ++i) dt[i - 1] = t_ns[i] - t_ns[i - 1];
  const auto mid = dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2);
  std::nth_element(dt.begin(), mid, dt.end());
  return *mid;
}

/// Whether the step from t_ns[k] to t_ns[k + 1] lost samples, in a stream whose median interval
/// is `median_ns`: it is longer than 1.5 of them and no neighbouring step makes up for it.
/// Timestamps taken on a coarse or jittery clock (a host's receive time) step by 1.5 and 0.5
/// periods in turn with no time lost: two such steps together stay under 2.5 periods, while a
/// lost sample makes them 3.
inline bool step_lost_samples(std::span<const TimeNs> t_ns, std::size_t k, TimeNs median_ns) {
  if (2 * (t_ns[k + 1] - t_ns[k]) <= 3 * median_ns) return false;
  const bool made_up_before = k > 0 && 2 * (t_ns[k + 1] - t_ns[k - 1]) < 5 * median_ns;
  const bool made_up_after = k + 2 < t_ns.size() && 2 * (t_ns[k + 2] - t_ns[k]) < 5 * median_ns;
  return !made_up_before && !made_up_after;
}

}  // namespace imucal
