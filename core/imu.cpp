// SPDX-License-Identifier: BSD-3-Clause
#include "core/imu.hpp"

namespace imucal {

const char* imu_units_name(ImuUnits units) { return units == ImuUnits::kRaw ? "raw" : "si"; }

}  // namespace imucal
