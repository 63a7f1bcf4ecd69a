// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Driver settings from what a rig configuration or a simulation asks for: an output rate, the
// low-pass filter bandwidth and the full-scale ranges. The MPU-6000 produces only
// gyro_rate / (1 + SMPLRT_DIV) with a gyro rate of 8 kHz (DLPF off) or 1 kHz (DLPF on), so a
// rate it cannot produce exactly is refused with the nearest ones it can.

#include <optional>

#include "core/result.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::drivers::mpu6000 {

struct OutputRequest {
  BusKind bus = BusKind::kSpi;
  double rate_hz = 1000.0;
  /// Gyro DLPF bandwidth in Hz (256, 188, 98, 42, 20, 10, 5; 256 = filter off, 8 kHz). Empty:
  /// the widest bandwidth below the output's Nyquist frequency (rate / 2), the filter off for
  /// rates above 1 kHz.
  std::optional<int> dlpf_hz;
  int accel_full_scale_g = 16;     // 2, 4, 8, 16
  int gyro_full_scale_dps = 2000;  // 250, 500, 1000, 2000
  std::uint32_t spi_config_speed_hz = kSpiConfigSpeedHz;
  std::uint32_t spi_data_speed_hz = kSpiSensorSpeedHz;
};

[[nodiscard]] Result<AccelRange> accel_range_for(int full_scale_g);
[[nodiscard]] Result<GyroRange> gyro_range_for(int full_scale_dps);

/// Settings for `request`, validated (Settings::validate). The read interval allows a read about
/// every millisecond, or every sample at lower rates, with room for one late read.
[[nodiscard]] Result<Settings> settings_for(const OutputRequest& request);

}  // namespace imucal::drivers::mpu6000
