// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The V4L2 camera backend: a video capture node (/dev/videoN) streaming through mmap buffers.
// docs/cameras.md ("V4L2") describes what it does and refuses.
//
// Timestamps: V4L2 drivers stamp each buffer themselves; the buffer flags say on which clock
// (V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC is CLOCK_MONOTONIC) and what instant (end of frame, or start
// of exposure with V4L2_BUF_FLAG_TSTAMP_SRC_SOE). Stamps on another clock ("unknown", or copied
// from an output queue) are refused unless V4l2Options::stamp_at_dequeue allows stamping at
// dequeue time, which lags the end of the frame by the wake-up latency of the caller.
//
// Buffers: the mappings are shared by the camera and the frames it handed out, and unmapped
// when the last of them goes; a frame held across stop() or the camera's destruction keeps its
// pixels readable and is simply not requeued. A frame may be released from another thread than
// the camera's (the requeue is serialised with stop()).

#include <sys/types.h>

#include <cstddef>
#include <memory>
#include <string>

#include "core/time.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::drivers::camera {

/// The system calls the V4L2 backend makes. The default forwards to the kernel; tests substitute
/// a fake kernel (queues, formats, buffer flags) to check the backend without a device.
class V4l2Io {
 public:
  virtual ~V4l2Io() = default;
  /// open(2) with O_RDWR | O_NONBLOCK | O_CLOEXEC: a descriptor, or -errno.
  virtual int open(const std::string& path) = 0;
  virtual void close(int fd) = 0;
  /// ioctl(2): its result, or -errno (EINTR is retried).
  virtual int ioctl(int fd, unsigned long request, void* arg) = 0;
  /// mmap(2) of `length` bytes at `offset` of `fd`, shared and read-only: the address, or
  /// nullptr (errno set).
  virtual void* mmap(std::size_t length, int fd, off_t offset) = 0;
  virtual void munmap(void* address, std::size_t length) = 0;
  /// CLOCK_MONOTONIC, for stamping at dequeue time (V4l2Options::stamp_at_dequeue).
  virtual TimeNs monotonic_now_ns() = 0;
};

/// The kernel's open, close, ioctl, mmap, munmap and clock_gettime.
std::shared_ptr<V4l2Io> system_v4l2_io();

struct V4l2Options {
  /// mmap buffers requested at start() (the driver may grant more, or fewer but at least one).
  int buffers = 4;
  /// Drivers whose buffer stamps are not on CLOCK_MONOTONIC (timestamp type "unknown" or
  /// "copy") are refused at start(). With this set, such frames are stamped with
  /// CLOCK_MONOTONIC when dequeued instead: the stamp then marks the end of the frame plus the
  /// latency of the driver's completion and of the caller's wake-up (and any time the frame
  /// waited for the caller). Stamps on CLOCK_MONOTONIC are always used as the driver gives them.
  bool stamp_at_dequeue = false;
  /// The system calls; null means system_v4l2_io().
  std::shared_ptr<V4l2Io> io;
};

/// Opens a V4L2 video capture node. Errors: kNotFound (no such node; names the path),
/// kIo (permission denied: says to join the group `video`), kUnsupported (not a V4L2 device,
/// not a single-planar video capture device, or no streaming I/O), kInvalidArgument (options).
[[nodiscard]] Result<std::unique_ptr<Camera>> open_v4l2_camera(const std::string& device_path,
                                                               V4l2Options options = {});

/// "GREY" for V4L2_PIX_FMT_GREY: the four characters as the kernel stores them (trailing
/// blanks kept, "Y16 "); "-BE" appended for big-endian variants.
std::string fourcc_name(std::uint32_t fourcc);
/// The fourcc of a 4-character name (shorter names are padded with blanks); 0 when invalid.
std::uint32_t fourcc_from_name(const std::string& name);

}  // namespace imucal::drivers::camera
