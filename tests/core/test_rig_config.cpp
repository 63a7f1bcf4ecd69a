// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <Eigen/LU>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/rig_config.hpp"
#include "core/target.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using ::testing::HasSubstr;

TEST(RigConfig, ShippedSimRigLoads) {
  auto cfg = load_rig_config(test::source_path("config/rig.yaml"));
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  EXPECT_EQ(cfg->name, "sim");
  EXPECT_EQ(cfg->imu.bus, ImuBus::kSim);
  EXPECT_EQ(cfg->imu.device, "sim");
  ASSERT_EQ(cfg->cameras.size(), 1u);
  EXPECT_EQ(cfg->cameras[0].backend, CameraBackend::kSim);
  ASSERT_TRUE(cfg->target.has_value());
  // The target is a path relative to the config file.
  EXPECT_EQ(cfg->target->cols, 7);
  EXPECT_EQ(cfg->target->rows, 6);
  EXPECT_DOUBLE_EQ(cfg->target->col_spacing_m, 0.06);
  EXPECT_EQ(cfg->storage.backend, StorageBackend::kFile);
}

TEST(RigConfig, ShippedSpiExampleLoads) {
  auto cfg = load_rig_config(test::source_path("config/rig-spi-example.yaml"));
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  EXPECT_EQ(cfg->imu.bus, ImuBus::kSpi);
  EXPECT_EQ(cfg->imu.device, "/dev/spidev0.0");
  EXPECT_EQ(cfg->imu.spi_config_speed_hz, 1'000'000);
  EXPECT_EQ(cfg->imu.spi_data_speed_hz, 20'000'000);
  EXPECT_EQ(cfg->imu.accel_range_g, 8);
  EXPECT_EQ(cfg->imu.gyro_range_dps, 1000);
  EXPECT_EQ(cfg->imu.rate_hz, 500.0);
  EXPECT_EQ(cfg->imu.dlpf_hz, 188);
  ASSERT_TRUE(cfg->imu.data_ready.has_value());
  EXPECT_EQ(cfg->imu.data_ready->chip, "gpiochip0");
  EXPECT_EQ(cfg->imu.data_ready->line, 17);
  Eigen::Matrix3d expected;
  expected << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  EXPECT_TRUE(cfg->imu.R_rig_imu.isApprox(expected, 1e-15));
  EXPECT_EQ(cfg->cameras.at(0).device, "/dev/video0");
  EXPECT_EQ(cfg->storage.backend, StorageBackend::kNvmem);
  ASSERT_TRUE(cfg->target.has_value());
}

TEST(RigConfig, CheckerboardTargetFileIsKalibrYaml) {
  auto t = load_target_yaml(test::source_path("config/checkerboard-7x6.yaml"));
  ASSERT_TRUE(t.ok()) << t.error().message;
  EXPECT_EQ(t->type, TargetDescription::Type::kCheckerboard);
  EXPECT_EQ(t->cols, 7);
  EXPECT_EQ(t->rows, 6);
}

