// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Local gravity magnitude, and the Earth rotation a still gyro sees along it.

namespace imucal::calib {

/// WGS-84 normal gravity (Somigliana formula) at geodetic latitude `latitude_deg`, with the
/// standard free-air correction for ellipsoidal height `height_m`. Accurate to a few 1e-5 m/s^2
/// below 10 km, which is well under what a MEMS accelerometer resolves.
double wgs84_gravity(double latitude_deg, double height_m);

/// Earth rotation rate, rad/s (WGS-84).
inline constexpr double kEarthRateRadps = 7.2921150e-5;

/// The part of the Earth's rotation that a still gyro cannot tell from g-sensitivity: its vertical
/// component Omega sin(latitude) lies along gravity, so in every still pose the gyro reads it as
/// (Omega sin(latitude) / g) a with a the gravity reaction the accelerometer sees. Returned as that
/// factor (rad/s per m/s^2): an estimated G holds it times the identity, and a caller that knows
/// the latitude subtracts it. At most 7.4e-6 rad/s per m/s^2 (0.004 deg/s per g).
double earth_rate_gsens(double latitude_deg, double gravity_mps2);

}  // namespace imucal::calib
