// SPDX-License-Identifier: BSD-3-Clause
#include "sim/rig.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace imucal::sim {

namespace mpu = drivers::mpu6000;

TimeNs clipped_latency_mean_ns(TimeNs mean_ns, TimeNs sigma_ns) {
  if (sigma_ns <= 0) return std::max<TimeNs>(0, mean_ns);
  const double m = static_cast<double>(mean_ns), s = static_cast<double>(sigma_ns), a = m / s;
  const double cdf = 0.5 * std::erfc(-a / std::sqrt(2.0));
  const double pdf = std::exp(-0.5 * a * a) / std::sqrt(2.0 * std::numbers::pi);
  return static_cast<TimeNs>(std::llround(m * cdf + s * pdf));
}

double chip_sample_period_s(const mpu::Settings& settings, double clock_ppm) {
  return 1.0 / (settings.sample_rate_hz() * (1.0 + clock_ppm * 1e-6));
}

fake::EmulatorOptions emulator_options(const SimRigOptions& o) {
  fake::EmulatorOptions eo;
  eo.bus = o.settings.bus;
  eo.timing = o.settings.bus == mpu::BusKind::kSpi ? fake::BusTiming::spi() : fake::BusTiming::i2c();
  eo.clock_ppm = o.clock_ppm;
  eo.start_ns = o.start_ns;
  eo.record_truth = o.record_truth;
  return eo;
}

acq::AcquisitionOptions acquisition_options(const SimRigOptions& o) {
  acq::AcquisitionOptions ao = o.acquisition;
  ao.timestamps.edge_latency_ns = clipped_latency_mean_ns(o.data_ready.latency_ns, o.data_ready.sigma_ns);
  ao.timestamps.edge_jitter_ns = std::max<TimeNs>(1, o.data_ready.sigma_ns);
  return ao;
}

SimImuRig::SimImuRig(fake::SensorSource source, const SimRigOptions& options)
    : options_(options),
      emulator_(std::move(source), emulator_options(options)),
      line_(emulator_, options.data_ready),
      driver_(emulator_, options.settings),
      clock_(emulator_) {
  emulator_.connect(line_);
  acquisition_ = std::make_unique<acq::ImuAcquisition>(driver_, &line_, clock_, options.mounting,
                                                       acquisition_options(options));
}

Result<std::unique_ptr<SimImuRig>> SimImuRig::create(fake::SensorSource source,
                                                     const SimRigOptions& options) {
  if (auto valid = options.settings.validate(); !valid.ok())
    return valid.error().context("simulated MPU-6000 settings");
  std::unique_ptr<SimImuRig> rig(new SimImuRig(std::move(source), options));
  if (auto st = rig->driver_.probe(); !st.ok()) return st.error().context("simulated MPU-6000");
  return rig;
}

TrajectorySensor::TrajectorySensor(const sim::ImuModelParams& params, std::uint64_t seed,
                                   const sim::Trajectory& trajectory, TimeNs host_offset_ns,
                                   double sample_period_s)
    : simulator_(params, seed, trajectory.start_ns()),
      trajectory_(trajectory),
      offset_ns_(host_offset_ns),
      period_s_(sample_period_s),
      last_counted_ns_(std::numeric_limits<TimeNs>::min()) {}

fake::SensorReading TrajectorySensor::operator()(TimeNs host_t_ns) {
  const TimeNs t = host_t_ns - offset_ns_;
  const TimeNs tc = std::clamp(t, trajectory_.start_ns(), trajectory_.end_ns());
  const sim::RigState state = trajectory_.at(tc);
  const sim::ImuSimDetail d = simulator_.sample_si(tc, state, period_s_);
  // One count per sample instant: at 8 kHz the accelerometer value is asked for at its own 1 kHz
  // instants, within rounding of a gyro instant.
  const TimeNs half_period_ns = static_cast<TimeNs>(period_s_ * 0.5e9);
  if (t >= trajectory_.start_ns() && t <= trajectory_.end_ns() &&
      (stats_.samples == 0 || t > last_counted_ns_ + half_period_ns)) {
    last_counted_ns_ = t;
    const double a = state.a_world.norm(), w = state.omega_body.norm();
    if (stats_.samples == 0) stats_.temperature_start_c = d.temperature_c;
    ++stats_.samples;
    stats_.sum_accel_mps2 += a;
    stats_.sum_rate_radps += w;
    stats_.max_accel_mps2 = std::max(stats_.max_accel_mps2, a);
    stats_.max_rate_radps = std::max(stats_.max_rate_radps, w);
    stats_.sum_accel_bias += d.accel_bias;
    stats_.sum_gyro_bias += d.gyro_bias;
    stats_.sum_accel_bias_temp += d.accel_bias_temp;
    stats_.sum_gyro_bias_temp += d.gyro_bias_temp;
    stats_.accel_bias_end = d.accel_bias;
    stats_.gyro_bias_end = d.gyro_bias;
    stats_.temperature_end_c = d.temperature_c;
  }
  fake::SensorReading r;
  r.specific_force = d.accel_si;
  r.angular_rate = d.gyro_si;
  r.temperature_c = d.temperature_c;
  return r;
}

fake::SensorSource TrajectorySensor::source(std::shared_ptr<TrajectorySensor> sensor) {
  return [sensor = std::move(sensor)](TimeNs t_ns) { return (*sensor)(t_ns); };
}

}  // namespace imucal::sim
