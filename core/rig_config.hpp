// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Rig configuration: which IMU bus and settings, which cameras, which calibration target, where
// the calibration is stored. Read from YAML (docs/config.md lists every key and its default).
// Loading validates every field; unknown keys are errors, so typos do not pass silently. An
// error names the file, the line, the key path (e.g. "imu.accel_range_g"), what is wrong and
// what is allowed.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "core/camera_model.hpp"
#include "core/result.hpp"
#include "core/target.hpp"

namespace imucal {

enum class ImuBus { kSpi, kI2c, kSim };
const char* imu_bus_name(ImuBus bus);

/// Who reads the chip: imucal's own driver through spidev / i2c-dev ("direct"), the kernel's
/// inv-mpu6050 IIO driver ("iio"), or the kernel's when it owns the configured chip ("auto").
enum class ImuDriver { kDirect, kIio, kAuto };
const char* imu_driver_name(ImuDriver driver);

/// A GPIO line (libgpiod): chip name or path ("gpiochip0", "/dev/gpiochip0") and line offset.
struct GpioLineConfig {
  std::string chip;
  int line = 0;
};

/// MPU-6000 settings.
struct ImuConfig {
  ImuBus bus = ImuBus::kSim;
  /// spidev or i2c-dev node; "sim" for the simulated rig. With the kernel's driver it names the
  /// bus the chip hangs on (the IIO device bound to it is used).
  std::string device = "sim";
  ImuDriver driver = ImuDriver::kAuto;
  /// The IIO device to use ("iio:device0"); empty: the inv-mpu6050 device bound to `device`.
  std::string iio_device;
  /// I2C only: 0x68 (AD0 low) or 0x69 (AD0 high).
  int i2c_address = 0x68;
  /// SPI only. The MPU-6000 accepts at most 1 MHz for register access and 20 MHz for reading
  /// the sensor and interrupt registers (datasheet section 6.5 / register map p. 46).
  int spi_config_speed_hz = 1'000'000;
  int spi_data_speed_hz = 20'000'000;
  int accel_range_g = 4;                     // 2, 4, 8, 16
  int gyro_range_dps = 500;                  // 250, 500, 1000, 2000
  double rate_hz = 200.0;                    // output rate: base / (1 + SMPLRT_DIV), base 8 kHz or 1 kHz
  int dlpf_hz = 98;                          // gyro bandwidth of a DLPF_CFG setting: 256,188,98,42,20,10,5
  std::optional<GpioLineConfig> data_ready;  // absent: poll the FIFO
  /// Mounting: rotates IMU-frame vectors into the rig frame (v_rig = R_rig_imu * v_imu).
  Eigen::Matrix3d R_rig_imu = Eigen::Matrix3d::Identity();
};

enum class CameraBackend { kV4l2, kLibcamera, kAravis, kSim };
const char* camera_backend_name(CameraBackend backend);

struct CameraConfig {
  std::string name;  // unique among the rig's cameras, e.g. "cam0"
  CameraBackend backend = CameraBackend::kSim;
  std::string device;  // /dev/videoN (v4l2), camera id (libcamera, aravis), "sim"
  int width = 0;
  int height = 0;
  double rate_hz = 0.0;
  std::string pixel_format;  // V4L2 fourcc ("GREY", "YUYV") or GenICam name ("Mono8")
  /// The shutter as the integrator knows it (docs/config.md): global (the default) or rolling,
  /// with the readout direction, the row the stamps mark and, when known (a datasheet, the sensor
  /// mode), the line delay: the session then holds it; 0 = rolling with the line delay estimated.
  Shutter shutter;
};

enum class StorageBackend { kFile, kNvmem, kI2cEeprom };
const char* storage_backend_name(StorageBackend backend);

/// Where the accepted calibration record lives on the rig.
struct StorageConfig {
  StorageBackend backend = StorageBackend::kFile;
  std::string path = "/var/lib/imucal/calibration.bin";  // file / nvmem: the file to use
  std::string i2c_device;                                // i2c-eeprom: the i2c-dev node
  int i2c_address = 0x50;                                // i2c-eeprom: 0x50..0x57
  int page_bytes = 32;    // i2c-eeprom: the chip's write page (24c01/02: 8, 24c04..16: 16, 24c32/64: 32)
  int address_bytes = 2;  // i2c-eeprom: word address width, 1 (24c01..24c16) or 2 (24c32 and larger)
  int size_bytes = 4096;  // bytes available to imucal (both A/B slots)
  int offset_bytes = 0;   // where imucal's region starts inside the device
  /// imucald puts the stored gyro bias into the MPU-6000's gyro offset registers (cleared while a
  /// session records the chip as it powers up); docs/storage.md.
  bool program_gyro_offsets = false;
};

/// The service's guided session (imucald, docs/service-session.md): which steps run and their
/// thresholds. Every field is optional in the file; these defaults apply.
struct SessionConfig {
  /// Steps in protocol order; empty: every step that applies (gsens is opt-in, motion needs
  /// cameras, thermal is opt-in). Names: preflight, warmup, thermal, still, poses, gsens, motion,
  /// solve, review, write.
  std::vector<std::string> steps;
  double warmup_rate_c_per_min = 0.3;   // warm when the die temperature changes slower than this
  double warmup_window_s = 15.0;        // over this window
  double warmup_timeout_s = 900.0;      // then the step fails (or is skipped by the operator)
  double thermal_min_span_c = 3.0;      // thermal: the die must move this much for a model
  double thermal_timeout_s = 3600.0;    // thermal: the recording ends here at the latest
  double still_s = 10.0;                // initial still period (the gyro bias, T_init)
  double hold_s = 2.0;                  // a pose is captured after this long still
  double still_gyro_dps = 2.0;          // still: gyro mean (bias removed) below this, deg/s
  double still_accel_mps2 = 0.2;        // still: accelerometer std over 0.5 s below this, m/s^2
  double pose_min_angle_deg = 20.0;     // a pose this close to an earlier one is refused
  int poses = 18;                       // the step ends at this count once the sigma target is met
  int poses_min = 12;                   // the operator may end the step from here
  double pose_sigma_target = 1.5e-3;    // largest scale-factor sigma (relative) to end the step
  double gsens_hold_s = 8.0;            // each six-face hold
  double motion_s = 60.0;               // checkerboard motion
  double gate_gravity_rms_mps2 = 0.05;  // review gate: gravity-magnitude residual RMS
  double gate_scale_sigma = 3e-3;       // review gate: largest scale-factor sigma
  double gate_reprojection_px = 1.0;    // review gate: camera-IMU reprojection RMS
  double operator_wait_s = 1800.0;      // a session waiting this long for a key it needs ends
  bool auto_write = false;              // write without the operator's accept when every gate passes
};

/// The live view (imucald serves the session to a web browser, docs/service.md "Live view"): off
/// unless enabled; on the loopback address unless another is given. Watching is open to whoever
/// reaches the address; the keys need the token imucald writes to its state folder.
struct LiveViewConfig {
  bool enabled = false;
  std::string address = "127.0.0.1";  // an IPv4 or IPv6 address to bind; 0.0.0.0 for every interface
  int port = 8421;
  double frame_rate_hz = 4.0;  // each camera's frames sent to the page, at most this often
  int width = 320;             // a frame is shrunk by a whole factor to at most this many columns
};

/// Names of the session's steps in protocol order.
const std::vector<std::string>& session_step_names();

/// The rig's named sides as signed axes of the rig frame (each a unit vector along x, y or z),
/// for the operator's guidance ("put the rig on its left side"). front x left = top.
struct RigSides {
  Eigen::Vector3d front = Eigen::Vector3d::UnitX();
  Eigen::Vector3d left = Eigen::Vector3d::UnitY();
  Eigen::Vector3d top = Eigen::Vector3d::UnitZ();
};

struct RigConfig {
  std::string name = "rig";
  ImuConfig imu;
  std::optional<RigSides> sides;  // absent: guidance names the IMU's axes
  std::vector<CameraConfig> cameras;
  std::optional<TargetDescription> target;  // required when cameras are configured
  StorageConfig storage;
  SessionConfig session;
  LiveViewConfig live_view;
};

/// MPU-6000 DLPF bandwidths (gyro, Hz) indexed by DLPF_CFG 0..6.
inline constexpr int kMpu6000DlpfHz[] = {256, 188, 98, 42, 20, 10, 5};

/// Parses rig configuration YAML. `source` names the file in errors; `base_dir` resolves a
/// target given as a relative path.
[[nodiscard]] Result<RigConfig> parse_rig_config(const std::string& text,
                                                 const std::string& source = "<config>",
                                                 const std::string& base_dir = ".");
/// Reads and parses a configuration file; a relative target path is relative to the file.
[[nodiscard]] Result<RigConfig> load_rig_config(const std::string& path);

/// Checks the cross-field rules on a configuration built in code (parsing already does).
[[nodiscard]] Status validate_rig_config(const RigConfig& config);

/// Normalized forms: every key with its value, defaults filled in, target inline. The YAML
/// form parses back to the same configuration.
std::string rig_config_to_yaml(const RigConfig& config);
std::string rig_config_to_json(const RigConfig& config);

}  // namespace imucal