TEST(RigConfig, MinimalConfigGetsDefaults) {
  auto cfg = parse_rig_config("imu: {bus: i2c}\n", "min.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  EXPECT_EQ(cfg->name, "rig");
  EXPECT_EQ(cfg->imu.device, "/dev/i2c-1");
  EXPECT_EQ(cfg->imu.i2c_address, 0x68);
  EXPECT_EQ(cfg->imu.accel_range_g, 4);
  EXPECT_EQ(cfg->imu.gyro_range_dps, 500);
  EXPECT_EQ(cfg->imu.rate_hz, 200.0);
  EXPECT_EQ(cfg->imu.dlpf_hz, 98);
  EXPECT_FALSE(cfg->imu.data_ready.has_value());
  EXPECT_TRUE(cfg->imu.R_rig_imu.isIdentity());
  EXPECT_TRUE(cfg->cameras.empty());
  EXPECT_FALSE(cfg->target.has_value());
  EXPECT_EQ(cfg->storage.path, "/var/lib/imucal/calibration.bin");
}

TEST(RigConfig, HexAddressAndSpiDefaults) {
  auto i2c = parse_rig_config("imu: {bus: i2c, i2c_address: 0x69}\n");
  ASSERT_TRUE(i2c.ok()) << i2c.error().message;
  EXPECT_EQ(i2c->imu.i2c_address, 0x69);
  auto spi = parse_rig_config("imu: {bus: spi}\n");
  ASSERT_TRUE(spi.ok()) << spi.error().message;
  EXPECT_EQ(spi->imu.device, "/dev/spidev0.0");
  EXPECT_EQ(spi->imu.spi_config_speed_hz, 1'000'000);
  EXPECT_EQ(spi->imu.spi_data_speed_hz, 20'000'000);
}

TEST(RigConfig, RpyMountingIsZYX) {
  auto cfg = parse_rig_config("imu:\n  bus: sim\n  mounting: {rpy_deg: [0, 0, 90]}\n");
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  // Yaw +90 deg: the IMU's x axis points along the rig's y axis.
  const Eigen::Vector3d v = cfg->imu.R_rig_imu * Eigen::Vector3d::UnitX();
  EXPECT_TRUE(v.isApprox(Eigen::Vector3d::UnitY(), 1e-12)) << v.transpose();
  auto roll = parse_rig_config("imu:\n  bus: sim\n  mounting: {rpy_deg: [90, 0, 0]}\n");
  ASSERT_TRUE(roll.ok());
  EXPECT_TRUE((roll->imu.R_rig_imu * Eigen::Vector3d::UnitY()).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
}

TEST(RigConfig, MountingMatrixAcceptsFlatAndRows) {
  auto flat = parse_rig_config("imu:\n  bus: sim\n  mounting: {R_rig_imu: [0,-1,0, 1,0,0, 0,0,1]}\n");
  ASSERT_TRUE(flat.ok()) << flat.error().message;
  EXPECT_DOUBLE_EQ(flat->imu.R_rig_imu(0, 1), -1.0);
  EXPECT_DOUBLE_EQ(flat->imu.R_rig_imu(1, 0), 1.0);
  // Four-digit values are accepted and projected onto the nearest rotation.
  auto rounded = parse_rig_config(
      "imu:\n  bus: sim\n  mounting:\n    R_rig_imu: [[0.7071, -0.7071, 0], [0.7071, 0.7071, 0], [0, 0, "
      "1]]\n");
  ASSERT_TRUE(rounded.ok()) << rounded.error().message;
  const Eigen::Matrix3d& R = rounded->imu.R_rig_imu;
  EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_NEAR(R(0, 0), std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-14);
}

TEST(RigConfig, NormalizedYamlRoundTrips) {
  auto cfg = load_rig_config(test::source_path("config/rig-spi-example.yaml"));
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  const std::string yaml = rig_config_to_yaml(*cfg);
  auto again = parse_rig_config(yaml, "normalized.yaml");
  ASSERT_TRUE(again.ok()) << again.error().message << "\n" << yaml;
  EXPECT_EQ(rig_config_to_yaml(*again), yaml);
  EXPECT_EQ(again->imu.R_rig_imu, cfg->imu.R_rig_imu);
  EXPECT_EQ(again->storage.path, cfg->storage.path);
  EXPECT_TRUE(validate_rig_config(*cfg).ok());
  const std::string json = rig_config_to_json(*cfg);
  EXPECT_THAT(json, HasSubstr("\"spi_data_speed_hz\": 20000000"));
  EXPECT_THAT(json, HasSubstr("\"targetCols\": 7"));
}

TEST(RigConfig, ARollingShutterCameraKeepsItsShutterThroughTheNormalizedYaml) {
  auto c = parse_rig_config(
      "imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 752, height: 480, rate_hz: 20,\n"
      "     shutter: rolling, line_delay_us: 30, readout_direction: bottom_to_top, stamp_row: middle}\n"
      "  - {name: cam1, backend: v4l2, device: /dev/video0, width: 640, height: 480, rate_hz: 30, shutter: "
      "rolling}\n"
      "target: {target_type: checkerboard, targetCols: 7, targetRows: 6, rowSpacingMeters: 0.06, "
      "colSpacingMeters: 0.06}\n");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const Shutter& s = c->cameras[0].shutter;
  EXPECT_TRUE(s.rolling());
  EXPECT_DOUBLE_EQ(s.line_delay_s, 30e-6);
  EXPECT_EQ(s.readout, Shutter::Readout::kBottomToTop);
  EXPECT_EQ(s.stamp_row, Shutter::StampRow::kMiddle);
  EXPECT_TRUE(c->cameras[1].shutter.rolling());
  EXPECT_EQ(c->cameras[1].shutter.line_delay_s, 0.0);  // estimated by the session
  auto again = parse_rig_config(rig_config_to_yaml(*c));
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_DOUBLE_EQ(again->cameras[0].shutter.line_delay_s, 30e-6);
  EXPECT_EQ(again->cameras[0].shutter.stamp_row, Shutter::StampRow::kMiddle);
}

TEST(RigConfig, SidesNameTheRigsFrontLeftAndTop) {
  const std::string base = "name: r\nimu: {bus: sim}\n";
  auto c = parse_rig_config(base + "sides: {front: -y, left: +X, top: +z}\n");
  ASSERT_TRUE(c.ok()) << c.error().message;
  ASSERT_TRUE(c->sides.has_value());
  EXPECT_EQ(c->sides->front, -Eigen::Vector3d::UnitY());
  EXPECT_EQ(c->sides->left, Eigen::Vector3d::UnitX());
  EXPECT_EQ(c->sides->top, Eigen::Vector3d::UnitZ());
  for (const std::string& text : {rig_config_to_yaml(*c), rig_config_to_json(*c)}) {
    auto again = parse_rig_config(text);
    ASSERT_TRUE(again.ok()) << again.error().message << "\n" << text;
    ASSERT_TRUE(again->sides.has_value()) << text;
    EXPECT_EQ(again->sides->front, c->sides->front);
    EXPECT_EQ(again->sides->left, c->sides->left);
  }
  EXPECT_FALSE(parse_rig_config(base)->sides.has_value());
  EXPECT_EQ(rig_config_to_yaml(*parse_rig_config(base)).find("sides"), std::string::npos);
  // Mistakes are named.
  auto mirrored = parse_rig_config(base + "sides: {front: +x, left: -y, top: +z}\n");
  ASSERT_FALSE(mirrored.ok());
  EXPECT_THAT(mirrored.error().message, HasSubstr("front x left is not top"));
  auto same = parse_rig_config(base + "sides: {front: +x, left: -x, top: +z}\n");
  ASSERT_FALSE(same.ok());
  EXPECT_THAT(same.error().message, HasSubstr("three different axes"));
  auto word = parse_rig_config(base + "sides: {front: forward, left: +y, top: +z}\n");
  ASSERT_FALSE(word.ok());
  EXPECT_THAT(word.error().message, HasSubstr("sides.front: 'forward' is not a rig axis"));
  auto missing = parse_rig_config(base + "sides: {front: +x, left: +y}\n");
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.error().message, HasSubstr("sides.top: missing"));
}

TEST(RigConfig, ValidateCatchesCodeBuiltMistakes) {
  RigConfig cfg;
  EXPECT_TRUE(validate_rig_config(cfg).ok());
  cfg.imu.accel_range_g = 3;
  auto s = validate_rig_config(cfg);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.error().message, HasSubstr("imu.accel_range_g"));
}

