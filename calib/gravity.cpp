// SPDX-License-Identifier: BSD-3-Clause
#include "calib/gravity.hpp"

#include <cmath>

namespace imucal::calib {

double wgs84_gravity(double latitude_deg, double height_m) {
  // WGS-84 constants (NIMA TR8350.2, 2000, section 4).
  constexpr double kGammaEquator = 9.7803253359;  // m/s^2
  constexpr double kK = 0.00193185265241;         // Somigliana constant
  constexpr double kE2 = 0.00669437999013;        // first eccentricity squared
  constexpr double kA = 6378137.0;                // semi-major axis, m
  constexpr double kF = 1.0 / 298.257223563;      // flattening
  constexpr double kM = 0.00344978650684;         // omega^2 a^2 b / GM
  const double phi = latitude_deg * M_PI / 180.0;
  const double s2 = std::sin(phi) * std::sin(phi);
  const double gamma0 = kGammaEquator * (1.0 + kK * s2) / std::sqrt(1.0 - kE2 * s2);
  // Second-order height expansion (TR8350.2 eq. 4-3).
  const double h = height_m;
  return gamma0 * (1.0 - 2.0 / kA * (1.0 + kF + kM - 2.0 * kF * s2) * h + 3.0 / (kA * kA) * h * h);
}

double earth_rate_gsens(double latitude_deg, double gravity_mps2) {
  return kEarthRateRadps * std::sin(latitude_deg * M_PI / 180.0) / gravity_mps2;
}

}  // namespace imucal::calib
