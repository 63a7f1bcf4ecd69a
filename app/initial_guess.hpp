// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the static calibration assumes before it estimates: the local gravity magnitude and
// the nominal initial guesses, from the stream's description (its nominal conversion, or the
// full-scale ranges it was recorded with) or from values the user gives.

#include <Eigen/Core>
#include <optional>
#include <string>

#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// The gravity magnitude the calibration uses, and where it comes from (written with the
/// result as "gravity_source").
struct GravityChoice {
  double mps2 = 0.0;
  std::string source;
  bool standard_assumed = false;  // nothing given: standard gravity, up to 0.3 % off locally
};

/// `given` if set, else WGS-84 normal gravity at `latitude_deg` and `height_m` if a latitude is
/// set, else standard gravity.
GravityChoice choose_gravity(std::optional<double> given, std::optional<double> latitude_deg,
                             double height_m);

/// Values given by the user; each replaces the stream's nominal one.
struct NominalOverrides {
  std::optional<Eigen::Vector3d> accel_scale;   // m/s^2 per input unit
  std::optional<Eigen::Vector3d> accel_offset;  // input units
  std::optional<Eigen::Vector3d> gyro_scale;    // rad/s per input unit
};

/// Initial guesses for calib::StaticCalibrationOptions::accel_init / gyro_init.
struct NominalGuess {
  /// Empty when nothing is known: the ellipsoid fit of the static intervals provides it.
  std::optional<AxisConversion> accel;
  AxisConversion gyro;
};

/// The guesses for `info`. A raw gyro stream whose scale the log does not give (no full-scale
/// range, unit scale) has no usable guess: Errc::kInvalidArgument unless a gyro scale is given.
[[nodiscard]] Result<NominalGuess> nominal_guess(const ImuStreamInfo& info, const NominalOverrides& given);

}  // namespace imucal::app