struct InvalidCase {
  const char* yaml;
  const char* key_path;  // must appear in the message
  int line;              // 1-based line the message must name
  const char* hint;      // what is allowed / wrong, must appear in the message
};

class RigConfigInvalid : public ::testing::TestWithParam<InvalidCase> {};

// yaml-cpp 0.7's LoadAll never returns on this (it grows a list of null documents until memory
// runs out); found by the rig_config fuzz target.
TEST(RigConfig, TextAfterTheDocumentThatYamlCannotReadIsRefused) {
  auto cfg = parse_rig_config(", one simulated\n", "comma.yaml");
  ASSERT_FALSE(cfg.ok());
  EXPECT_THAT(cfg.error().message,
              HasSubstr("comma.yaml:1: a second YAML document ('---'), or text after the "
                        "first that YAML cannot read"));
  auto after_map = parse_rig_config("imu: {bus: sim}\n, one simulated\n", "comma.yaml");
  ASSERT_FALSE(after_map.ok());
  EXPECT_THAT(after_map.error().message, HasSubstr("comma.yaml:2: not valid YAML"));
}

TEST(RigConfig, ASecondYamlDocumentIsRefused) {
  auto cfg = parse_rig_config("imu: {bus: sim}\n---\nimu: {bus: spi}\n", "two.yaml");
  ASSERT_FALSE(cfg.ok());
  EXPECT_THAT(cfg.error().message, HasSubstr("two.yaml:2: a second YAML document")) << cfg.error().message;
}

