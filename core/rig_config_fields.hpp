// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Internal to core/rig_config.cpp and core/rig_config_output.cpp: the table of the session's
// numeric settings that the parser and both writers share.

#include "core/rig_config.hpp"

namespace imucal::rig_config_detail {

/// The session's numeric settings: key, member, accepted range. One table serves the parser and
/// both writers.
struct SessionNumber {
  const char* key;
  double SessionConfig::*member;
  double min, max;
};
inline constexpr SessionNumber kSessionNumbers[] = {
    {"warmup_rate_c_per_min", &SessionConfig::warmup_rate_c_per_min, 0.001, 10.0},
    {"warmup_window_s", &SessionConfig::warmup_window_s, 2.0, 600.0},
    {"warmup_timeout_s", &SessionConfig::warmup_timeout_s, 1.0, 7200.0},
    {"thermal_min_span_c", &SessionConfig::thermal_min_span_c, 0.5, 100.0},
    {"thermal_timeout_s", &SessionConfig::thermal_timeout_s, 60.0, 28800.0},
    {"still_s", &SessionConfig::still_s, 1.0, 600.0},
    {"hold_s", &SessionConfig::hold_s, 0.5, 60.0},
    {"still_gyro_dps", &SessionConfig::still_gyro_dps, 0.01, 90.0},
    {"still_accel_mps2", &SessionConfig::still_accel_mps2, 0.001, 10.0},
    {"pose_min_angle_deg", &SessionConfig::pose_min_angle_deg, 1.0, 90.0},
    {"pose_sigma_target", &SessionConfig::pose_sigma_target, 1e-6, 1.0},
    {"gsens_hold_s", &SessionConfig::gsens_hold_s, 1.0, 600.0},
    {"motion_s", &SessionConfig::motion_s, 5.0, 1800.0},
    {"gate_gravity_rms_mps2", &SessionConfig::gate_gravity_rms_mps2, 1e-6, 10.0},
    {"gate_scale_sigma", &SessionConfig::gate_scale_sigma, 1e-7, 1.0},
    {"gate_reprojection_px", &SessionConfig::gate_reprojection_px, 0.01, 100.0},
    {"operator_wait_s", &SessionConfig::operator_wait_s, 60.0, 86400.0},
};

}  // namespace imucal::rig_config_detail
