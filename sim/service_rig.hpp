// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig of the service (`imucald --sim`, `make demo`): the MPU-6000 register emulator
// behind the real driver and acquisition loop (sim/session_rig.hpp), its cameras
// (sim/virtual_cameras.hpp), the pace of its clock against the wall clock, its injected faults, the
// scripted operator and the comparison of a result with its truth, all behind this interface.
//
// The implementation lives in the module libimucal_virtual_rig.so, which imucald loads only when
// it runs the virtual rig (app/module_loader.hpp): the rig's service does not link the simulator.
// This header is the one part of sim/ that imucald includes.

#include <Eigen/Core>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "acquisition/mounting.hpp"
#include "core/imu.hpp"
#include "core/module.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "core/session_messages.hpp"
#include "core/time.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::sim {

inline constexpr const char* kVirtualRigModule = "imucal_virtual_rig";
inline constexpr const char* kVirtualRigModuleEntry = "imucal_virtual_rig_module";

struct ServiceRigOptions {
  drivers::mpu6000::Settings settings;
  acq::MountingMap mounting;
  /// The rig's cameras (virtual, whatever their backend says) and the target they see.
  std::vector<CameraConfig> cameras;
  std::optional<TargetDescription> target;
  /// The motion step's length: the operator's motion in front of the target covers it.
  double motion_s = 60.0;
  /// Seeds the IMU's errors, the cameras' noise and the operator.
  std::uint64_t seed = 1;
  /// A cold start: the die starts at this temperature and warms towards 45 deg C (time constant
  /// 300 s), its biases moving with a quadratic in temperature drawn from the seed (what the
  /// session's thermal step fits). Empty: the die is already near its working temperature.
  std::optional<double> cold_start_c;
  /// Rig seconds per wall-clock second; 0: as fast as the host computes.
  double time_scale = 1.0;
  /// The wall time over which the pace reached is measured against time_scale (ServiceRigTick's
  /// pace_notice), s.
  double pace_window_s = 5.0;
  /// The scripted operator: "" (nobody moves the rig), "motion" (moves it as the prompts ask),
  /// "full" (also presses the keys, through press_key).
  std::string operator_mode;
  std::function<void(session_msg::OperatorKey key)> press_key;
};

/// What a tick of the virtual rig did and when the next one is due.
struct ServiceRigTick {
  /// Whether the rig advanced (false: it waited for the service's worker).
  bool advanced = false;
  /// When the next tick is due on the steady clock; empty: at once.
  std::optional<std::chrono::steady_clock::time_point> next;
  /// Set when the pace reached over the last pace_window_s falls below 80 % of time_scale (the
  /// host cannot keep up), and again when it is back above 95 %: a sentence for the operator.
  std::string pace_notice;
};

class ServiceRig {
 public:
  virtual ~ServiceRig() = default;
  virtual const ImuStreamInfo& stream_info() const = 0;
  /// The real driver, talking to the emulator.
  virtual drivers::mpu6000::Mpu6000& driver() = 0;
  virtual TimeNs now_ns() = 0;
  /// Lets `duration_ns` of rig time pass without sampling (the chip's self-test).
  virtual void stall(TimeNs duration_ns) = 0;
  /// One tick: 20 ms of rig time through the acquisition, the samples handed to `deliver`, then
  /// the operator's turn. On accelerated time (a scale other than 1) the rig waits instead while
  /// `worker_busy` (a solve or a write): at hundreds of times real time it would otherwise move on
  /// by minutes during a quick solve that a rig's operator does not notice; wall time spent
  /// waiting does not count as rig time. An error is the acquisition's (an injected fault).
  [[nodiscard]] virtual Result<ServiceRigTick> tick(
      bool worker_busy, const std::function<void(std::span<const ImuSample>)>& deliver) = 0;
  /// The IMU stops answering `after_s` seconds of rig time from now (a yanked cable).
  virtual void unplug_imu_after(double after_s) = 0;
  /// The session's messages, for the scripted operator.
  virtual void on_message(const session_msg::SessionMessage& message) = 0;
  /// Whether the scripted operator presses keys.
  virtual bool operator_presses_keys() const = 0;
  /// Whether the cameras can render (the target is there and the renderer loaded).
  virtual bool cameras_ready() const = 0;
  /// The camera `index` of the options, started on the rig's clock one frame period from now; it is
  /// gone after `disconnect_after` frames when that is not 0.
  [[nodiscard]] virtual Result<std::unique_ptr<drivers::camera::Camera>> open_camera(
      std::size_t index, std::uint32_t disconnect_after) = 0;
  /// A session's "result" message beside the virtual rig's truth, as text; empty when the message
  /// holds no IMU result.
  virtual std::string truth_report(const session_msg::ResultSummary& result) const = 0;
  /// Where camera `index`'s frame stamped t_ns truly shows the target's points, by point id (NaN
  /// where not on the sensor); nothing once the frame is older than the last 64 rendered.
  virtual std::optional<std::vector<Eigen::Vector2d>> truth_corners(std::size_t index, TimeNs t_ns) const = 0;
};

/// The virtual rig (sim/service_rig.cpp): the module's entry; tests link imucal_sim_service.
[[nodiscard]] Result<std::unique_ptr<ServiceRig>> make_service_rig(const ServiceRigOptions& options);

struct VirtualRigModuleApi {
  ModuleHeader header;
  decltype(&make_service_rig) create;
};

}  // namespace imucal::sim