TEST_P(RigConfigInvalid, NamesFileLineKeyAndWhatIsAllowed) {
  const InvalidCase& c = GetParam();
  auto cfg = parse_rig_config(c.yaml, "bad.yaml");
  ASSERT_FALSE(cfg.ok()) << c.yaml;
  const std::string& msg = cfg.error().message;
  EXPECT_EQ(cfg.error().code, Errc::kInvalidArgument);
  EXPECT_THAT(msg, HasSubstr("bad.yaml:" + std::to_string(c.line) + ":")) << msg;
  EXPECT_THAT(msg, HasSubstr(std::string(c.key_path) + ":")) << msg;
  EXPECT_THAT(msg, HasSubstr(c.hint)) << msg;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, RigConfigInvalid,
    ::testing::Values(
        InvalidCase{"imu:\n  bus: usb\n", "imu.bus", 2, "spi, i2c or sim"},
        InvalidCase{"name: x\n", "imu", 1, "missing"},
        InvalidCase{"imu:\n  bus: sim\n  accel_range_g: 3\n", "imu.accel_range_g", 3, "2, 4, 8, 16"},
        InvalidCase{"imu:\n  bus: sim\n  gyro_range_dps: 300\n", "imu.gyro_range_dps", 3,
                    "250, 500, 1000, 2000"},
        InvalidCase{"imu:\n  bus: sim\n  dlpf_hz: 100\n", "imu.dlpf_hz", 3, "256, 188, 98"},
        InvalidCase{"imu:\n  bus: sim\n  rate_hz: 300\n", "imu.rate_hz", 3, "1000 / N"},
        InvalidCase{"imu:\n  bus: sim\n  rate_hz: fast\n", "imu.rate_hz", 3, "not a finite number"},
        InvalidCase{"imu:\n  bus: i2c\n  i2c_address: 0x70\n", "imu.i2c_address", 3, "0x68"},
        InvalidCase{"imu:\n  bus: i2c\n  spi_data_speed_hz: 1000000\n", "imu.spi_data_speed_hz", 3,
                    "only to bus: spi"},
        InvalidCase{"imu:\n  bus: spi\n  spi_data_speed_hz: 40000000\n", "imu.spi_data_speed_hz", 3,
                    "20 MHz"},
        InvalidCase{"imu:\n  bus: spi\n  spi_config_speed_hz: 20000000\n", "imu.spi_config_speed_hz", 3,
                    "1 MHz"},
        InvalidCase{"imu:\n  bus: spi\n  device: spidev0.0\n", "imu.device", 3, "not a device path"},
        InvalidCase{"imu:\n  bus: sim\n  acel_range_g: 4\n", "imu.acel_range_g", 3,
                    "did you mean 'accel_range_g'"},
        InvalidCase{"imu: {bus: sim}\ncamras: []\n", "camras", 2, "unknown key"},
        InvalidCase{"imu:\n  bus: sim\n  rate_hz: 200\n  rate_hz: 100\n", "imu.rate_hz", 4, "given twice"},
        InvalidCase{"imu: {bus: sim}\nname: a\nname: b\n", "name", 3, "given twice"},
        InvalidCase{"imu:\n  bus: sim\n  data_ready: {chip: gpiochip0}\n", "imu.data_ready.line", 3,
                    "missing"},
        InvalidCase{"imu:\n  bus: sim\n  mounting:\n    R_rig_imu: [[1,0,0],[0,1,0],[0,0.5,1]]\n",
                    "imu.mounting.R_rig_imu", 4, "not orthonormal"},
        InvalidCase{"imu:\n  bus: sim\n  mounting:\n    R_rig_imu: [[1,0,0],[0,1,0],[0,0,-1]]\n",
                    "imu.mounting.R_rig_imu", 4, "reflection"},
        InvalidCase{"imu:\n  bus: sim\n  mounting:\n    rpy_deg: [1, 2]\n", "imu.mounting.rpy_deg", 4,
                    "roll, pitch, yaw"},
        InvalidCase{
            "imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: usb, width: 640, height: 480, rate_hz: "
            "20}\n"
            "target: {target_type: checkerboard, targetCols: 7, targetRows: 6, rowSpacingMeters: 0.06, "
            "colSpacingMeters: 0.06}\n",
            "cameras[0].backend", 3, "v4l2, libcamera, aravis or sim"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: v4l2, width: 640, height: 480, "
                    "rate_hz: 20}\n",
                    "cameras[0].device", 3, "/dev/video0"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 0, height: 480, "
                    "rate_hz: 20}\n",
                    "cameras[0].width", 3, "16..16384"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480}\n",
                    "cameras[0].rate_hz", 3, "missing"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
                    "rate_hz: 20, pixel_format: GRAY8}\n",
                    "cameras[0].pixel_format", 3, "fourcc"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
                    "rate_hz: 20, shutter: slit}\n",
                    "cameras[0].shutter", 3, "global or rolling"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
                    "rate_hz: 20, line_delay_us: 30}\n",
                    "cameras[0].line_delay_us", 3, "add shutter: rolling"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
                    "rate_hz: 20, shutter: rolling}\n",
                    "cameras[0].line_delay_us", 3, "line delay > 0"},
        InvalidCase{
            "imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
            "rate_hz: 20}\n  - {name: cam0, backend: sim, width: 640, height: 480, rate_hz: 20}\n"
            "target: {target_type: checkerboard, targetCols: 7, targetRows: 6, rowSpacingMeters: 0.06, "
            "colSpacingMeters: 0.06}\n",
            "cameras[1].name", 4, "used by another camera"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
                    "rate_hz: 20}\n",
                    "target", 1, "calibration target is needed"},
        InvalidCase{
            "imu: {bus: sim}\ntarget:\n  target_type: checkerboard\n  targetCols: 1\n  targetRows: 6\n"
            "  rowSpacingMeters: 0.06\n  colSpacingMeters: 0.06\n",
            "target", 3, "2x2 inner corners"},
        InvalidCase{"imu: {bus: sim}\ntarget: {target_type: checkerboard, targetCol: 7}\n",
                    "target.targetCol", 2, "did you mean 'targetCols'"},
        InvalidCase{"imu: {bus: sim}\ntarget: no-such-target.yaml\n", "target", 2,
                    "target file: cannot open"},
        InvalidCase{"imu: {bus: sim}\nstorage:\n  backend: flash\n", "storage.backend", 3,
                    "file, nvmem or i2c-eeprom"},
        InvalidCase{"imu: {bus: sim}\nstorage:\n  backend: nvmem\n", "storage.path", 3, "missing"},
        InvalidCase{"imu: {bus: sim}\nstorage:\n  backend: i2c-eeprom\n  i2c_device: /dev/i2c-1\n"
                    "  i2c_address: 0x68\n",
                    "storage.i2c_address", 5, "0x50..0x57"},
        InvalidCase{"imu: {bus: sim}\nstorage:\n  backend: file\n  i2c_address: 0x50\n",
                    "storage.i2c_address", 4, "only to backend: i2c-eeprom"},
        InvalidCase{"imu: {bus: sim}\nstorage:\n  backend: file\n  size_bytes: 16\n", "storage.size_bytes", 4,
                    "256..16777216"},
        InvalidCase{"imu:\n  bus: sim\n  accel_range_g: [4]\n", "imu.accel_range_g", 3,
                    "expected an integer"},
        InvalidCase{"imu:\n  bus: sim\n  accel_range_g: 010\n", "imu.accel_range_g", 3, "not allowed"},
        InvalidCase{"imu:\n  bus: i2c\n  driver: kernel\n", "imu.driver", 3,
                    "iio: the kernel's inv-mpu6050 driver"},
        InvalidCase{"imu:\n  bus: sim\n  driver: iio\n", "imu.driver", 3, "needs a hardware bus"},
        InvalidCase{"imu:\n  bus: i2c\n  driver: direct\n  iio_device: iio:device0\n", "imu.iio_device", 4,
                    "only to driver: iio or auto"},
        InvalidCase{"imu:\n  bus: i2c\n  iio_device: mpu6050\n", "imu.iio_device", 3, "not an IIO device"},
        InvalidCase{"imu:\n  bus: i2c\n  driver: iio\n  data_ready: {chip: gpiochip0, line: 3}\n",
                    "imu.data_ready", 4, "kernel owns the chip's interrupt"},
        InvalidCase{"imu: {bus: sim}\ncameras:\n  - {name: cam0, backend: sim, width: 640, height: 480, "
                    "rate_hz: 0}\n",
                    "cameras[0].rate_hz", 3, "must be > 0"}));

