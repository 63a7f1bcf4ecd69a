// SPDX-License-Identifier: BSD-3-Clause
// Driver settings from a requested rate, filter and ranges (drivers/mpu6000/output_settings.hpp).

#include <gtest/gtest.h>

#include "drivers/mpu6000/output_settings.hpp"

namespace imucal::drivers::mpu6000 {
namespace {

OutputRequest request(double rate_hz) {
  OutputRequest r;
  r.rate_hz = rate_hz;
  return r;
}

TEST(OutputSettings, ExactRatesWithTheWidestFilterBelowNyquist) {
  struct Case {
    double rate;
    int dlpf_cfg, div;
  };
  // DLPF bandwidths 256 (off, 8 kHz), 188, 98, 42, 20, 10, 5 Hz.
  for (const Case c :
       {Case{1000, 1, 0}, Case{500, 1, 1}, Case{200, 2, 4}, Case{100, 3, 9}, Case{50, 4, 19}, Case{25, 5, 39},
        Case{10, 6, 99}, Case{8000, 0, 0}, Case{4000, 0, 1}, Case{2000, 0, 3}, Case{1600, 0, 4}}) {
    auto s = settings_for(request(c.rate));
    ASSERT_TRUE(s.ok()) << c.rate << ": " << s.error().message;
    EXPECT_EQ(s->dlpf_cfg, c.dlpf_cfg) << c.rate;
    EXPECT_EQ(s->smplrt_div, c.div) << c.rate;
    EXPECT_DOUBLE_EQ(s->sample_rate_hz(), c.rate);
    const Status valid = s->validate();
    EXPECT_TRUE(valid.ok()) << c.rate << ": " << (valid.ok() ? "" : valid.error().message);
  }
}

TEST(OutputSettings, ReadIntervalAllowsOneLateRead) {
  auto s1k = settings_for(request(1000));
  ASSERT_TRUE(s1k.ok());
  EXPECT_EQ(s1k->read_interval_ns, 2'000'000);  // a read per sample, twice the period
  auto s8k = settings_for(request(8000));
  ASSERT_TRUE(s8k.ok());
  EXPECT_EQ(s8k->read_interval_ns, 2'000'000);  // 8 samples per read
  auto s100 = settings_for(request(100));
  ASSERT_TRUE(s100.ok());
  EXPECT_EQ(s100->read_interval_ns, 20'000'000);
}

TEST(OutputSettings, AGivenFilterSetsTheBaseRate) {
  OutputRequest r = request(1000);
  r.dlpf_hz = 256;  // off: 8 kHz / 8
  auto s = settings_for(r);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->dlpf_cfg, 0);
  EXPECT_EQ(s->smplrt_div, 7);
  r.dlpf_hz = 20;
  s = settings_for(r);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->dlpf_cfg, 4);
  EXPECT_EQ(s->smplrt_div, 0);
}

TEST(OutputSettings, RangesMapToTheirRegisterValues) {
  OutputRequest r = request(100);
  r.accel_full_scale_g = 4;
  r.gyro_full_scale_dps = 1000;
  r.bus = BusKind::kI2c;
  auto s = settings_for(r);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->accel_range, AccelRange::k4g);
  EXPECT_EQ(s->gyro_range, GyroRange::k1000dps);
  EXPECT_EQ(s->bus, BusKind::kI2c);
}

TEST(OutputSettings, WhatTheChipCannotDoIsRefusedWithTheReason) {
  auto odd = settings_for(request(300));
  ASSERT_FALSE(odd.ok());
  EXPECT_EQ(odd.error().code, Errc::kInvalidArgument);
  EXPECT_NE(odd.error().message.find("cannot produce 300 Hz"), std::string::npos) << odd.error().message;
  EXPECT_NE(odd.error().message.find("nearest: 296.296 or 307.692 Hz"), std::string::npos)
      << odd.error().message;

  OutputRequest filtered = request(2000);
  filtered.dlpf_hz = 98;  // 1 kHz base rate: 2 kHz impossible
  auto fast = settings_for(filtered);
  ASSERT_FALSE(fast.ok());
  EXPECT_NE(fast.error().message.find("DLPF on"), std::string::npos) << fast.error().message;

  OutputRequest bad_dlpf = request(100);
  bad_dlpf.dlpf_hz = 100;
  EXPECT_FALSE(settings_for(bad_dlpf).ok());
  OutputRequest bad_range = request(100);
  bad_range.accel_full_scale_g = 3;
  auto r = settings_for(bad_range);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("2, 4, 8 or 16 g"), std::string::npos);
  bad_range = request(100);
  bad_range.gyro_full_scale_dps = 300;
  EXPECT_FALSE(settings_for(bad_range).ok());
  EXPECT_FALSE(settings_for(request(0.0)).ok());
  EXPECT_FALSE(settings_for(request(-5.0)).ok());
  EXPECT_FALSE(settings_for(request(3.0)).ok());  // below 1000 / 256
}

}  // namespace
}  // namespace imucal::drivers::mpu6000
