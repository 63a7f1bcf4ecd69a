// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The review's text before the write (docs/service-session.md, "The review"): every quantity the
// record stores, in true units with its sigma ("not determined" where there is none, never 0),
// and the change from the stored record in the same units. Plain functions of typed results, so
// that the session engine only chooses which to show.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/thermal_calibration.hpp"
#include "core/calibration_record.hpp"
#include "core/camimu_calibration.hpp"
#include "core/imu.hpp"
#include "core/imu_calibration.hpp"

namespace imucal::app::session {

/// Three figures times `k` with `digits` decimals, "not determined" for one that is not finite.
std::string figures(const Eigen::Vector3d& v, double k, int digits);
/// "a b c +- sa sb sc".
std::string figures_with_sigmas(const Eigen::Vector3d& v, const Eigen::Vector3d& sigma, double k, int digits);

/// The IMU calibration: the biases as the correction removes them, the scales against the
/// nominal conversion, the misalignment angles and the g-sensitivity, with sigmas.
std::vector<std::string> imu_review_lines(const StaticCalibrationResult& r, const ImuStreamInfo& info);

/// The thermal model: range, orders, the coefficients with their sigmas, the drift it removes
/// and what it leaves, and the scale against temperature where it was fitted.
std::vector<std::string> thermal_review_lines(const calib::ThermalResult& t);

/// A camera as the record stores it: T_cam_imu, time offset (and line delay) with sigmas, and
/// its intrinsics with theirs. `rms_px`: the reprojection RMS of the solve.
std::vector<std::string> camera_review_lines(const CameraRecord& cam, double rms_px);

/// The change of the IMU's canonical model from the stored one: biases in m/s^2 and deg/s (and
/// counts on raw input), scales (relative), misalignment (mrad) and g-sensitivity. `now_a` and
/// `now_g`: the accelerometer's and gyro's correction matrices of the new model.
std::vector<std::string> imu_change_lines(const CanonicalImuModel& now, const CanonicalImuModel& stored,
                                          bool raw_counts);

/// The change of the thermal model from the stored one: the largest difference of the modelled
/// bias change over the range both cover, per axis, in deg/s and mg (`info`: the input's
/// nominal conversion, for models on raw counts).
std::vector<std::string> thermal_change_lines(const ThermalModel& now,
                                              const std::optional<ThermalModel>& stored,
                                              const ImuStreamInfo& info);

/// The change of a camera from the stored one: translation, rotation, time offset, line delay
/// and intrinsics (focal lengths and principal point in px, the other figures as numbers).
std::string camera_change_line(const CameraRecord& now, const CameraRecord& stored);

}  // namespace imucal::app::session
