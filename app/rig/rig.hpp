// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The hardware IMU rig assembled from its configuration: either imucal's own driver (the bus,
// spidev or i2c-dev, the data-ready line through libgpiod when configured, the MPU-6000 driver
// with the configured output settings) or the kernel's inv-mpu6050 IIO driver when it owns the
// chip (imu.driver: iio, or auto and an IIO device bound to the configured bus), with
// CLOCK_MONOTONIC and the acquisition with the configured mounting. Shared by `imucal record`
// and the rig service. The simulated rig is assembled in sim/, not here.

#include <memory>
#include <string>

#include "acquisition/iio_acquisition.hpp"
#include "acquisition/imu_acquisition.hpp"
#include "acquisition/mounting.hpp"
#include "acquisition/recorder.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/bus/register_bus.hpp"
#include "drivers/gpio/data_ready_line.hpp"
#include "drivers/iio/iio_imu.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::app {

/// Driver settings for the configured bus, rate, DLPF and ranges (the driver's own
/// validation applies; the configuration loader has usually checked them already).
[[nodiscard]] Result<drivers::mpu6000::Settings> driver_settings(const ImuConfig& imu);

/// The configured mounting (imu.mounting).
[[nodiscard]] Result<acq::MountingMap> imu_mounting(const ImuConfig& imu);

/// Options of a recording of `config`'s rig with the metadata every recording carries: the
/// configuration as JSON ("rig_config") and "source" ("hardware" or "sim").
acq::RecordOptions record_options(const RigConfig& config, bool simulated);

class ImuRig;

/// Where the kernel's IIO devices are (tests point these at a fake tree).
struct IioPaths {
  std::string sysfs_root = "/sys/bus/iio/devices";
  std::string dev_root = "/dev";
};

/// The driver `config` gets here: imu.driver, with auto resolved (iio when an inv-mpu6050 IIO
/// device is bound to the configured bus, or imu.iio_device is set; else direct).
ImuDriver resolve_imu_driver(const ImuConfig& imu, const IioPaths& paths = {});

/// Opens the rig `config` describes (imu.bus spi or i2c) and probes the MPU-6000, or opens it
/// through the kernel's driver (resolve_imu_driver()). Errors keep the driver's code
/// (kNotFound for a missing node, kDevice for a chip that does not answer, kInvalidArgument for
/// a bus that is not hardware or invalid settings, kUnsupported for what the kernel's driver
/// cannot give) and say which part failed: "opening the IMU bus: ...", "opening the data-ready
/// line: ...", "MPU-6000 on <bus>: ...", "the kernel's inv-mpu6050 driver: ...".
[[nodiscard]] Result<std::unique_ptr<ImuRig>> open_imu_rig(const RigConfig& config,
                                                           const acq::AcquisitionOptions& options = {},
                                                           const IioPaths& paths = {});

/// An opened and probed rig. Owns everything the acquisition borrows; not movable, as the
/// acquisition and the driver hold references into it.
class ImuRig {
 public:
  ImuRig(const ImuRig&) = delete;
  ImuRig& operator=(const ImuRig&) = delete;
  ~ImuRig();

  /// The acquisition, whichever driver reads the chip.
  acq::ImuSource& source();
  /// imucal's own driver, or null when the kernel's driver owns the chip.
  drivers::mpu6000::Mpu6000* driver() { return driver_.get(); }
  /// The kernel's driver's device, or null with imucal's own driver.
  drivers::iio::IioImu* iio() { return iio_.get(); }
  /// The stream as a recording describes it: "imu0", device "mpu6000@<bus>" or
  /// "mpu6000@iio:deviceN".
  const ImuStreamInfo& stream_info() const { return stream_info_; }
  /// "MPU-6000 on /dev/spidev0.0", "MPU-6000 through the kernel's inv-mpu6050 driver (iio:device0 ...)".
  std::string describe() const;

  /// The chip's offset registers, through the bus or the kernel's calibbias attributes.
  [[nodiscard]] Result<drivers::mpu6000::OffsetRegisters> read_offsets();
  [[nodiscard]] Status write_offsets(const drivers::mpu6000::OffsetRegisters& offsets);

 private:
  friend Result<std::unique_ptr<ImuRig>> open_imu_rig(const RigConfig&, const acq::AcquisitionOptions&,
                                                      const IioPaths&);
  ImuRig() = default;

  std::unique_ptr<drivers::RegisterBus> bus_;
  std::unique_ptr<drivers::DataReadyLine> line_;  // null: the acquisition polls the FIFO
  std::unique_ptr<drivers::mpu6000::Mpu6000> driver_;
  acq::MonotonicClock clock_;
  std::unique_ptr<acq::ImuAcquisition> acquisition_;
  std::unique_ptr<drivers::iio::IioImu> iio_;  // the kernel's driver (instead of the four above)
  std::unique_ptr<acq::IioAcquisition> iio_acquisition_;
  ImuStreamInfo stream_info_;
};

}  // namespace imucal::app
