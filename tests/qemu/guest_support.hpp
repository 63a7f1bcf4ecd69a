// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the QEMU guest programs share: a check line per result ("ok - ..." / "FAIL - ..."), and
// a camera's frames taken the way a consumer takes them (wait on fd(), dequeue).

#include <poll.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::qemu {

/// Checks that failed so far in this program.
inline int failures = 0;

inline void check(bool ok, const std::string& what, const std::string& detail = "") {
  std::printf("%s - %s%s%s\n", ok ? "ok" : "FAIL", what.c_str(), detail.empty() ? "" : ": ", detail.c_str());
  std::fflush(stdout);
  if (!ok) ++failures;
}

inline bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

/// Frames taken from a camera, with the host's time at each dequeue.
struct StreamedFrames {
  std::vector<TimeNs> t_ns;
  std::vector<TimeNs> dequeued_ns;
  std::vector<std::uint32_t> sequence;
  drivers::camera::Frame last;  // the last frame, still held
  std::string error;            // the dequeue error that ended the stream, if any
  Errc error_code = Errc::kInternal;
  double elapsed_s = 0.0;  // from the first wait to the last frame
};

/// Waits on fd() and dequeues up to `count` frames within `timeout_s`. `on_frame` sees each
/// frame; every frame but the last is released when the next one comes.
template <class OnFrame>
StreamedFrames stream_frames(drivers::camera::Camera& camera, int count, double timeout_s,
                             OnFrame&& on_frame) {
  StreamedFrames out;
  const TimeNs begin_ns = monotonic_now_ns();
  const TimeNs deadline = begin_ns + s_to_ns(timeout_s);
  while (static_cast<int>(out.t_ns.size()) < count && monotonic_now_ns() < deadline) {
    pollfd p{camera.fd(), POLLIN, 0};
    ::poll(&p, 1, 1000);
    auto frame = camera.dequeue();
    if (!frame.ok()) {
      out.error = frame.error().message;
      out.error_code = frame.error().code;
      break;
    }
    if (!frame->valid()) continue;
    out.dequeued_ns.push_back(monotonic_now_ns());
    out.t_ns.push_back(frame->t_ns);
    out.sequence.push_back(frame->sequence);
    on_frame(*frame);
    out.last = std::move(*frame);
  }
  out.elapsed_s = ns_to_s(monotonic_now_ns() - begin_ns);
  return out;
}

}  // namespace imucal::qemu
