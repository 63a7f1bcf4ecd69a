// SPDX-License-Identifier: BSD-3-Clause
// The options of the static calibration, checked without the solver (so that a program can
// validate them before it loads libimucal_solve.so).

#include <cmath>
#include <cstdio>
#include <string>

#include "calib/static_calibration.hpp"

namespace imucal::calib {

Status StaticCalibrationOptions::validate() const {
  char gravity[32];
  std::snprintf(gravity, sizeof(gravity), "%g", gravity_mps2);
  auto fail = [](const std::string& msg) -> Status { return make_error(Errc::kInvalidArgument, msg); };
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9)) {
    return fail("gravity " + std::string(gravity) + " m/s^2 is not a terrestrial value (9.7..9.9)");
  }
  if (!(init_still_s >= 0.0) || !std::isfinite(init_still_s))
    return fail("the initial still period must be >= 0 s");
  if (!(window_s > 0.0 && window_s <= 10.0)) return fail("the detector window must be in (0, 10] s");
  if (!(min_init_still_s >= 1.0)) return fail("the shortest still start must be at least 1 s");
  if (min_poses_for_gsens < 5) return fail("the g-sensitivity needs at least 5 poses to be estimated");
  if (threads < 0) return fail("threads must be 0 (one per core) or more");
  if (!(min_interval_s > 0.0)) return fail("the minimum static interval must be positive");
  if (multiplier_min < 1 || multiplier_max < multiplier_min)
    return fail("threshold multipliers must satisfy 1 <= min <= max");
  if (min_attitudes < 9)
    return fail("at least 9 distinct attitudes are needed for observability (Tedaldi 3.5)");
  if (min_attitudes_scale_bias < 6 || min_attitudes_scale_bias > min_attitudes)
    return fail("scales and biases need at least 6 distinct attitudes, and no more than the full model");
  if (!(face_max_angle_deg > 0.0 && face_max_angle_deg < 45.0))
    return fail("the angle within which a pose lies on a face must be in (0, 45) deg");
  if (!(misalignment_prior_rad >= 0.0 && misalignment_prior_rad < 0.5))
    return fail("the misalignment prior must be in [0, 0.5) rad");
  if (!(distinct_attitude_deg > 0.0)) return fail("the distinct-attitude angle must be positive");
  if (!(max_rotation_in_static_deg > 0.0))
    return fail("the rotation limit inside a static interval must be positive");
  for (const auto* c : {&accel_init, &gyro_init}) {
    if (*c &&
        (!(*c)->scale.allFinite() || !(*c)->offset.allFinite() || (*c)->scale.cwiseAbs().minCoeff() == 0.0)) {
      return fail("a nominal scale is zero or not finite");
    }
  }
  return {};
}

}  // namespace imucal::calib
