#pragma once
// The hardware IMU rig assembled from its configuration: the bus (spidev or i2c-dev), the
// data-ready line (libgpiod) when configured, the MPU-6000 driver with the configured output
// settings, CLOCK_MONOTONIC and the acquisition with the configured mounting. Shared by
// `imucal record` and the rig service. The simulated rig is assembled in sim/, not here.

#include <memory>
#include <string>

#include "acquisition/imu_acquisition.hpp"
#include "acquisition/mounting.hpp"
#include "acquisition/recorder.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/bus/register_bus.hpp"
#include "drivers/gpio/data_ready_line.hpp"
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

/// Opens the rig `config` describes (imu.bus spi or i2c) and probes the MPU-6000. Errors keep
/// the driver's code (kNotFound for a missing node, kDevice for a chip that does not answer,
/// kInvalidArgument for a bus that is not hardware or invalid settings) and say which part
/// failed: "opening the IMU bus: ...", "opening the data-ready line: ...", "MPU-6000 on
/// <bus>: ...".
[[nodiscard]] Result<std::unique_ptr<ImuRig>> open_imu_rig(const RigConfig& config,
                                                           const acq::AcquisitionOptions& options = {});

/// An opened and probed rig. Owns everything the acquisition borrows; not movable, as the
/// acquisition and the driver hold references into it.
class ImuRig {
 public:
  ImuRig(const ImuRig&) = delete;
  ImuRig& operator=(const ImuRig&) = delete;
  ~ImuRig();

  acq::ImuAcquisition& acquisition() { return *acquisition_; }
  drivers::mpu6000::Mpu6000& driver() { return *driver_; }
  /// The stream as a recording describes it: "imu0", device "mpu6000@<bus>".
  const ImuStreamInfo& stream_info() const { return stream_info_; }
  /// The bus's name (its device node).
  std::string bus_name() const { return bus_->name(); }

 private:
  friend Result<std::unique_ptr<ImuRig>> open_imu_rig(const RigConfig&, const acq::AcquisitionOptions&);
  ImuRig() = default;

  std::unique_ptr<drivers::RegisterBus> bus_;
  std::unique_ptr<drivers::DataReadyLine> line_;  // null: the acquisition polls the FIFO
  std::unique_ptr<drivers::mpu6000::Mpu6000> driver_;
  acq::MonotonicClock clock_;
  std::unique_ptr<acq::ImuAcquisition> acquisition_;
  ImuStreamInfo stream_info_;
};

}  // namespace imucal::app
