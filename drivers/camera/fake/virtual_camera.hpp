// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The virtual camera: a peer of the V4L2, libcamera and Aravis backends (drivers/camera/camera.hpp)
// whose images come from a renderer the simulated rig supplies (sim/ builds it on the target
// renderer). It behaves as a camera does: a fixed set of buffers, frames at a fixed rate stamped
// at mid-exposure on the host clock, a descriptor to wait on, frames dropped and counted when no
// buffer is free, and it can be told to stall or to vanish (a yanked cable) for fault tests.
//
// Two clocks, as the simulated IMU has:
//   - a simulated clock (`clock` given): frames are rendered when dequeue() finds one due, on the
//     caller's thread, so a session is deterministic and runs as fast as the host renders;
//   - real time (no `clock`): a thread of its own sleeps on CLOCK_MONOTONIC until each frame's
//     end of exposure, renders it into a free buffer and signals the descriptor.
//
// Frame k has its mid-exposure at first_frame_ns + k / rate_hz; it becomes available at its end
// of exposure.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::drivers::camera::fake {

/// Renders frame `sequence` (mid-exposure at host time t_mid_ns, exposure exposure_ns) as 8-bit
/// grey rows of `width` bytes into `pixels` (width * height bytes).
using FrameRenderer =
    std::function<Status(TimeNs t_mid_ns, std::uint32_t sequence, std::span<std::uint8_t> pixels)>;

/// A test pattern, cheap enough for any frame rate (as vivid's and Aravis's fake cameras have):
/// a fixed texture of smooth gradients and pixel noise, shifted sideways by 3 pixels a frame, so
/// frames differ and compress as a textured scene does. For measuring the recording path
/// without the cost of rendering.
FrameRenderer test_pattern_renderer(int width, int height, std::uint64_t seed = 1);

struct VirtualCameraOptions {
  std::string id = "sim";
  int width = 640;
  int height = 480;
  double rate_hz = 20.0;
  TimeNs exposure_ns = 4'000'000;
  /// Host time of frame 0's mid-exposure.
  TimeNs first_frame_ns = 0;
  /// Frames the camera delivers before it stops (the end of a simulated session); 0: no limit.
  std::uint32_t frame_limit = 0;
  int buffers = 4;
  /// The simulated host clock; empty: real time (CLOCK_MONOTONIC, a rendering thread).
  std::function<TimeNs()> clock;
  // Faults, for tests of what the acquisition does with them.
  /// After this many frames the camera delivers nothing more (a camera that stops delivering).
  std::optional<std::uint32_t> stall_after;
  /// After this many frames dequeue() fails with kNotFound, as a camera unplugged mid-stream.
  std::optional<std::uint32_t> disconnect_after;
};

class VirtualCamera final : public Camera {
 public:
  /// Checks the options (sizes, rate, exposure shorter than the frame period, buffers >= 1).
  [[nodiscard]] static Result<std::unique_ptr<VirtualCamera>> create(const VirtualCameraOptions& options,
                                                                     FrameRenderer renderer);
  ~VirtualCamera() override;

  const char* backend() const override { return "sim"; }
  const std::string& id() const override { return options_.id; }
  [[nodiscard]] Result<std::vector<FrameFormat>> formats() override;
  /// Accepts only its own size, "GREY" and its own rate (a rate of 0 means any).
  [[nodiscard]] Status set_format(const FrameFormat& format) override;
  FrameFormat format() const override;
  [[nodiscard]] Status start() override;
  [[nodiscard]] Status stop() override;
  int fd() const override { return event_fd_; }
  [[nodiscard]] Result<Frame> dequeue() override;
  TimestampMeaning timestamp_meaning() const override { return TimestampMeaning::kMidExposure; }
  CameraCounters counters() const override;

  /// Host time of frame k's mid-exposure.
  TimeNs frame_time_ns(std::uint32_t k) const;

 private:
  VirtualCamera(const VirtualCameraOptions& options, FrameRenderer renderer);
  /// The index of the frame due next, under mutex_.
  bool due(std::uint32_t k, TimeNs now) const;
  /// Renders frame k into a free buffer and queues it; counts a drop when none is free.
  Status produce(std::uint32_t k);
  void thread_main();
  Frame make_frame(int buffer, std::uint32_t k);
  bool finished(std::uint32_t k) const;

  VirtualCameraOptions options_;
  FrameRenderer renderer_;
  TimeNs period_ns_ = 0;
  int event_fd_ = -1;
  std::vector<std::vector<std::uint8_t>> buffers_;

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::vector<int> free_;                            // buffer indices the device may fill
  std::deque<std::pair<int, std::uint32_t>> ready_;  // filled buffers and their frame index
  std::uint32_t next_ = 0;                           // next frame index to produce
  bool streaming_ = false;
  bool stopping_ = false;
  bool lost_ = false;
  Error render_error_;
  bool render_failed_ = false;
  CameraCounters counters_;
  std::thread thread_;
};

}  // namespace imucal::drivers::camera::fake
