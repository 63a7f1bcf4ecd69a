// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Cameras through libcamera (0.0.3, Debian 12): CSI sensors behind an ISP (Raspberry Pi,
// Rockchip, i.MX), and UVC webcams through its uvcvideo pipeline.
//
// One stream (StreamRole::Raw by default: the sensor's own pixels, no ISP processing, which is
// what calibration wants; Viewfinder for an ISP-processed stream). A fixed set of requests, each
// with one buffer, circulates: completed requests are queued by the camera manager's thread,
// which signals an eventfd (fd()); dequeue() hands out the frame and the request is queued again
// when the frame is released.
//
// Time: t_ns is the request's SensorTimestamp, which libcamera defines as the start of exposure
// of the first row on CLOCK_BOOTTIME; the 0.0.3 pipeline handlers copy the V4L2 buffer's
// timestamp into it, which is CLOCK_MONOTONIC. The two clocks differ only by the time the system
// spent suspended; a stamp that lies closer to CLOCK_BOOTTIME than to CLOCK_MONOTONIC is moved
// onto CLOCK_MONOTONIC. The exposure comes from the ExposureTime metadata when the pipeline
// reports it.
//
// libcamera allows one CameraManager per process: every camera and list call shares one, which
// lives while any camera is open.

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "drivers/camera/camera.hpp"

namespace libcamera {
class Camera;
class CameraConfiguration;
class CameraManager;
class Request;
class Stream;
}  // namespace libcamera

namespace imucal::drivers::camera {

struct LibcameraOptions {
  enum class Role { kRaw, kViewfinder };
  Role role = Role::kRaw;
  int buffers = 4;  // requests in flight; 0: the pipeline's default
};

/// The ids of the cameras libcamera finds; fails when the camera manager cannot start.
[[nodiscard]] Result<std::vector<std::string>> list_libcamera_cameras();

class LibcameraCamera;
/// Opens and acquires a camera by its libcamera id. An unknown id fails with kNotFound naming
/// the cameras found (or saying that none were); a camera in use elsewhere fails with kDevice.
[[nodiscard]] Result<std::unique_ptr<LibcameraCamera>> open_libcamera_camera(
    const std::string& id, const LibcameraOptions& options = {});

class LibcameraCamera final : public Camera {
 public:
  ~LibcameraCamera() override;
  LibcameraCamera(const LibcameraCamera&) = delete;
  LibcameraCamera& operator=(const LibcameraCamera&) = delete;

  const char* backend() const override { return "libcamera"; }
  const std::string& id() const override { return id_; }

  /// The stream's formats for the role: each pixel format with each size the pipeline lists
  /// (or its largest size when it gives a range); rate 0 (libcamera lists no rates).
  [[nodiscard]] Result<std::vector<FrameFormat>> formats() override;
  /// Sets size and pixel format; a rate becomes FrameDurationLimits at start(). A configuration
  /// the pipeline marks Invalid, or Adjusted in size or pixel format, is refused (buffer count
  /// and stride adjustments are accepted).
  [[nodiscard]] Status set_format(const FrameFormat& format) override;
  FrameFormat format() const override { return format_; }

  [[nodiscard]] Status start() override;
  [[nodiscard]] Status stop() override;
  int fd() const override { return event_fd_; }
  [[nodiscard]] Result<Frame> dequeue() override;

  TimestampMeaning timestamp_meaning() const override { return TimestampMeaning::kStartOfExposure; }
  CameraCounters counters() const override;

  struct Session;  // buffers, mappings and requests of one start(), shared with held frames

 private:
  friend Result<std::unique_ptr<LibcameraCamera>> open_libcamera_camera(const std::string&,
                                                                        const LibcameraOptions&);
  LibcameraCamera(std::string id, std::shared_ptr<libcamera::CameraManager> manager,
                  std::shared_ptr<libcamera::Camera> camera, LibcameraOptions options);
  [[nodiscard]] Status configure();
  [[nodiscard]] Status check_rate(double rate_hz) const;
  void on_request_completed(libcamera::Request* request);
  void on_disconnected();
  Frame make_frame(libcamera::Request* request);

  std::string id_;
  std::shared_ptr<libcamera::CameraManager> manager_;  // outlives camera_
  std::shared_ptr<libcamera::Camera> camera_;
  LibcameraOptions options_;
  std::unique_ptr<libcamera::CameraConfiguration> config_;
  bool configured_ = false;
  FrameFormat format_;
  int event_fd_ = -1;
  std::shared_ptr<Session> session_;
  std::atomic<bool> lost_{false};

  std::mutex mutex_;  // completed_ is filled by the camera manager's thread
  std::deque<libcamera::Request*> completed_;

  bool have_sequence_ = false;
  std::uint32_t last_sequence_ = 0;
  std::atomic<std::uint64_t> frames_{0};
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> incomplete_{0};
  std::atomic<std::uint64_t> errors_{0};
};

}  // namespace imucal::drivers::camera
