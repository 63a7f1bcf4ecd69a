// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The die temperatures a thermal model may name.

namespace imucal {

/// Deg C: an MPU-6000 works from -40 to 85 deg C and its temperature register spans about -60 to
/// 133. A temperature outside is a wrong input (a wrong scale, a damaged or hostile file), never a
/// die's: it is refused, not fitted or applied.
inline constexpr double kMinDieTemperatureC = -60.0;
inline constexpr double kMaxDieTemperatureC = 150.0;
inline bool is_die_temperature(double t_c) {
  return t_c >= kMinDieTemperatureC && t_c <= kMaxDieTemperatureC;
}

}  // namespace imucal
