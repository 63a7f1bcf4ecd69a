// SPDX-License-Identifier: BSD-3-Clause
#include "app/initial_guess.hpp"

#include "calib/gravity.hpp"

namespace imucal::app {

GravityChoice choose_gravity(std::optional<double> given, std::optional<double> latitude_deg,
                             double height_m) {
  GravityChoice g;
  if (given) {
    g.mps2 = *given;
    g.source = "given";
  } else if (latitude_deg) {
    g.mps2 = calib::wgs84_gravity(*latitude_deg, height_m);
    g.source = "WGS-84 normal gravity at latitude " + std::to_string(*latitude_deg) + " deg, height " +
               std::to_string(height_m) + " m";
  } else {
    g.mps2 = kStandardGravity;
    g.source = "standard gravity";
    g.standard_assumed = true;
  }
  return g;
}

Result<NominalGuess> nominal_guess(const ImuStreamInfo& info, const NominalOverrides& given) {
  // A raw stream's conversion is known when the log records the full-scale range or a scale
  // other than the unit placeholder an import writes when it was not told one.
  const bool raw = info.units == ImuUnits::kRaw;
  const bool accel_known = !raw || info.accel_full_scale_g != 0 || !info.accel.scale.isOnes();
  const bool gyro_known = !raw || info.gyro_full_scale_dps != 0 || !info.gyro.scale.isOnes();
  NominalGuess guess;
  if (given.accel_scale || given.accel_offset) {
    AxisConversion c = info.accel;
    if (given.accel_scale) c.scale = *given.accel_scale;
    if (given.accel_offset) c.offset = *given.accel_offset;
    guess.accel = c;
  } else if (accel_known) {
    guess.accel = info.accel;
  }
  if (given.gyro_scale) {
    guess.gyro = info.gyro;
    guess.gyro.scale = *given.gyro_scale;
  } else if (gyro_known) {
    guess.gyro = info.gyro;
  } else {
    return make_error(Errc::kInvalidArgument,
                      "the gyro stream is in raw counts and the log does not give its full-scale range");
  }
  return guess;
}

}  // namespace imucal::app
