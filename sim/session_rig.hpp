// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig for guided sessions: the MPU-6000 emulator, the real driver and acquisition
// loop (sim/rig.hpp) on simulated time, moved along an OperatorTrajectory by a ScriptedOperator
// (session_operator.hpp). advance() runs the acquisition for a span of simulated time and
// returns the samples: the service runs it from its event loop (accelerated time) and the tests
// run it in a plain loop.
#include <memory>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/rig.hpp"
#include "sim/session_operator.hpp"

namespace imucal::sim {

struct SessionRigOptions {
  drivers::mpu6000::Settings settings;
  acq::MountingMap mounting;
  std::uint64_t seed = 1;
  /// The IMU's errors; by default drawn from `seed` (ImuModelParams::draw), with the die already
  /// near its working temperature (a rig that was on before the session: warm-up takes one
  /// window, not ten minutes).
  std::optional<ImuModelParams> params;
};

class SessionRig {
 public:
  [[nodiscard]] static Result<std::unique_ptr<SessionRig>> create(const SessionRigOptions& options);
  /// Runs the acquisition until simulated time has advanced by `dt_ns`, appending the samples.
  /// An error is the acquisition's (a fault injected into the emulator).
  [[nodiscard]] Status advance(TimeNs dt_ns, std::vector<ImuSample>& out);
  TimeNs now_ns() { return rig_->clock().now_ns(); }
  const ImuStreamInfo& stream_info() const { return info_; }
  OperatorTrajectory& trajectory() { return *trajectory_; }
  SimImuRig& rig() { return *rig_; }
  const ImuModelParams& params() const { return params_; }
  /// What the sensing elements saw so far (the biases in effect, summed over the samples).
  const TrajectorySensorStats& sensor_stats() const { return sensor_->stats(); }

 private:
  SessionRig() = default;
  ImuModelParams params_;
  ImuStreamInfo info_;
  std::unique_ptr<OperatorTrajectory> trajectory_;
  std::shared_ptr<TrajectorySensor> sensor_;
  std::unique_ptr<SimImuRig> rig_;
};

}  // namespace imucal::sim
