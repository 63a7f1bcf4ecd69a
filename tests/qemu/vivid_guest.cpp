// SPDX-License-Identifier: BSD-3-Clause
// Runs inside the QEMU guest (tests/qemu/run-in-qemu.sh --module vivid) against the kernel's
// virtual video driver: the V4L2 camera backend on a real V4L2 stack (videobuf2, mmap buffers,
// driver timestamps).
//
// vivid's default instance has four video nodes: /dev/video0 captures (input 0 is a "webcam"
// with discrete sizes and frame intervals), /dev/video1 is a video output, /dev/video2 and 3
// are metadata nodes. Its "Vivid Controls" include error injection; "Disconnect"
// (VIVID_CID_DISCONNECT) unregisters the nodes as an unplugged USB camera would, after which
// every ioctl fails with ENODEV. "Timestamp Source" switches the buffers' stamp between end of
// frame and start of exposure. Under TCG vivid produces about 5 frames per second.
// Prints one line per check, exits 0 only when all pass.

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "core/time.hpp"
#include "drivers/camera/v4l2/v4l2_camera.hpp"
#include "tests/qemu/guest_support.hpp"

namespace {

using imucal::Errc;
using imucal::TimeNs;
namespace cam = imucal::drivers::camera;

using imucal::qemu::check;
using imucal::qemu::contains;
using imucal::qemu::failures;

// Sets a control found by its name (vivid's own controls have no public ids) through a second
// descriptor on the node, as another program would.
bool set_control(const std::string& device, const char* name, int value) {
  const int fd = ::open(device.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return false;
  bool done = false;
  v4l2_queryctrl q{};
  q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
  while (!done && ::ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
    if (std::strcmp(reinterpret_cast<const char*>(q.name), name) == 0) {
      v4l2_ext_control c{};
      c.id = q.id;
      c.value = value;
      v4l2_ext_controls cs{};
      cs.which = V4L2_CTRL_WHICH_CUR_VAL;
      cs.count = 1;
      cs.controls = &c;
      done = ::ioctl(fd, VIDIOC_S_EXT_CTRLS, &cs) == 0;
      if (!done) std::printf("  VIDIOC_S_EXT_CTRLS '%s': %s\n", name, std::strerror(errno));
      break;
    }
    q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
  }
  ::close(fd);
  return done;
}

// Up to `count` frames within `timeout_s` (stream_frames(): the last one still held), and
// whether each had the configured size and format and a full buffer.
struct Streamed : imucal::qemu::StreamedFrames {
  bool frames_ok = true;
};

Streamed stream(cam::Camera& camera, int count, double timeout_s) {
  Streamed out;
  const cam::FrameFormat f = camera.format();
  imucal::qemu::StreamedFrames& frames = out;
  frames = imucal::qemu::stream_frames(camera, count, timeout_s, [&](const cam::Frame& frame) {
    out.frames_ok = out.frames_ok && frame.width == f.width && frame.height == f.height &&
                    frame.pixel_format == f.pixel_format &&
                    frame.data.size() >= frame.stride * static_cast<std::size_t>(frame.height) &&
                    frame.stride >= static_cast<std::size_t>(frame.width);
  });
  return out;
}

void check_stream(const Streamed& s, int count, const char* what, cam::TimestampMeaning camera_meaning) {
  check(s.error.empty() && static_cast<int>(s.t_ns.size()) == count,
        std::string(what) + ": " + std::to_string(count) + " frames",
        s.error.empty() ? std::to_string(s.t_ns.size()) + " frames" : s.error);
  check(s.frames_ok, std::string(what) + ": every frame has the configured size, format and a full buffer");
  bool increasing = true;
  bool sequence_up = true;
  TimeNs min_lag_ns = 0;
  TimeNs max_lag_ns = 0;
  for (std::size_t i = 0; i < s.t_ns.size(); ++i) {
    if (i > 0) {
      increasing = increasing && s.t_ns[i] > s.t_ns[i - 1];
      sequence_up = sequence_up && s.sequence[i] > s.sequence[i - 1];
    }
    // CLOCK_MONOTONIC: the stamp precedes its dequeue, and not by much.
    const TimeNs lag_ns = s.dequeued_ns[i] - s.t_ns[i];
    min_lag_ns = i == 0 ? lag_ns : std::min(min_lag_ns, lag_ns);
    max_lag_ns = i == 0 ? lag_ns : std::max(max_lag_ns, lag_ns);
  }
  check(increasing, std::string(what) + ": timestamps increase");
  check(sequence_up, std::string(what) + ": sequence numbers increase");
  // vivid's end-of-frame stamp is the frame's scheduled end, which it delivers early: the stamp
  // may lead its dequeue by up to a frame period. A start-of-exposure stamp precedes it.
  const bool soe = camera_meaning == cam::TimestampMeaning::kStartOfExposure;
  check(
      std::llabs(min_lag_ns) < imucal::kNsPerSecond && std::llabs(max_lag_ns) < imucal::kNsPerSecond &&
          (!soe || min_lag_ns >= 0),
      std::string(what) + ": stamps on CLOCK_MONOTONIC, within 1 s of their dequeue" +
          (soe ? " and before it" : ""),
      "dequeue lag " + std::to_string(min_lag_ns / 1000) + ".." + std::to_string(max_lag_ns / 1000) + " us");
  if (s.t_ns.size() > 1) {
    const double period_s =
        imucal::ns_to_s(s.t_ns.back() - s.t_ns.front()) / static_cast<double>(s.t_ns.size() - 1);
    std::printf("  %s: %.2f frames/s (sequence %u..%u)\n", what, 1.0 / period_s, s.sequence.front(),
                s.sequence.back());
  }
}

void open_checks() {
  auto missing = cam::open_v4l2_camera("/dev/video99");
  check(!missing.ok() && missing.error().code == Errc::kNotFound &&
            contains(missing.error().message, "/dev/video99"),
        "missing /dev/video99: not found, named", missing.ok() ? "opened" : missing.error().message);
  auto output = cam::open_v4l2_camera("/dev/video1");
  check(!output.ok() && output.error().code == Errc::kUnsupported &&
            contains(output.error().message, "not a video capture device"),
        "vivid's output node /dev/video1 is refused", output.ok() ? "opened" : output.error().message);
}

// Formats, a refused size, and GREY 640x480 at a listed rate near 10 fps.
bool format_checks(cam::Camera& camera) {
  auto list = camera.formats();
  check(list.ok() && !list->empty(), "formats() lists formats",
        list.ok() ? std::to_string(list->size()) + " combinations" : list.error().message);
  if (!list.ok()) return false;
  double rate_hz = 0.0;
  for (const auto& f : *list) {
    if (f.pixel_format == "GREY" && f.width == 640 && f.height == 480 &&
        (rate_hz == 0.0 || std::abs(f.rate_hz - 10.0) < std::abs(rate_hz - 10.0))) {
      rate_hz = f.rate_hz;
    }
  }
  check(rate_hz > 0.0, "GREY 640x480 listed with frame rates", "chose " + std::to_string(rate_hz) + " fps");

  auto refused = camera.set_format({99999, 3, "GREY", 0.0});
  check(!refused.ok() && refused.error().code == Errc::kUnsupported &&
            contains(refused.error().message, "GREY 99999x3") && contains(refused.error().message, "640x480"),
        "GREY 99999x3 refused, naming what was asked and what is offered",
        refused.ok() ? "accepted" : refused.error().message);
  auto bad_rate = camera.set_format({640, 480, "GREY", 7.3});
  check(!bad_rate.ok() && bad_rate.error().code == Errc::kUnsupported, "GREY 640x480 at 7.3 fps refused",
        bad_rate.ok() ? "accepted" : bad_rate.error().message);

  auto set = camera.set_format({640, 480, "GREY", rate_hz});
  check(set.ok(), "set_format GREY 640x480", set.ok() ? "" : set.error().message);
  const cam::FrameFormat f = camera.format();
  check(f.width == 640 && f.height == 480 && f.pixel_format == "GREY" && std::abs(f.rate_hz - rate_hz) < 1e-6,
        "format() reads back GREY 640x480 at the chosen rate");
  return set.ok();
}

void disconnect_checks(cam::Camera& camera, const std::string& device) {
  auto s = camera.start();
  check(s.ok(), "start before the disconnect", s.ok() ? "" : s.error().message);
  check(set_control(device, "Disconnect", 0), "vivid 'Disconnect' control pressed");
  // Frames may still be queued; the error must come within a few seconds, never a hang.
  const Streamed after = stream(camera, 1000, 10.0);
  check(after.error_code == Errc::kNotFound && contains(after.error, "camera " + device + " disconnected"),
        "dequeue after the disconnect: the disconnect error", after.error.empty() ? "no error" : after.error);
  check(camera.counters().errors >= 1, "the failed dequeue is counted");
  auto stopped = camera.stop();
  check(stopped.ok(), "stop() after the disconnect", stopped.ok() ? "" : stopped.error().message);
  auto reopen = cam::open_v4l2_camera(device);
  check(!reopen.ok() && reopen.error().code == Errc::kNotFound, "reopening the unplugged node: not found",
        reopen.ok() ? "opened" : reopen.error().message);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string device = argc > 1 ? argv[1] : "/dev/video0";
  open_checks();
  auto opened = cam::open_v4l2_camera(device);
  if (!opened.ok()) {
    std::printf("FAIL - open %s: %s\n", device.c_str(), opened.error().message.c_str());
    return 1;
  }
  cam::Camera& camera = **opened;
  check(std::string(camera.backend()) == "v4l2" && camera.id() == device, "open " + device);
  if (format_checks(camera)) {
    auto s = camera.start();
    check(s.ok(), "start", s.ok() ? "" : s.error().message);
    check(camera.timestamp_meaning() == cam::TimestampMeaning::kEndOfFrame,
          "vivid stamps the end of the frame");
    Streamed first = stream(camera, 10, 30.0);
    check_stream(first, 10, "stream", camera.timestamp_meaning());
    const auto c = camera.counters();
    check(c.frames == 10 && c.incomplete == 0 && c.errors == 0,
          "counters: 10 frames, none incomplete, no errors", "dropped " + std::to_string(c.dropped));
    // A frame held across stop() stays readable and is not requeued.
    const cam::Frame held = std::move(first.last);
    auto stopped = camera.stop();
    unsigned sum = 0;
    for (auto b : held.data) sum += b;
    check(stopped.ok() && held.valid(), "stop() with a frame still held; its pixels stay readable",
          stopped.ok() ? "pixel sum " + std::to_string(sum) : stopped.error().message);

    check(set_control(device, "Timestamp Source", 1), "vivid 'Timestamp Source' set to start of exposure");
    s = camera.start();
    check(s.ok() && camera.timestamp_meaning() == cam::TimestampMeaning::kStartOfExposure,
          "restart: timestamps now mark the start of exposure", s.ok() ? "" : s.error().message);
    check_stream(stream(camera, 3, 20.0), 3, "restart", camera.timestamp_meaning());
    check(camera.stop().ok(), "stop");
    set_control(device, "Timestamp Source", 0);
  }
  disconnect_checks(camera, device);
  std::printf("%s: %d failed check(s)\n", failures == 0 ? "PASS" : "FAIL", failures);
  return failures == 0 ? 0 : 1;
}
