#pragma once
// The scan of a recording that the static methods share (the calibration, calib/static_steps.hpp,
// and the check of a calibration, app/calibration_check.hpp): time base, breaks and invalid
// samples. No solver library.

#include <Eigen/Core>
#include <span>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// The recording as the method sees it: time base, breaks and invalid samples.
struct ScannedRecording {
  double period_s = 0.0;  // median sample interval
  double rate_hz = 0.0;
  /// A gap (flagged, or an interval over 1.5 periods) or a device reset before sample i.
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

}  // namespace imucal::calib
