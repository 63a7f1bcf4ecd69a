#pragma once
// Time is int64 nanoseconds on CLOCK_MONOTONIC. Names carry the unit (t_ns, period_ns).
// Doubles in seconds appear only inside estimators, converted at the boundary with these.

#include <cmath>
#include <cstdint>
#include <ctime>

namespace imucal {

using TimeNs = std::int64_t;

inline constexpr TimeNs kNsPerSecond = 1'000'000'000;

constexpr double ns_to_s(TimeNs t_ns) { return static_cast<double>(t_ns) * 1e-9; }

/// Seconds to nanoseconds, rounded to the nearest nanosecond.
inline TimeNs s_to_ns(double t_s) { return static_cast<TimeNs>(std::llround(t_s * 1e9)); }

inline TimeNs monotonic_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

}  // namespace imucal
