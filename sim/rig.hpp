// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig's IMU path, built the way a rig is: the MPU-6000 register emulator (its own
// oscillator, FIFO, data-ready pin) on a simulated bus, the simulated data-ready line with
// latency jitter, the real driver (drivers/mpu6000) and the real acquisition loop
// (recorder.hpp), with the emulator's clock as the host clock. `imucal sim`, `imucal record
// --sim`, the tests and the benchmarks all build their simulated IMU here, so simulated sessions
// exercise the code a rig runs.
//
// TrajectorySensor is the usual sample source: it moves the virtual rig along a trajectory and
// passes the motion through the IMU error model (sim/imu_error_model.hpp).

#include <Eigen/Core>
#include <cstdint>
#include <memory>

#include "acquisition/mounting.hpp"
#include "acquisition/recorder.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/trajectory.hpp"

namespace imucal::sim {

/// Mean of max(0, N(mean, sigma)): the simulated line clips its latency at zero, which moves the
/// mean edge latency above the nominal one. This is the latency the timestamper is told.
TimeNs clipped_latency_mean_ns(TimeNs mean_ns, TimeNs sigma_ns);

/// The emulated chip's true sample period: the nominal one on an oscillator off by `clock_ppm`.
/// White noise drawn for this period has the model's density on the chip's own sample clock.
double chip_sample_period_s(const drivers::mpu6000::Settings& settings, double clock_ppm);

/// The chip's oscillator against the host clock when nobody says otherwise, ppm: a chip 1.5 %
/// slow (negative: it samples slower), within the few percent the MPU-6000 drifts over
/// temperature. The simulated sessions and both virtual rigs default to this one figure.
inline constexpr double kDefaultClockPpm = -15'000.0;

/// The settings both virtual rigs share: the deterministic one (SimImuRig) takes them as they
/// are, the real-time one (realtime.hpp) extends them with its own.
struct SimRigOptions {
  drivers::mpu6000::Settings settings;   // bus, rate, ranges (drivers/mpu6000/output_settings.hpp)
  double clock_ppm = kDefaultClockPpm;   // the chip's oscillator against the host clock
  fake::DataReadyTiming data_ready;      // edge latency 20 us, jitter 30 us RMS
  TimeNs start_ns = 100 * kNsPerSecond;  // host time at power-on
  bool record_truth = false;             // keep every sample's true time and counts (tests)
  acq::MountingMap mounting;             // identity: the IMU's axes are the rig's
  acq::AcquisitionOptions acquisition;   // edge latency and jitter are set from data_ready
};

/// The emulated chip of a rig: its bus with that bus's transfer timing, its oscillator.
fake::EmulatorOptions emulator_options(const SimRigOptions& options);
/// The rig's acquisition options: `options.acquisition` with the timestamper told the simulated
/// line's mean latency and jitter, as a rig's configuration tells it its platform's.
acq::AcquisitionOptions acquisition_options(const SimRigOptions& options);

/// Emulator + data-ready line + driver + acquisition loop, wired together. Not movable: the
/// parts refer to each other.
class SimImuRig {
 public:
  /// Powers the emulated chip up and probes it (WHO_AM_I); the driver resets and configures the
  /// chip during the first acquisition steps, as on a rig.
  [[nodiscard]] static Result<std::unique_ptr<SimImuRig>> create(fake::SensorSource source,
                                                                 const SimRigOptions& options);
  SimImuRig(const SimImuRig&) = delete;
  SimImuRig& operator=(const SimImuRig&) = delete;

  fake::Mpu6000Emulator& emulator() { return emulator_; }
  fake::SimDataReadyLine& line() { return line_; }
  drivers::mpu6000::Mpu6000& driver() { return driver_; }
  acq::ImuAcquisition& acquisition() { return *acquisition_; }
  acq::AcquisitionClock& clock() { return clock_; }
  const SimRigOptions& options() const { return options_; }

  /// The host stops reading the chip until `host_t_ns` (a stalled process, a held bus): the
  /// chip keeps sampling and its FIFO overflows after 73 frames.
  void stall_until(TimeNs host_t_ns) { clock_.sleep_until(host_t_ns); }

  /// The simulated host clock (the emulator's time) as an AcquisitionClock.
  class Clock final : public acq::AcquisitionClock {
   public:
    explicit Clock(fake::Mpu6000Emulator& emulator) : emulator_(emulator) {}
    TimeNs now_ns() override { return emulator_.now_ns(); }
    void sleep_until(TimeNs t_ns) override {
      if (t_ns > emulator_.now_ns()) emulator_.advance_to(t_ns);
    }

   private:
    fake::Mpu6000Emulator& emulator_;
  };

 private:
  SimImuRig(fake::SensorSource source, const SimRigOptions& options);

  SimRigOptions options_;
  fake::Mpu6000Emulator emulator_;
  fake::SimDataReadyLine line_;
  drivers::mpu6000::Mpu6000 driver_;
  Clock clock_;
  std::unique_ptr<acq::ImuAcquisition> acquisition_;
};

/// What the sensing elements saw while the rig moved along the trajectory (for the truth file).
struct TrajectorySensorStats {
  std::int64_t samples = 0;  // distinct sample instants inside the trajectory
  double sum_accel_mps2 = 0.0, sum_rate_radps = 0.0;
  double max_accel_mps2 = 0.0, max_rate_radps = 0.0;
  Eigen::Vector3d sum_accel_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d sum_gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d sum_accel_bias_temp = Eigen::Vector3d::Zero();  // their die-temperature parts
  Eigen::Vector3d sum_gyro_bias_temp = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias_end = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias_end = Eigen::Vector3d::Zero();
  double temperature_start_c = 0.0, temperature_end_c = 0.0;
};

/// A sensor source that moves the virtual rig along `trajectory` and applies the IMU error
/// model. Host time t corresponds to trajectory time t - host_offset_ns; before the trajectory
/// starts and after it ends the rig rests in its first and last state. White noise is drawn for
/// a bandwidth of 1 / (2 sample_period_s). The trajectory is borrowed.
class TrajectorySensor {
 public:
  TrajectorySensor(const sim::ImuModelParams& params, std::uint64_t seed, const sim::Trajectory& trajectory,
                   TimeNs host_offset_ns, double sample_period_s);

  fake::SensorReading operator()(TimeNs host_t_ns);

  /// Wraps a shared sensor as an emulator source (the emulator copies its source).
  static fake::SensorSource source(std::shared_ptr<TrajectorySensor> sensor);

  const TrajectorySensorStats& stats() const { return stats_; }
  TimeNs host_offset_ns() const { return offset_ns_; }

 private:
  sim::ImuSimulator simulator_;
  const sim::Trajectory& trajectory_;
  TimeNs offset_ns_;
  double period_s_;
  TimeNs last_counted_ns_;
  TrajectorySensorStats stats_;
};

}  // namespace imucal::sim
