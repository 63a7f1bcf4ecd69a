#pragma once
// Local gravity magnitude.

namespace imucal::calib {

/// WGS-84 normal gravity (Somigliana formula) at geodetic latitude `latitude_deg`, with the
/// standard free-air correction for ellipsoidal height `height_m`. Accurate to a few 1e-5 m/s^2
/// below 10 km, which is well under what a MEMS accelerometer resolves.
double wgs84_gravity(double latitude_deg, double height_m);

}  // namespace imucal::calib
