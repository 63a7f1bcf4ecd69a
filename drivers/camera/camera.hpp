// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// One interface for every camera backend: V4L2 (v4l2/), libcamera (libcamera/), Aravis/GenICam
// (aravis/) and, as a peer, the virtual camera of the simulated rig (fake/). The rig assembly
// (app/) opens the backend a camera's configuration names; acquisition/ drives any of them the
// same way from its event loop:
//
//   open -> formats() / set_format() -> start() -> { wait for fd() readable; dequeue() }* -> stop()
//
// Time: every frame carries t_ns on CLOCK_MONOTONIC (int64 ns). What instant it marks is
// timestamp_meaning(): V4L2 drivers stamp the end of the frame (or the start of exposure, by a
// buffer flag), libcamera's SensorTimestamp is the start of exposure of the first line, Aravis
// device timestamps are mapped onto the host clock by the backend. The exposure time is given
// when the backend knows it, so the mid-exposure time can be derived (mid_exposure_ns()).
//
// Buffers: dequeue() hands out a Frame that owns one of the backend's buffers until it is
// destroyed (or release() is called); the buffer then goes back to the device. A backend has a
// small fixed set of buffers: a consumer that holds them all stalls the camera, which the
// backend counts as dropped frames. Frames must be released before the camera is destroyed.
//
// Threads: a camera is used from one thread (the acquisition thread); counters() may be read
// from any thread.

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::drivers::camera {

/// The instant a frame's t_ns marks.
enum class TimestampMeaning { kStartOfExposure, kMidExposure, kEndOfFrame };
/// "start-of-exposure", "mid-exposure", "end-of-frame" (the session log's timestamp_source).
const char* timestamp_meaning_name(TimestampMeaning meaning);

/// A frame format. pixel_format is the backend's own name: a V4L2 fourcc ("GREY", "YUYV"), a
/// libcamera PixelFormat name ("R8", "YUYV"), a GenICam PixelFormat ("Mono8").
struct FrameFormat {
  int width = 0;
  int height = 0;
  std::string pixel_format;
  double rate_hz = 0.0;  // 0: the device's default or unknown
};

/// Counters of one camera since open(); monotonic.
struct CameraCounters {
  std::uint64_t frames = 0;      // frames handed out by dequeue()
  std::uint64_t dropped = 0;     // frames the device produced but nobody got (sequence gaps, no free buffer)
  std::uint64_t incomplete = 0;  // frames the device reported as damaged or truncated (not handed out)
  std::uint64_t packets_lost = 0;  // GigE Vision / USB3 Vision only: packets missing or resent
  std::uint64_t errors = 0;        // failed dequeue/requeue calls
};

/// One captured frame. Owns its buffer (see above); move-only.
class Frame {
 public:
  Frame() = default;
  Frame(const Frame&) = delete;
  Frame& operator=(const Frame&) = delete;
  Frame(Frame&& other) noexcept { *this = std::move(other); }
  Frame& operator=(Frame&& other) noexcept;
  ~Frame() { release(); }

  TimeNs t_ns = 0;             // CLOCK_MONOTONIC, the instant timestamp_meaning() names
  TimeNs exposure_ns = 0;      // 0 when unknown
  std::uint32_t sequence = 0;  // the device's frame counter (gaps mean dropped frames)
  int width = 0;
  int height = 0;
  std::string pixel_format;
  std::size_t stride = 0;  // bytes per row of the first plane
  /// The pixels (first plane; for the formats imucal records there is one).
  std::span<const std::uint8_t> data;

  bool valid() const { return !data.empty(); }
  /// Gives the buffer back to the device now. Idempotent.
  void release();

  /// Backends build frames with a release action that requeues their buffer.
  void set_release(std::function<void()> release_action) { release_action_ = std::move(release_action); }

 private:
  std::function<void()> release_action_;
};

class Camera {
 public:
  virtual ~Camera() = default;

  /// The backend ("v4l2", "libcamera", "aravis", "sim") and the id it was opened with.
  virtual const char* backend() const = 0;
  virtual const std::string& id() const = 0;

  /// Formats the device offers (frame sizes and pixel formats; rate 0 where the device does not
  /// list rates).
  [[nodiscard]] virtual Result<std::vector<FrameFormat>> formats() = 0;
  /// Configures the stream before start(). A format the device does not accept is refused with
  /// kUnsupported naming what the device offers; a device that adjusts a field (a nearby size)
  /// is refused too, so a calibration is never taken at a resolution nobody asked for.
  [[nodiscard]] virtual Status set_format(const FrameFormat& format) = 0;
  /// The configured format.
  virtual FrameFormat format() const = 0;

  [[nodiscard]] virtual Status start() = 0;
  /// Stops streaming; frames still held stay valid until released. Idempotent.
  [[nodiscard]] virtual Status stop() = 0;

  /// A descriptor that turns readable when a frame may be ready (epoll/asio wait_read); -1 when
  /// the backend has none (then poll dequeue() on a timer).
  virtual int fd() const = 0;
  /// The next completed frame, or an invalid Frame when none is ready now (never blocks). An
  /// error means the device is gone or broken (kDevice, kNotFound); the stream cannot go on.
  [[nodiscard]] virtual Result<Frame> dequeue() = 0;

  virtual TimestampMeaning timestamp_meaning() const = 0;
  virtual CameraCounters counters() const = 0;
};

/// t_ns moved to the middle of the exposure, given the frame's meaning; frames without an
/// exposure time keep their stamp (end-of-frame stamps then lag by the readout time).
TimeNs mid_exposure_ns(const Frame& frame, TimestampMeaning meaning);

}  // namespace imucal::drivers::camera
