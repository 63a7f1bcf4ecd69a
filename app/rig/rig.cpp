// SPDX-License-Identifier: BSD-3-Clause
#include "app/rig/rig.hpp"

#include "drivers/bus/i2cdev_bus.hpp"
#include "drivers/bus/spidev_bus.hpp"
#include "drivers/gpio/gpiod_line.hpp"
#include "drivers/mpu6000/output_settings.hpp"

namespace imucal::app {

namespace mpu = drivers::mpu6000;

Result<mpu::Settings> driver_settings(const ImuConfig& imu) {
  mpu::OutputRequest req;
  req.bus = imu.bus == ImuBus::kI2c ? mpu::BusKind::kI2c : mpu::BusKind::kSpi;
  req.rate_hz = imu.rate_hz;
  req.dlpf_hz = imu.dlpf_hz;
  req.accel_full_scale_g = imu.accel_range_g;
  req.gyro_full_scale_dps = imu.gyro_range_dps;
  req.spi_config_speed_hz = static_cast<std::uint32_t>(imu.spi_config_speed_hz);
  req.spi_data_speed_hz = static_cast<std::uint32_t>(imu.spi_data_speed_hz);
  return mpu::settings_for(req);
}

Result<acq::MountingMap> imu_mounting(const ImuConfig& imu) {
  return acq::MountingMap::from_rotation(imu.R_rig_imu);
}

acq::RecordOptions record_options(const RigConfig& config, bool simulated) {
  acq::RecordOptions ro;
  ro.metadata.emplace_back("rig_config", rig_config_to_json(config));
  ro.metadata.emplace_back("source", simulated ? "sim" : "hardware");
  return ro;
}

ImuRig::~ImuRig() = default;

namespace {

Result<std::unique_ptr<drivers::RegisterBus>> open_bus(const ImuConfig& imu) {
  if (imu.bus == ImuBus::kSpi) {
    drivers::SpidevOptions so;
    so.config_speed_hz = static_cast<std::uint32_t>(imu.spi_config_speed_hz);
    so.max_speed_hz = static_cast<std::uint32_t>(imu.spi_data_speed_hz);
    auto bus = drivers::SpidevBus::open(imu.device, so);
    if (!bus.ok()) return bus.error();
    return std::unique_ptr<drivers::RegisterBus>(std::move(*bus));
  }
  if (imu.bus == ImuBus::kI2c) {
    drivers::I2cDevOptions io;
    io.address = static_cast<std::uint8_t>(imu.i2c_address);
    auto bus = drivers::I2cDevBus::open(imu.device, io);
    if (!bus.ok()) return bus.error();
    return std::unique_ptr<drivers::RegisterBus>(std::move(*bus));
  }
  return make_error(Errc::kInvalidArgument, "imu.bus is sim: the simulated rig is not hardware");
}

std::string iio_parent(const ImuConfig& imu) {
  return drivers::iio::bus_parent_name(imu.device, imu.bus == ImuBus::kI2c, imu.i2c_address);
}

// The kernel's driver sets the chip's filter from the rate (inv_mpu6050_set_lpf(): the gyro
// bandwidth of DLPF_CFG 1..6 for rates from 400, 200, 90, 40, 20 Hz and below).
int kernel_dlpf_hz(double rate_hz) {
  const double from[] = {400, 200, 90, 40, 20};
  const int hz[] = {188, 98, 42, 20, 10};
  for (int i = 0; i < 5; ++i)
    if (rate_hz >= from[i]) return hz[i];
  return 5;
}

// The chip through the kernel's inv-mpu6050 driver: the IIO device, its acquisition, and the
// stream info from the scales the kernel states.
Status open_iio(const ImuConfig& imu, const mpu::Settings& settings, const acq::MountingMap& mounting,
                const IioPaths& paths, std::unique_ptr<drivers::iio::IioImu>& iio,
                std::unique_ptr<acq::IioAcquisition>& acquisition, acq::AcquisitionClock& clock,
                ImuStreamInfo& info) {
  if (kernel_dlpf_hz(imu.rate_hz) != imu.dlpf_hz) {
    return make_error(Errc::kUnsupported, "imu.dlpf_hz " + std::to_string(imu.dlpf_hz) +
                                              ": the kernel's inv-mpu6050 driver sets the "
                                              "filter from the rate, " +
                                              std::to_string(kernel_dlpf_hz(imu.rate_hz)) + " Hz at " +
                                              std::to_string(imu.rate_hz) +
                                              " Hz; set imu.dlpf_hz to that, or use imu.driver: direct");
  }
  drivers::iio::IioImuOptions o;
  o.sysfs_root = paths.sysfs_root;
  o.dev_root = paths.dev_root;
  o.device = imu.iio_device;
  o.parent = imu.iio_device.empty() ? iio_parent(imu) : std::string();
  o.rate_hz = imu.rate_hz;
  o.accel_range = settings.accel_range;
  o.gyro_range = settings.gyro_range;
  auto opened = drivers::iio::IioImu::open(o);
  if (!opened.ok()) return opened.error();
  iio = std::move(*opened);
  acquisition = std::make_unique<acq::IioAcquisition>(*iio, clock, mounting);
  info = mpu::make_stream_info(settings, "mpu6000@" + iio->info().id);
  info.rate_hz = iio->rate_hz();
  info.accel.scale = Eigen::Vector3d::Constant(iio->accel_scale());
  info.gyro.scale = Eigen::Vector3d::Constant(iio->gyro_scale());
  info.temperature_scale = iio->temp_scale();
  info.temperature_offset = iio->temp_offset_c();
  return {};
}

}  // namespace

ImuDriver resolve_imu_driver(const ImuConfig& imu, const IioPaths& paths) {
  if (imu.bus == ImuBus::kSim) return ImuDriver::kDirect;  // the virtual rig is not a kernel's
  if (imu.driver != ImuDriver::kAuto) return imu.driver;
  if (!imu.iio_device.empty()) return ImuDriver::kIio;
  const std::string parent = iio_parent(imu);
  for (const auto& d : drivers::iio::find_inv_mpu_devices(paths.sysfs_root))
    if (!parent.empty() && d.parent == parent) return ImuDriver::kIio;
  return ImuDriver::kDirect;
}

acq::ImuSource& ImuRig::source() {
  if (iio_acquisition_) return *iio_acquisition_;
  return *acquisition_;
}

std::string ImuRig::describe() const {
  if (iio_) return "MPU-6000 through the kernel's inv-mpu6050 driver (" + iio_->describe() + ")";
  return "MPU-6000 on " + bus_->name();
}

Result<mpu::OffsetRegisters> ImuRig::read_offsets() {
  if (iio_) return iio_->read_offsets();
  return driver_->read_offsets();
}

Status ImuRig::write_offsets(const mpu::OffsetRegisters& offsets) {
  if (iio_) return iio_->write_offsets(offsets);
  return driver_->write_offsets(offsets);
}

Result<std::unique_ptr<ImuRig>> open_imu_rig(const RigConfig& config, const acq::AcquisitionOptions& options,
                                             const IioPaths& paths) {
  const ImuConfig& imu = config.imu;
  auto mounting = imu_mounting(imu);
  if (!mounting.ok()) return mounting.error().context("imu mounting");
  auto settings = driver_settings(imu);
  if (!settings.ok()) return settings.error().context("imu settings");

  std::unique_ptr<ImuRig> rig(new ImuRig());
  if (resolve_imu_driver(imu, paths) == ImuDriver::kIio) {
    if (auto st = open_iio(imu, *settings, *mounting, paths, rig->iio_, rig->iio_acquisition_, rig->clock_,
                           rig->stream_info_);
        !st.ok()) {
      return st.error().context("the kernel's inv-mpu6050 driver");
    }
    rig->stream_info_.name = "imu0";
    return rig;
  }
  auto bus = open_bus(imu);
  if (!bus.ok()) return bus.error().context("opening the IMU bus");
  rig->bus_ = std::move(*bus);
  if (imu.data_ready) {
    drivers::GpiodLineOptions lo;
    lo.chip = imu.data_ready->chip;
    lo.line = std::to_string(imu.data_ready->line);
    auto line = drivers::GpiodDataReadyLine::open(lo);
    if (!line.ok()) return line.error().context("opening the data-ready line");
    rig->line_ = std::move(*line);
  }
  rig->driver_ = std::make_unique<mpu::Mpu6000>(*rig->bus_, *settings);
  if (auto probed = rig->driver_->probe(); !probed.ok()) {
    return probed.error().context("MPU-6000 on " + rig->bus_->name());
  }
  rig->acquisition_ =
      std::make_unique<acq::ImuAcquisition>(*rig->driver_, rig->line_.get(), rig->clock_, *mounting, options);
  rig->stream_info_ = mpu::make_stream_info(*settings, "mpu6000@" + rig->bus_->name());
  rig->stream_info_.name = "imu0";
  return rig;
}

}  // namespace imucal::app
