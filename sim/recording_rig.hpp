// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual rig of `imucal record --sim`: the MPU-6000 emulator behind the real driver and
// acquisition loop, moved along a motion script, with the configuration's cameras as virtual
// cameras (sim/virtual_cameras.hpp) rendering the target as the rig moves; on simulated time (as
// fast as the host computes) or in real time (a ticker thread on CLOCK_MONOTONIC and the eventfd
// data-ready line, as a rig's event loop sees it). All of its assembly is here; the CLI parses
// options and records.

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "acquisition/imu_acquisition.hpp"
#include "acquisition/mounting.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "sim/camera_scene.hpp"
#include "sim/realtime.hpp"
#include "sim/rig.hpp"

namespace imucal::sim {

struct RecordingRigOptions {
  drivers::mpu6000::Settings settings;
  acq::MountingMap mounting;
  /// The configuration's cameras (every one of backend sim) and the target they see.
  std::vector<CameraConfig> cameras;
  std::optional<TargetDescription> target;
  std::uint64_t seed = 1;
  double clock_ppm = kDefaultClockPpm;
  double jitter_us = 30.0;
  /// What the rig does: "still", "static" (the multi-position protocol) or "checkerboard" (in
  /// front of the target; the cameras need it). Empty: checkerboard with cameras, else still.
  std::string motion;
  /// What the cameras show: "render" (the target through the camera model, with `render`) or
  /// "pattern" (a cheap moving test pattern).
  std::string camera_content = "render";
  /// The renderer (the render module's make_scene_renderer); needed for "render" with cameras.
  decltype(&make_scene_renderer) render = nullptr;
  /// Seconds to be recorded: the motion lasts at least that long.
  double duration_s = 10.0;
  /// Real time instead of simulated time.
  bool realtime = false;
};

class RecordingRig {
 public:
  /// Assembles the rig. kInvalidArgument for options that do not fit together (cameras of another
  /// backend, cameras without the checkerboard motion, no renderer), with what to change.
  [[nodiscard]] static Result<std::unique_ptr<RecordingRig>> create(const RecordingRigOptions& options);
  ~RecordingRig();

  acq::ImuAcquisition& acquisition();
  drivers::mpu6000::Mpu6000& driver();
  /// The IMU stream as the log describes it ("imu0", device "sim").
  const ImuStreamInfo& stream_info() const { return info_; }
  /// The virtual cameras, in the configuration's order, their formats set as configured.
  std::vector<std::unique_ptr<drivers::camera::Camera>>& cameras() { return cameras_; }
  /// The log's "sim" metadata: seed, clock error, edge timing, motion script, the cameras' time
  /// offset when there are cameras (JSON text).
  const std::string& metadata() const { return metadata_; }
  /// Real time: stops the ticker thread (after the recording).
  void stop();

 private:
  RecordingRig() = default;
  // Declared first, destroyed last: the sensor and the cameras' renderers read it.
  std::shared_ptr<const Trajectory> trajectory_;
  std::unique_ptr<SimImuRig> rig_;
  std::unique_ptr<RealtimeSimRig> realtime_;
  std::vector<std::unique_ptr<drivers::camera::Camera>> cameras_;
  ImuStreamInfo info_;
  std::string metadata_;
};

}  // namespace imucal::sim
