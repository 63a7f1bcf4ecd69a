// SPDX-License-Identifier: BSD-3-Clause
// Hardware rig assembly from a configuration, without hardware: settings, mounting, metadata
// and the errors of a rig whose devices are missing.

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "app/rig/rig.hpp"

namespace imucal::app {
namespace {

ImuConfig spi_imu(double rate_hz, int dlpf_hz) {
  ImuConfig imu;
  imu.bus = ImuBus::kSpi;
  imu.device = "/dev/spidev-imucal-test-missing";
  imu.rate_hz = rate_hz;
  imu.dlpf_hz = dlpf_hz;
  imu.accel_range_g = 8;
  imu.gyro_range_dps = 1000;
  return imu;
}

TEST(DriverSettings, DividerRangesAndBus) {
  auto s = driver_settings(spi_imu(500, 188));
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->smplrt_div, 1);  // 1 kHz / (1 + 1)
  EXPECT_EQ(s->accel_range, drivers::mpu6000::AccelRange::k8g);
  EXPECT_EQ(s->gyro_range, drivers::mpu6000::GyroRange::k1000dps);
  EXPECT_EQ(s->bus, drivers::mpu6000::BusKind::kSpi);

  auto s200 = driver_settings(spi_imu(200, 98));
  ASSERT_TRUE(s200.ok());
  EXPECT_EQ(s200->smplrt_div, 4);

  EXPECT_FALSE(driver_settings(spi_imu(3, 188)).ok());
}

TEST(RecordOptions, CarryTheConfigurationAndSource) {
  RigConfig config;
  config.imu = spi_imu(200, 98);
  const acq::RecordOptions ro = record_options(config, false);
  ASSERT_EQ(ro.metadata.size(), 2u);
  EXPECT_EQ(ro.metadata[0].first, "rig_config");
  EXPECT_TRUE(nlohmann::json::accept(ro.metadata[0].second));
  EXPECT_EQ(ro.metadata[1], (std::pair<std::string, std::string>("source", "hardware")));
  EXPECT_EQ(record_options(config, true).metadata[1].second, "sim");
}

TEST(OpenImuRig, MissingSpiDeviceSaysWhichPart) {
  RigConfig config;
  config.imu = spi_imu(200, 98);
  auto rig = open_imu_rig(config);
  ASSERT_FALSE(rig.ok());
  EXPECT_TRUE(rig.error().code == Errc::kNotFound || rig.error().code == Errc::kDevice)
      << rig.error().message;
  EXPECT_EQ(rig.error().message.rfind("opening the IMU bus: ", 0), 0u) << rig.error().message;
  EXPECT_NE(rig.error().message.find("/dev/spidev-imucal-test-missing"), std::string::npos);
}

TEST(OpenImuRig, MissingI2cDevice) {
  RigConfig config;
  config.imu = spi_imu(200, 98);
  config.imu.bus = ImuBus::kI2c;
  config.imu.device = "/dev/i2c-imucal-test-missing";
  auto rig = open_imu_rig(config);
  ASSERT_FALSE(rig.ok());
  EXPECT_TRUE(rig.error().code == Errc::kNotFound || rig.error().code == Errc::kDevice)
      << rig.error().message;
  EXPECT_NE(rig.error().message.find("/dev/i2c-imucal-test-missing"), std::string::npos);
}

TEST(OpenImuRig, SimulatedBusIsNotHardware) {
  RigConfig config;  // imu.bus sim
  auto rig = open_imu_rig(config);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.error().code, Errc::kInvalidArgument);
}

}  // namespace
}  // namespace imucal::app
