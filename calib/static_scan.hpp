// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The scan of a recording that the static methods share (the calibration, calib/static_steps.hpp,
// the six-orientation g-sensitivity experiment, calib/gsens_calibration.hpp, and the check of a
// calibration, app/calibration_check.hpp): time base, breaks and invalid samples, and the variance
// static detector over the whole recording. No solver library.

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// The recording as the method sees it: time base, breaks and invalid samples.
struct ScannedRecording {
  /// The mean step between samples over the steps that are not gaps: with timestamps from a
  /// coarse or jittery clock (steps of 0.5, 1 and 1.5 periods) the median step is not the rate.
  double period_s = 0.0;
  double rate_hz = 0.0;
  /// A gap (flagged, or a step over 1.5 periods that no neighbouring step makes up for) or a
  /// device reset before sample i.
  std::vector<bool> break_before;
  std::vector<bool> reset_before;  // a device reset before sample i
  std::vector<bool> accel_ok, gyro_ok;
  std::vector<double> t_s;  // sample times from the first, s
  int gaps = 0, accel_saturated = 0, gyro_saturated = 0;
  /// The samples' values; an invalid accelerometer value is replaced by the previous one so that
  /// running sums stay finite (such samples are never part of a static interval).
  std::vector<Eigen::Vector3d> accel, gyro;
};

/// Checks the time base (kInsufficientData below 3 samples, kCorrupt when timestamps do not
/// increase) and finds breaks and saturated samples; warns about them. Callers refuse recordings
/// too short for their method themselves.
[[nodiscard]] Result<ScannedRecording> scan_recording(std::span<const ImuSample> samples,
                                                      std::vector<std::string>* warnings);

/// The variance static detector (eq. 3.9) over the whole recording, for the accelerometer (which
/// selects the static poses) and the gyroscope (which, with it, tells a still start from motion).
struct StaticDetection {
  std::size_t window = 0;             // samples
  std::size_t half = 0;               // window / 2
  std::vector<double> sigma_sq;       // accelerometer
  std::vector<double> gyro_sigma_sq;  // the same statistic of the gyroscope
  /// 10th percentile of sigma_sq (gyro_sigma_sq) over the valid samples: the noise floor of a
  /// still rig.
  double floor_sq = 0.0;
  double gyro_floor_sq = 0.0;

  /// Ratios to the floors (on varsigma^2, the squared variance) for the still start: a sample is
  /// moving when both sensors exceed kStillRatio (variance 3.2 times the floor), or either
  /// exceeds kStrongRatio (variance 1000 times). One sensor alone being noisier than in the later
  /// poses (an accelerometer that settles after power-up; a gyro on a rig held by hand, 40 times
  /// the floor's variance in a real recording) is not motion: turning the rig raises both, by
  /// far more.
  static constexpr double kStillRatio = 10.0;
  static constexpr double kStrongRatio = 1e6;
  bool moving(std::size_t i) const;
};
StaticDetection detect_variance(const ScannedRecording& scan, double window_s);

}  // namespace imucal::calib