// imu.driver and imu.iio_device; a hardware camera's rate 0 (its own rate).
TEST(RigConfig, TheKernelsDriverAndACamerasOwnRate) {
  auto cfg = parse_rig_config(
      "imu: {bus: i2c, device: /dev/i2c-1, driver: iio, iio_device: iio:device2}\n"
      "cameras:\n  - {name: cam0, backend: libcamera, device: 'platform/vimc.0 Sensor B', width: 636, "
      "height: 480, rate_hz: 0}\n"
      "target: {target_type: checkerboard, targetCols: 7, targetRows: 6, rowSpacingMeters: 0.06, "
      "colSpacingMeters: 0.06}\n",
      "iio.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  EXPECT_EQ(cfg->imu.driver, ImuDriver::kIio);
  EXPECT_EQ(cfg->imu.iio_device, "iio:device2");
  EXPECT_EQ(cfg->cameras[0].rate_hz, 0.0);
  auto again = parse_rig_config(rig_config_to_yaml(*cfg), "again.yaml");
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(again->imu.driver, ImuDriver::kIio);
  EXPECT_EQ(again->imu.iio_device, "iio:device2");
  EXPECT_THAT(rig_config_to_json(*cfg), HasSubstr("\"driver\": \"iio\""));
  auto defaults = parse_rig_config("imu: {bus: spi}\n", "d.yaml");
  ASSERT_TRUE(defaults.ok());
  EXPECT_EQ(defaults->imu.driver, ImuDriver::kAuto);
}

TEST(RigConfig, YamlSyntaxErrorNamesLine) {
  auto cfg = parse_rig_config("imu:\n  bus: sim\n  rate_hz: [200\n", "broken.yaml");
  ASSERT_FALSE(cfg.ok());
  EXPECT_THAT(cfg.error().message, HasSubstr("broken.yaml:"));
  EXPECT_THAT(cfg.error().message, HasSubstr("not valid YAML"));
}

// A target path that is no file a person writes: never read (a FIFO would block, /dev/zero
// never ends), refused with the reason.
TEST(RigConfig, ATargetThatIsNotARegularFileIsRefusedAtOnce) {
  const std::string dir = test::scratch_dir();
  ASSERT_EQ(mkfifo((dir + "/fifo.yaml").c_str(), 0600), 0);
  for (const std::string& target : {std::string("/dev/zero"), dir + "/fifo.yaml"}) {
    auto cfg = parse_rig_config("imu: {bus: sim}\ntarget: " + target + "\n", "rig.yaml");
    ASSERT_FALSE(cfg.ok()) << target;
    EXPECT_THAT(cfg.error().message, HasSubstr("is not a regular file")) << cfg.error().message;
  }
  std::ofstream(dir + "/huge.yaml") << std::string(2 << 20, '#');
  auto huge = load_target_yaml(dir + "/huge.yaml");
  ASSERT_FALSE(huge.ok());
  EXPECT_THAT(huge.error().message, HasSubstr("more than such a file can be")) << huge.error().message;
  auto fifo_config = load_rig_config(dir + "/fifo.yaml");
  ASSERT_FALSE(fifo_config.ok());
  EXPECT_THAT(fifo_config.error().message, HasSubstr("is not a regular file"));
}

// Strings that JSON output and the control socket could not carry are refused where they are
// read, and messages show invisible or invalid bytes instead of passing them on.
TEST(RigConfig, TextThatIsNotUtf8OrNestedTooDeeplyIsRefusedReadably) {
  auto bad = parse_rig_config("imu: {bus: spi, device: \"/dev/spi\xff\"}\n", "u.yaml");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, HasSubstr("u.yaml:1: imu.device: '/dev/spi\\xFF' is not UTF-8 text"));
  auto bom = parse_rig_config("name: \"rig\xef\xbb\xbf\"\nimu: {bus: sim}\n", "b.yaml");
  ASSERT_FALSE(bom.ok());
  EXPECT_THAT(bom.error().message, HasSubstr("'rig\\xEF\\xBB\\xBF' is not allowed")) << bom.error().message;
  auto deep =
      parse_rig_config("imu: " + std::string(100000, '[') + std::string(100000, ']') + "\n", "d.yaml");
  ASSERT_FALSE(deep.ok());
  EXPECT_THAT(deep.error().message, HasSubstr("levels deep: not a rig configuration"));
  auto long_number =
      parse_rig_config("imu:\n  bus: sim\n  rate_hz: " + std::string(5000, '9') + "x\n", "n.yaml");
  ASSERT_FALSE(long_number.ok());
  EXPECT_LT(long_number.error().message.size(), 200u) << long_number.error().message;
}

