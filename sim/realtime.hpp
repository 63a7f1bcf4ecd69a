// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig in real time, to run the event-loop acquisition (asio_acquisition.hpp) the
// way a rig does: the MPU-6000 register emulator is advanced to CLOCK_MONOTONIC by a ticker
// thread (at each sample instant, when a data-ready edge falls due, and at least every
// `tick_ns`) and before every bus transfer, with a mutex serialising the ticker against the
// driver's transfers; its INT pin feeds a data-ready line whose fd() is a real eventfd
// (drivers/gpio/fake/eventfd_line.hpp), each edge readable only once CLOCK_MONOTONIC has
// passed its kernel-like timestamp.
// The host clock is CLOCK_MONOTONIC itself.
//
// Bus transfers take no simulated time here: the real time they take is their bus time.
// Unlike SimImuRig (sim/rig.hpp) a run is not reproducible: the host's scheduling decides when
// the FIFO is read. The chip's samples themselves (values and true times) are.

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>

#include "acquisition/recorder.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/bus/register_bus.hpp"
#include "drivers/gpio/fake/eventfd_line.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "sim/rig.hpp"

namespace imucal::sim {

/// The shared rig settings (rig.hpp) on CLOCK_MONOTONIC, plus what only the real-time rig has.
struct RealtimeSimRigOptions : SimRigOptions {
  /// Here start_ns is CLOCK_MONOTONIC at the chip's power-on, by default 0: when the rig is
  /// created (the shared default, a fixed time, lies anywhere on this machine's clock).
  RealtimeSimRigOptions() { start_ns = 0; }
  /// False: no data-ready line (the acquisition polls the FIFO on its timer).
  bool with_line = true;
  /// The ticker advances the emulator at least this often.
  TimeNs tick_ns = 200'000;
};

/// Emulator + ticker + real-time line + driver + acquisition (on acq::MonotonicClock). Not movable.
/// The acquisition is meant for acq::ImuAcquisition::service() on an event loop (step() works too).
class RealtimeSimRig {
 public:
  /// Powers the emulated chip up, probes it and starts the ticker.
  [[nodiscard]] static Result<std::unique_ptr<RealtimeSimRig>> create(fake::SensorSource source,
                                                                      const RealtimeSimRigOptions& options);
  ~RealtimeSimRig();
  RealtimeSimRig(const RealtimeSimRig&) = delete;
  RealtimeSimRig& operator=(const RealtimeSimRig&) = delete;

  acq::ImuAcquisition& acquisition() { return *acquisition_; }
  drivers::mpu6000::Mpu6000& driver() { return *driver_; }
  /// Null without a line (options.with_line false).
  fake::RealtimeDataReadyLine* line() { return line_.get(); }
  acq::AcquisitionClock& clock() { return clock_; }
  const RealtimeSimRigOptions& options() const { return options_; }
  TimeNs start_ns() const { return options_.start_ns; }

  /// Stops the ticker: from here on the chip's time stands still (unless the driver touches
  /// the bus), and emulator() may be inspected from this thread.
  void stop_ticker();
  /// The emulator. While the ticker runs or the acquisition is in use, hold emulator_mutex().
  fake::Mpu6000Emulator& emulator() { return emulator_; }
  std::mutex& emulator_mutex() { return mutex_; }

 private:
  class Bus;
  RealtimeSimRig(fake::SensorSource source, const RealtimeSimRigOptions& options,
                 std::unique_ptr<fake::RealtimeDataReadyLine> line);
  void tick_loop();

  RealtimeSimRigOptions options_;
  std::mutex mutex_;  // the emulator
  fake::Mpu6000Emulator emulator_;
  std::unique_ptr<fake::RealtimeDataReadyLine> line_;
  std::unique_ptr<Bus> bus_;
  std::unique_ptr<drivers::mpu6000::Mpu6000> driver_;
  acq::MonotonicClock clock_;
  std::unique_ptr<acq::ImuAcquisition> acquisition_;
  std::atomic<bool> stop_{false};
  std::thread ticker_;
};

}  // namespace imucal::sim
