// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// IMU samples and stream descriptions shared by drivers, acquisition and calib.

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <string>

#include "core/time.hpp"

namespace imucal {

/// Per-sample flags, stored in the session log.
enum ImuFlag : std::uint32_t {
  kImuFlagNone = 0,
  kImuFlagGapBefore = 1u << 0,    // one or more samples are missing before this one
  kImuFlagDeviceReset = 1u << 1,  // the device (or its FIFO) was reset before this sample
  kImuFlagAccelSaturated = 1u << 2,
  kImuFlagGyroSaturated = 1u << 3,
  kImuFlagTimeEstimated = 1u << 4,  // timestamp extrapolated, not anchored to an interrupt
};

/// Units of the values of a stream: SI (m/s^2, rad/s, deg C) or raw device counts.
enum class ImuUnits { kSi, kRaw };

const char* imu_units_name(ImuUnits units);

/// One IMU sample. In a raw stream the values are integral counts held in doubles (so 16-bit
/// ADCs centred at 32768 fit as well as the MPU-6000's signed counts); in an SI stream they are
/// m/s^2 and rad/s. temperature_c is NaN when the device does not report it.
struct ImuSample {
  TimeNs t_ns = 0;
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  double temperature = std::numeric_limits<double>::quiet_NaN();
  std::uint32_t flags = kImuFlagNone;
};

/// Nominal conversion from raw counts to SI: si = scale .* (raw - offset), per axis.
/// For an SI stream scale is 1 and offset 0.
struct AxisConversion {
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();

  Eigen::Vector3d to_si(const Eigen::Vector3d& v) const { return scale.cwiseProduct(v - offset); }
};

/// Description of one IMU stream in a session log.
struct ImuStreamInfo {
  std::string name = "imu0";
  ImuUnits units = ImuUnits::kSi;
  double rate_hz = 0.0;  // nominal output rate
  AxisConversion accel;  // nominal raw->SI conversion (initial guess for calibration)
  AxisConversion gyro;
  double temperature_scale = 1.0;  // deg C = scale * raw + offset (raw streams)
  double temperature_offset = 0.0;
  // Device settings, where known (0 = unknown).
  int accel_full_scale_g = 0;   // 2, 4, 8, 16 for the MPU-6000
  int gyro_full_scale_dps = 0;  // 250, 500, 1000, 2000
  int dlpf_hz = 0;
  std::string device;  // e.g. "mpu6000@spi0.0", "sim", "euroc:imu0"
};

/// Standard gravity, m/s^2 (only a default: the calibration takes local gravity).
inline constexpr double kStandardGravity = 9.80665;

}  // namespace imucal
