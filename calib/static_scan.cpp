// SPDX-License-Identifier: BSD-3-Clause
// The scan of a recording before a static method: time base, breaks and invalid samples, and the
// variance static detector over it (calib/static_scan.hpp).

#include "calib/static_scan.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "calib/static_detector.hpp"
#include "core/time.hpp"

namespace imucal::calib {

Result<ScannedRecording> scan_recording(std::span<const ImuSample> samples,
                                        std::vector<std::string>* warnings) {
  const std::size_t n = samples.size();
  if (n < 3) {
    return make_error(Errc::kInsufficientData,
                      "the recording has " + std::to_string(n) + " samples: too few for a time base");
  }
  std::vector<TimeNs> t_ns(n);
  for (std::size_t i = 0; i < n; ++i) {
    t_ns[i] = samples[i].t_ns;
    if (i > 0 && t_ns[i] <= t_ns[i - 1]) {
      return make_error(Errc::kCorrupt, "timestamps do not increase at sample " + std::to_string(i) +
                                            ": the log is damaged or its samples are out of order");
    }
  }
  ScannedRecording s;
  const TimeNs median_ns = median_interval_ns(t_ns);
  s.break_before.assign(n, false);
  s.reset_before.assign(n, false);
  s.accel_ok.assign(n, true);
  s.gyro_ok.assign(n, true);
  s.t_s.resize(n);
  for (std::size_t i = 0; i < n; ++i) s.t_s[i] = ns_to_s(samples[i].t_ns - samples[0].t_ns);
  TimeNs run_time_ns = 0;
  std::size_t run_steps = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const auto f = samples[i].flags;
    if (i > 0 &&
        ((f & (kImuFlagGapBefore | kImuFlagDeviceReset)) || step_lost_samples(t_ns, i - 1, median_ns))) {
      s.break_before[i] = true;
      s.reset_before[i] = (f & kImuFlagDeviceReset) != 0;
      ++s.gaps;
    } else if (i > 0) {
      run_time_ns += t_ns[i] - t_ns[i - 1];
      ++run_steps;
    }
    if ((f & kImuFlagAccelSaturated) || !samples[i].accel.allFinite()) {
      s.accel_ok[i] = false;
      ++s.accel_saturated;
    }
    if ((f & kImuFlagGyroSaturated) || !samples[i].gyro.allFinite()) {
      s.gyro_ok[i] = false;
      ++s.gyro_saturated;
    }
  }
  s.period_s = run_steps > 0 ? ns_to_s(run_time_ns) / static_cast<double>(run_steps) : ns_to_s(median_ns);
  s.rate_hz = 1.0 / s.period_s;
  if (s.accel_saturated + s.gyro_saturated > 0) {
    warnings->push_back(std::to_string(s.accel_saturated) + " accelerometer and " +
                        std::to_string(s.gyro_saturated) +
                        " gyroscope samples are saturated or invalid: they were excluded (static "
                        "intervals never contain them and no gyro integration crosses them); if this "
                        "is frequent, raise the full-scale range or move the rig more gently");
  }
  if (s.gaps > 0) {
    warnings->push_back("the log has " + std::to_string(s.gaps) +
                        " gap(s) or device reset(s): static intervals are split there and no gyro "
                        "integration crosses them");
  }
  s.accel.resize(n);
  s.gyro.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    s.accel[i] = s.accel_ok[i] ? samples[i].accel : Eigen::Vector3d::Zero();
    s.gyro[i] = samples[i].gyro;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!s.accel_ok[i]) s.accel[i] = i > 0 ? s.accel[i - 1] : Eigen::Vector3d::Zero();
  }
  return s;
}

StaticDetection detect_variance(const ScannedRecording& scan, double window_s) {
  StaticDetection d;
  d.window = std::max<std::size_t>(3, static_cast<std::size_t>(std::lround(window_s * scan.rate_hz)));
  d.half = d.window / 2;
  d.sigma_sq = variance_magnitude_sq(scan.accel, d.window);
  d.gyro_sigma_sq = variance_magnitude_sq(scan.gyro, d.window);
  std::vector<double> usable_sigma, usable_gyro;
  usable_sigma.reserve(d.sigma_sq.size());
  usable_gyro.reserve(d.sigma_sq.size());
  for (std::size_t i = 0; i < d.sigma_sq.size(); ++i) {
    if (scan.accel_ok[i]) usable_sigma.push_back(d.sigma_sq[i]);
    if (scan.gyro_ok[i]) usable_gyro.push_back(d.gyro_sigma_sq[i]);
  }
  d.floor_sq = std::max(percentile(usable_sigma, 0.1), 1e-300);
  d.gyro_floor_sq = std::max(percentile(usable_gyro, 0.1), 1e-300);
  return d;
}

bool StaticDetection::moving(std::size_t i) const {
  const double ra = sigma_sq[i] / floor_sq, rg = gyro_sigma_sq[i] / gyro_floor_sq;
  return (ra > kStillRatio && rg > kStillRatio) || ra > kStrongRatio || rg > kStrongRatio;
}

}  // namespace imucal::calib
