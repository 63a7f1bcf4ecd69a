// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The rig imucald runs on, chosen once at start-up (make_rig): the hardware (the IMU through
// app::ImuRig on the Boost.Asio event loop, the configured cameras through their backends) or
// the virtual rig (sim::ServiceRig from libimucal_virtual_rig.so, on accelerated time). The
// service talks to either through this one interface and does not ask which it has, except to
// say so (status, the recording's "source").

#include <Eigen/Core>
#include <boost/asio/io_context.hpp>
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "core/session_messages.hpp"
#include "core/time.hpp"
#include "daemon/imucald/service_options.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::imucald {

/// The chip's self-test for the preflight: its outcome as a value and its words.
struct SelfTest {
  enum class Outcome { kPassed, kFailed, kCouldNotRun, kNotAvailable };  // kNotAvailable: IIO
  Outcome outcome = Outcome::kCouldNotRun;
  std::string text;
  /// The IMU passes its check: the test passed, or the kernel's driver offers none.
  bool ok() const { return outcome == Outcome::kPassed || outcome == Outcome::kNotAvailable; }
};

/// What the rig hands the service, and what it asks of it. Called on the event loop.
struct RigEvents {
  /// A batch of the IMU's samples.
  std::function<void(std::span<const ImuSample>)> samples;
  /// The IMU stopped (an error of its acquisition, a yanked cable).
  std::function<void(const Error&)> imu_failed;
  /// Camera `index`, watched (Rig::watch_camera), may have frames to dequeue.
  std::function<void(std::size_t index)> camera_readable;
  /// A sentence for the operator from the rig itself (the virtual rig's pace).
  std::function<void(const std::string&)> notice;
  /// Whether the session's worker is busy (a solve, a write): the virtual rig's clock waits.
  std::function<bool()> worker_busy;
  /// The virtual rig's scripted operator presses a key.
  std::function<void(session_msg::OperatorKey)> press_key;
};

class Rig {
 public:
  virtual ~Rig() = default;

  /// The virtual rig (status and recordings say so).
  virtual bool simulated() const = 0;

  /// Opens the IMU and puts its acquisition on the event loop: samples come through
  /// RigEvents::samples once run() runs. Errors keep the driver's code and say what failed.
  [[nodiscard]] virtual Status open_imu() = 0;
  /// Closes the IMU (a fault, a redo, the service's end); open_imu() opens it again.
  virtual void close_imu() = 0;
  virtual bool imu_open() const = 0;
  /// The stream as recordings describe it; valid while the IMU is open.
  virtual const ImuStreamInfo& stream_info() const = 0;
  /// The open IMU for the preflight: "MPU-6000 on /dev/spidev0.0, WHO_AM_I answered".
  virtual std::string describe_imu() const = 0;
  /// The chip's self-test (the acquisition pauses for it).
  virtual SelfTest self_test() = 0;
  /// The chip's offset registers, through whichever driver reads it.
  [[nodiscard]] virtual Result<drivers::mpu6000::OffsetRegisters> read_offsets() = 0;
  [[nodiscard]] virtual Status write_offsets(const drivers::mpu6000::OffsetRegisters& regs) = 0;

  /// The preflight's line for the configuration's camera `index` (opened and closed again).
  virtual session_msg::PreflightReport::Device check_camera(std::size_t index) = 0;
  /// The configuration's camera `index`, opened, not started.
  [[nodiscard]] virtual Result<std::unique_ptr<drivers::camera::Camera>> open_camera(std::size_t index) = 0;
  /// After the camera started: RigEvents::camera_readable(index) whenever it may have frames, until
  /// unwatch_cameras().
  [[nodiscard]] virtual Status watch_camera(std::size_t index, drivers::camera::Camera& camera) = 0;
  /// Before the cameras stop: no more camera_readable.
  virtual void unwatch_cameras() = 0;

  /// Runs the event loop (with the IMU's acquisition when it is on it) until stop(), or until the
  /// IMU fails (RigEvents::imu_failed has then been called). Called again after each return.
  virtual void run() = 0;
  /// Ends run() for good (the service stops); from a handler on the event loop.
  virtual void stop() = 0;

  // What only the virtual rig does; nothing on the hardware.
  /// A session starts (the virtual rig's injected IMU fault is armed for the first one).
  virtual void session_starting() {}
  /// The session's messages, for the scripted operator.
  virtual void on_message(const session_msg::SessionMessage& /*message*/) {}
  /// Whether a scripted operator presses the keys.
  virtual bool operator_presses_keys() const { return false; }
  /// A session's result beside the rig's truth, as text; empty when there is no truth.
  virtual std::string truth_report(const session_msg::ResultSummary& /*result*/) const { return {}; }
  /// Where camera `index`'s frame stamped t_ns truly shows the target's points; none without truth.
  virtual std::optional<std::vector<Eigen::Vector2d>> truth_corners(std::size_t /*index*/,
                                                                    TimeNs /*t_ns*/) const {
    return std::nullopt;
  }
};

/// The rig `options` and `config` choose: the virtual rig with options.sim (set also when
/// imu.bus is sim), else the hardware. Opens nothing yet.
[[nodiscard]] std::unique_ptr<Rig> make_rig(const RigConfig& config, const ServiceOptions& options,
                                            boost::asio::io_context& io, RigEvents events);

}  // namespace imucal::imucald
