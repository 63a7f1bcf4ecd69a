// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Helpers shared by the session log tests.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "log/session_log.hpp"

namespace imucal::test {

inline ImuStreamInfo test_raw_imu_info() {
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kRaw;
  info.rate_hz = 1000.0;
  info.accel.scale = Eigen::Vector3d::Constant(9.80665 / 16384.0);
  info.accel.offset = {1.0, -2.0, 0.5};
  info.gyro.scale = Eigen::Vector3d::Constant(M_PI / 180.0 / 131.0);
  info.gyro.offset = {0.0, 0.25, -3.0};
  info.temperature_scale = 1.0 / 340.0;
  info.temperature_offset = 36.53;
  info.accel_full_scale_g = 2;
  info.gyro_full_scale_dps = 250;
  info.dlpf_hz = 188;
  info.device = "mpu6000@spi0.0";
  return info;
}

/// `count` raw samples at 1 kHz from `t0_ns`, values derived from the index.
inline std::vector<ImuSample> make_raw_samples(int count, TimeNs t0_ns, int first_index = 0) {
  std::vector<ImuSample> samples(static_cast<std::size_t>(count));
  for (int k = 0; k < count; ++k) {
    const int i = first_index + k;
    ImuSample& s = samples[static_cast<std::size_t>(k)];
    s.t_ns = t0_ns + static_cast<TimeNs>(k) * 1'000'000;
    s.accel = {static_cast<double>(i % 30000), static_cast<double>(-(i % 1000)), 16384.0};
    s.gyro = {static_cast<double>(i % 7), 3.0, static_cast<double>(-(i % 11))};
    s.temperature = static_cast<double>(-500 + i % 100);
    s.flags = 0;
  }
  return samples;
}

inline bool same_double(double a, double b) {
  if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b);
  return std::memcmp(&a, &b, sizeof a) == 0;  // bit-exact, including the sign of zero
}

inline void expect_same_info(const ImuStreamInfo& got, const ImuStreamInfo& want) {
  EXPECT_EQ(got.name, want.name);
  EXPECT_EQ(got.units, want.units);
  EXPECT_EQ(got.rate_hz, want.rate_hz);
  EXPECT_EQ(got.accel.scale, want.accel.scale);
  EXPECT_EQ(got.accel.offset, want.accel.offset);
  EXPECT_EQ(got.gyro.scale, want.gyro.scale);
  EXPECT_EQ(got.gyro.offset, want.gyro.offset);
  EXPECT_EQ(got.temperature_scale, want.temperature_scale);
  EXPECT_EQ(got.temperature_offset, want.temperature_offset);
  EXPECT_EQ(got.accel_full_scale_g, want.accel_full_scale_g);
  EXPECT_EQ(got.gyro_full_scale_dps, want.gyro_full_scale_dps);
  EXPECT_EQ(got.dlpf_hz, want.dlpf_hz);
  EXPECT_EQ(got.device, want.device);
}

inline void expect_same_samples(const std::vector<ImuSample>& got, const std::vector<ImuSample>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(got[i].t_ns, want[i].t_ns);
    for (int a = 0; a < 3; ++a) {
      EXPECT_TRUE(same_double(got[i].accel[a], want[i].accel[a]))
          << got[i].accel[a] << " vs " << want[i].accel[a];
      EXPECT_TRUE(same_double(got[i].gyro[a], want[i].gyro[a]))
          << got[i].gyro[a] << " vs " << want[i].gyro[a];
    }
    EXPECT_TRUE(same_double(got[i].temperature, want[i].temperature))
        << got[i].temperature << " vs " << want[i].temperature;
    EXPECT_EQ(got[i].flags, want[i].flags);
  }
}

/// What a recording left in its log: the IMU stream "imu0", the metadata, the stream
/// description and whether the log was closed complete.
struct RecordedLog {
  std::vector<ImuSample> samples;
  std::map<std::string, std::string> metadata;
  ImuStreamInfo info;
  bool complete = false;
};

inline RecordedLog read_recorded_log(const std::string& path) {
  RecordedLog r;
  auto reader = log::SessionLogReader::open(path);
  EXPECT_TRUE(reader.ok()) << (reader.ok() ? "" : reader.error().message);
  if (!reader.ok()) return r;
  auto id = (*reader)->find_imu_stream("imu0");
  EXPECT_TRUE(id.ok());
  if (!id.ok()) return r;
  auto samples = (*reader)->read_imu(*id);
  EXPECT_TRUE(samples.ok());
  if (samples.ok()) r.samples = *samples;
  r.metadata = (*reader)->metadata();
  r.info = (*reader)->imu_streams().at(*id);
  r.complete = (*reader)->health().complete;
  return r;
}

}  // namespace imucal::test
