// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// One camera in a recording: takes every frame the camera has ready into its CameraStream,
// and turns what goes wrong with the camera into events in the log instead of ending the
// recording: a camera that stops delivering (no frame for stall_timeout) and one that fails
// (unplugged, a broken driver). The IMU stream and the log go on either way.
//
// Used from the acquisition thread only.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "acquisition/camera_stream.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/camera/camera.hpp"
#include "log/session_log.hpp"

namespace imucal::acq {

struct CameraAcquisitionStats {
  CameraStreamStats stream;
  drivers::camera::CameraCounters device;
  std::uint64_t stalls = 0;  // times the camera went silent for longer than the timeout
  bool failed = false;       // the camera failed and was given up
  std::string failure;       // why
};

class CameraAcquisition {
 public:
  /// Receives fault events (time on the log's clock) for the log.
  using EventSink = std::function<void(log::Event)>;

  /// `camera` is borrowed and must be started by the caller; `name` is the stream's name.
  /// A camera silent for longer than `stall_timeout_ns` is reported once per silence.
  CameraAcquisition(drivers::camera::Camera& camera, std::string name, std::unique_ptr<CameraStream> stream,
                    EventSink events, TimeNs stall_timeout_ns);

  /// Takes every frame the camera has ready. `now_ns` is the host time (the acquisition's clock),
  /// used for stall detection. False once the camera has failed.
  bool service(TimeNs now_ns);

  CameraStream& stream() { return *stream_; }
  drivers::camera::Camera& camera() { return camera_; }
  const std::string& name() const { return name_; }
  bool failed() const { return failed_; }
  CameraAcquisitionStats stats() const;

 private:
  void post(TimeNs host_t_ns, std::string message);

  drivers::camera::Camera& camera_;
  std::string name_;
  std::unique_ptr<CameraStream> stream_;
  EventSink events_;
  TimeNs stall_timeout_ns_;
  TimeNs last_frame_host_ns_ = -1;  // host time of the last frame (or of the first service call)
  bool silent_ = false;
  bool failed_ = false;
  std::string failure_;
  std::uint64_t stalls_ = 0;
};

}  // namespace imucal::acq
