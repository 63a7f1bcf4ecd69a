// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include "calib/gravity.hpp"

namespace imucal::calib {
namespace {

TEST(Wgs84Gravity, MatchesPublishedValues) {
  // Normal gravity at the equator and the poles (WGS-84 defining values).
  EXPECT_NEAR(wgs84_gravity(0.0, 0.0), 9.7803253359, 1e-9);
  EXPECT_NEAR(wgs84_gravity(90.0, 0.0), 9.8321849379, 1e-9);
  EXPECT_NEAR(wgs84_gravity(-90.0, 0.0), 9.8321849379, 1e-9);
  // 45 deg: 9.806199 m/s^2 (Somigliana).
  EXPECT_NEAR(wgs84_gravity(45.0, 0.0), 9.806199, 2e-6);
}

TEST(Wgs84Gravity, FreeAirGradient) {
  // About -3.086e-6 m/s^2 per metre near the surface.
  const double dg = wgs84_gravity(47.0, 1000.0) - wgs84_gravity(47.0, 0.0);
  EXPECT_NEAR(dg, -3.086e-3, 2e-5);
}

}  // namespace
}  // namespace imucal::calib
