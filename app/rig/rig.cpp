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

}  // namespace

Result<std::unique_ptr<ImuRig>> open_imu_rig(const RigConfig& config,
                                             const acq::AcquisitionOptions& options) {
  const ImuConfig& imu = config.imu;
  auto mounting = imu_mounting(imu);
  if (!mounting.ok()) return mounting.error().context("imu mounting");
  auto settings = driver_settings(imu);
  if (!settings.ok()) return settings.error().context("imu settings");

  std::unique_ptr<ImuRig> rig(new ImuRig());
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