TEST(RigConfig, MissingFileIsNotFound) {
  auto cfg = load_rig_config(test::scratch_dir() + "/nope.yaml");
  ASSERT_FALSE(cfg.ok());
  EXPECT_EQ(cfg.error().code, Errc::kNotFound);
  EXPECT_THAT(cfg.error().message, HasSubstr("nope.yaml"));
}

TEST(RigConfig, TargetPathIsRelativeToConfigFile) {
  const std::string dir = test::scratch_dir();
  std::filesystem::create_directories(dir + "/sub/targets");
  std::ofstream(dir + "/sub/targets/board.yaml")
      << "target_type: checkerboard\ntargetCols: 5\ntargetRows: 4\nrowSpacingMeters: 0.03\n"
         "colSpacingMeters: 0.03\n";
  std::ofstream(dir + "/sub/rig.yaml") << "imu: {bus: sim}\ntarget: targets/board.yaml\n";
  auto cfg = load_rig_config(dir + "/sub/rig.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  ASSERT_TRUE(cfg->target.has_value());
  EXPECT_EQ(cfg->target->cols, 5);
  EXPECT_DOUBLE_EQ(cfg->target->row_spacing_m, 0.03);
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(RigConfig, SessionSectionParsesAndRoundTrips) {
  auto c = parse_rig_config(
      "imu: {bus: sim}\n"
      "session:\n"
      "  steps: [preflight, still, poses, solve]\n"
      "  still_s: 20\n"
      "  poses: 24\n"
      "  poses_min: 10\n"
      "  auto_write: true\n");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->session.steps, (std::vector<std::string>{"preflight", "still", "poses", "solve"}));
  EXPECT_DOUBLE_EQ(c->session.still_s, 20.0);
  EXPECT_EQ(c->session.poses, 24);
  EXPECT_EQ(c->session.poses_min, 10);
  EXPECT_TRUE(c->session.auto_write);
  auto again = parse_rig_config(rig_config_to_yaml(*c));
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(again->session.steps, c->session.steps);
  EXPECT_DOUBLE_EQ(again->session.still_s, 20.0);
  EXPECT_TRUE(again->session.auto_write);
  auto from_json = parse_rig_config(rig_config_to_json(*c));
  ASSERT_TRUE(from_json.ok()) << from_json.error().message;
  EXPECT_EQ(from_json->session.poses, 24);
}

TEST(RigConfig, SessionSectionRefusesWhatCannotRun) {
  const char* bad[][2] = {
      {"session: {steps: [poses, still]}", "out of protocol order"},
      {"session: {steps: [calibrate]}", "is not a step"},
      {"session: {still_s: 0}", "session.still_s"},
      {"session: {poses: 5}", "at least 9"},
      {"session: {poses: 12, poses_min: 15}", "above session.poses"},
      {"session: {auto_write: yes please}", "true or false"},
      {"session: {hold: 2}", "unknown key"},
  };
  for (const auto& [yaml, fragment] : bad) {
    auto c = parse_rig_config(std::string("imu: {bus: sim}\n") + yaml + "\n");
    ASSERT_FALSE(c.ok()) << yaml;
    EXPECT_NE(c.error().message.find(fragment), std::string::npos) << yaml << " -> " << c.error().message;
  }
}

TEST(RigConfig, TheLiveViewIsOffUnlessEnabledAndRoundTrips) {
  auto base = load_rig_config(test::source_path("config/rig.yaml"));
  ASSERT_TRUE(base.ok()) << base.error().message;
  EXPECT_FALSE(base->live_view.enabled);
  EXPECT_EQ(base->live_view.address, "127.0.0.1");
  EXPECT_EQ(base->live_view.port, 8421);
  const std::string text =
      "imu:\n  bus: sim\nlive_view:\n  enabled: true\n  address: 0.0.0.0\n  port: 9000\n"
      "  frame_rate_hz: 2.5\n  width: 640\n";
  auto c = parse_rig_config(text);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_TRUE(c->live_view.enabled);
  EXPECT_EQ(c->live_view.address, "0.0.0.0");
  EXPECT_EQ(c->live_view.port, 9000);
  EXPECT_DOUBLE_EQ(c->live_view.frame_rate_hz, 2.5);
  EXPECT_EQ(c->live_view.width, 640);
  auto again = parse_rig_config(rig_config_to_yaml(*c));
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(again->live_view.port, 9000);
  EXPECT_TRUE(again->live_view.enabled);
  const auto j = nlohmann::json::parse(rig_config_to_json(*c));
  EXPECT_EQ(j["live_view"]["address"], "0.0.0.0");
  EXPECT_EQ(j["live_view"]["port"], 9000);
  for (const auto& [bad, says] :
       std::vector<std::pair<std::string, std::string>>{{"  enabled: yes please\n", "live_view.enabled"},
                                                        {"  address: my-laptop\n", "not an IP address"},
                                                        {"  port: 0\n", "live_view.port"},
                                                        {"  port: 70000\n", "live_view.port"},
                                                        {"  frame_rate_hz: 100\n", "live_view.frame_rate_hz"},
                                                        {"  width: 10\n", "live_view.width"},
                                                        {"  colour: blue\n", "colour"}}) {
    auto r = parse_rig_config("imu:\n  bus: sim\nlive_view:\n" + bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.error().message.find(says), std::string::npos) << r.error().message;
  }
}

TEST(RigConfig, ProgramGyroOffsetsIsABooleanOfTheStorage) {
  auto c = parse_rig_config(
      "imu: {bus: sim}\nstorage: {backend: file, path: /tmp/x.bin, program_gyro_offsets: true}\n");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_TRUE(c->storage.program_gyro_offsets);
  auto again = parse_rig_config(rig_config_to_yaml(*c));
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_TRUE(again->storage.program_gyro_offsets);
  auto from_json = parse_rig_config(rig_config_to_json(*c));
  ASSERT_TRUE(from_json.ok()) << from_json.error().message;
  EXPECT_TRUE(from_json->storage.program_gyro_offsets);
  auto off = parse_rig_config("imu: {bus: sim}\nstorage: {backend: file, path: /tmp/x.bin}\n");
  ASSERT_TRUE(off.ok());
  EXPECT_FALSE(off->storage.program_gyro_offsets);
  auto bad = parse_rig_config(
      "imu: {bus: sim}\nstorage: {backend: file, path: /tmp/x.bin, program_gyro_offsets: 1}\n");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("storage.program_gyro_offsets"), std::string::npos)
      << bad.error().message;
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(Target, SizesNoImageCanHoldAreRefusedWithTheReason) {
  auto huge = parse_target_yaml(
      "target_type: checkerboard\ntargetCols: 100000\ntargetRows: 100000\nrowSpacingMeters: 0.01\n"
      "colSpacingMeters: 0.01\n",
      "huge.yaml");
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.error().message.find("100000 x 100000"), std::string::npos) << huge.error().message;
  EXPECT_NE(huge.error().message.find("at most 256"), std::string::npos) << huge.error().message;
  auto grid = parse_target_yaml(
      "target_type: aprilgrid\ntagCols: 30\ntagRows: 20\ntagSize: 0.02\ntagSpacing: 0.3\n", "grid.yaml");
  ASSERT_FALSE(grid.ok());
  EXPECT_NE(grid.error().message.find("tag36h11"), std::string::npos) << grid.error().message;
  // The largest that can exist still pass.
  EXPECT_TRUE(parse_target_yaml("target_type: checkerboard\ntargetCols: 256\ntargetRows: 256\n"
                                "rowSpacingMeters: 0.01\ncolSpacingMeters: 0.01\n",
                                "big.yaml")
                  .ok());
  EXPECT_TRUE(
      parse_target_yaml("target_type: aprilgrid\ntagCols: 29\ntagRows: 20\ntagSize: 0.02\ntagSpacing: 0.3\n",
                        "grid.yaml")
          .ok());
}

}  // namespace
}  // namespace imucal
