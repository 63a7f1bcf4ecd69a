// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/mpu6000/output_settings.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace imucal::drivers::mpu6000 {
namespace {

/// The divider that makes `rate_hz` from `base_hz`, when it does so exactly.
std::optional<int> exact_divider(double base_hz, double rate_hz) {
  const double d = base_hz / rate_hz;
  const double r = std::round(d);
  if (r < 1.0 || r > 256.0 || std::abs(d - r) > 1e-9 * d) return std::nullopt;
  return static_cast<int>(r);
}

/// The rates nearest to `rate_hz` that a base rate can produce, for error messages.
std::string nearest_rates(double base_hz, double rate_hz) {
  const double d = std::clamp(base_hz / rate_hz, 1.0, 256.0);
  const double lo = base_hz / std::ceil(d), hi = base_hz / std::floor(d);
  std::ostringstream s;
  s << lo;
  if (hi != lo) s << " or " << hi;
  s << " Hz";
  return s.str();
}

}  // namespace

Result<AccelRange> accel_range_for(int full_scale_g) {
  for (AccelRange r : {AccelRange::k2g, AccelRange::k4g, AccelRange::k8g, AccelRange::k16g}) {
    if (accel_full_scale_g(r) == full_scale_g) return r;
  }
  return make_error(Errc::kInvalidArgument, "accelerometer full-scale range must be 2, 4, 8 or 16 g, got " +
                                                std::to_string(full_scale_g));
}

Result<GyroRange> gyro_range_for(int full_scale_dps) {
  for (GyroRange r : {GyroRange::k250dps, GyroRange::k500dps, GyroRange::k1000dps, GyroRange::k2000dps}) {
    if (gyro_full_scale_dps(r) == full_scale_dps) return r;
  }
  return make_error(Errc::kInvalidArgument,
                    "gyroscope full-scale range must be 250, 500, 1000 or 2000 deg/s, got " +
                        std::to_string(full_scale_dps));
}

Result<Settings> settings_for(const OutputRequest& request) {
  const double rate = request.rate_hz;
  if (!(rate > 0.0) || !std::isfinite(rate)) {
    return make_error(Errc::kInvalidArgument, "the IMU rate must be a positive number of Hz");
  }
  Settings s;
  s.bus = request.bus;
  auto accel = accel_range_for(request.accel_full_scale_g);
  if (!accel.ok()) return accel.error();
  auto gyro = gyro_range_for(request.gyro_full_scale_dps);
  if (!gyro.ok()) return gyro.error();
  s.accel_range = *accel;
  s.gyro_range = *gyro;
  s.config_speed_hz = request.spi_config_speed_hz;
  s.fifo_speed_hz = request.spi_data_speed_hz;

  int cfg = -1;
  if (request.dlpf_hz) {
    for (int i = 0; i < 7; ++i) {
      if (kDlpfGyroBandwidthHz[i] == *request.dlpf_hz) cfg = i;
    }
    if (cfg < 0) {
      return make_error(Errc::kInvalidArgument,
                        "DLPF bandwidth must be one of 256, 188, 98, 42, 20, 10, 5 Hz, got " +
                            std::to_string(*request.dlpf_hz));
    }
  } else if (rate > 1000.0 || !exact_divider(1000.0, rate)) {
    cfg = 0;  // 8 kHz gyro rate, the filter off
  } else {
    cfg = 6;  // 5 Hz unless a wider bandwidth stays below rate / 2
    for (int i = 1; i < 7; ++i) {
      if (kDlpfGyroBandwidthHz[i] <= rate / 2.0) {
        cfg = i;
        break;
      }
    }
  }
  s.dlpf_cfg = static_cast<std::uint8_t>(cfg);
  const double base = static_cast<double>(s.gyro_rate_hz());
  const auto div = exact_divider(base, rate);
  if (!div) {
    std::ostringstream msg;
    msg << "the MPU-6000 cannot produce " << rate << " Hz with the DLPF "
        << (cfg == 0 ? "off (8 kHz gyro rate)" : "on (1 kHz gyro rate)") << ": the rate must be " << base
        << " Hz divided by 1..256; nearest: " << nearest_rates(base, rate);
    return make_error(Errc::kInvalidArgument, msg.str());
  }
  s.smplrt_div = static_cast<std::uint8_t>(*div - 1);
  const double per_read = std::max(1.0, std::round(s.sample_rate_hz() / 1000.0));
  s.read_interval_ns = static_cast<TimeNs>(2.0 * per_read * 1e9 / s.sample_rate_hz());
  IMUCAL_TRY(s.validate());
  return s;
}

}  // namespace imucal::drivers::mpu6000
