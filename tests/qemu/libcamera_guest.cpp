// SPDX-License-Identifier: BSD-3-Clause
// Runs inside the QEMU guest (tests/qemu/run-in-qemu.sh --module vimc) against the kernel's
// virtual media-controller camera: the libcamera backend on libcamera 0.0.3's vimc pipeline
// handler (and its IPA module, package libcamera-ipa), over real V4L2 subdevices and buffers.
//
// vimc (built out of tree by build-kmod.sh) gives /dev/media0, /dev/video0..2 and
// /dev/v4l-subdev0..7; libcamera makes one camera of it, "platform/vimc.0 Sensor B", whose only
// stream is processed RGB (BGR888, RGB888; no raw format, whatever the role), sizes 48x48 to
// 4096x2160 in multiples of 6. Its SensorTimestamp is the V4L2 buffer's CLOCK_MONOTONIC stamp
// (microseconds: a timeval), which vimc's capture entity takes after the frame was generated and
// processed, as it copies it into the buffer: start of exposure by libcamera's definition, the end
// of the frame in fact (vimc has no exposure). vimc starts streaming only with two buffers queued.
// Usage: qemu_libcamera_guest [ID|auto [IMUCAL_CLI]]; with the CLI and the IMU rig of qemu.iio
// loaded as well, it ends with `imucal record` of that IMU and this camera (lc_record_checks).
// Prints one line per check, exits 0 only when all pass.

#include <poll.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <system_error>
#include <vector>

#include "core/time.hpp"
#include "drivers/camera/libcamera/libcamera_camera.hpp"
#include "tests/qemu/guest_support.hpp"
#include "tests/qemu/iio_stub_rig.hpp"

namespace {

using imucal::Errc;
using imucal::TimeNs;
namespace cam = imucal::drivers::camera;
namespace fs = std::filesystem;

using imucal::qemu::check;
using imucal::qemu::contains;
using imucal::qemu::failures;

// libcamera enumerates through libudev, which takes a device node without an entry in udev's
// database (/run/udev/data/c<major>:<minor>) for one udevd has not processed yet and leaves it
// out. The guest runs no udevd, so libcamera would find no camera: an empty entry per media and
// video4linux node marks it processed. /run is the guest's own tmpfs; on a host, udevd's
// database is left alone.
void lc_fake_udev_database() {
  if (std::getenv("IMUCAL_IN_QEMU") == nullptr) {
    std::printf("  not in the QEMU guest: relying on udevd's database\n");
    return;
  }
  std::error_code ec;
  fs::create_directories("/run/udev/data", ec);
  std::string made;
  for (const char* dir : {"/sys/bus/media/devices", "/sys/class/video4linux"}) {
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      std::ifstream in(entry.path() / "dev");
      std::string devnum;
      if (!(in >> devnum)) continue;
      const std::string path = "/run/udev/data/c" + devnum;
      std::ofstream(path).flush();
      made += (made.empty() ? "" : ", ") + path.substr(std::string("/run/udev/data/").size()) + " (" +
              entry.path().filename().string() + ")";
    }
  }
  std::printf("  udev database entries made: %s\n", made.empty() ? "none (no media device)" : made.c_str());
}

// The luma of one 24-bit RGB pixel. libcamera's names are DRM fourccs, little endian:
// BGR888 holds R, G, B in memory order, RGB888 holds B, G, R.
int lc_luma(const std::uint8_t* px, bool rgb_in_memory_order) {
  const int r = rgb_in_memory_order ? px[0] : px[2];
  const int b = rgb_in_memory_order ? px[2] : px[0];
  return (299 * r + 587 * px[1] + 114 * b) / 1000;
}

// vimc's sensor draws 75 % colour bars (white, yellow, cyan, green, magenta, red, blue, black;
// their luma falls from left to right only when the channels are read in the right order) with
// text at the top. The mean luma of the middle of each bar, on a row below the text.
std::vector<int> lc_bar_luma(const cam::Frame& frame, bool rgb_in_memory_order) {
  std::vector<int> bars;
  const std::size_t w = static_cast<std::size_t>(frame.width);
  const std::size_t row = static_cast<std::size_t>(frame.height) * 3 / 4;
  const std::uint8_t* line = frame.data.data() + row * frame.stride;
  for (std::size_t bar = 0; bar < 8; ++bar) {
    const std::size_t centre = (2 * bar + 1) * w / 16;
    const std::size_t half = w / 64;  // a quarter of the bar's width either side
    int sum = 0;
    for (std::size_t x = centre - half; x <= centre + half; ++x)
      sum += lc_luma(line + 3 * x, rgb_in_memory_order);
    bars.push_back(sum / static_cast<int>(2 * half + 1));
  }
  return bars;
}

struct LcStreamed : imucal::qemu::StreamedFrames {
  bool frames_ok = true;    // size, format, stride and buffer length as configured
  bool pixels_vary = true;  // no frame of a single luma value
  int luma_min = 255;       // over all frames (a sampled grid)
  int luma_max = 0;
  std::vector<int> bars;  // lc_bar_luma() of the last frame
};

// Dequeues `count` frames within `timeout_s`, checking each one's shape and pixels (every frame
// but the last is released at once: the camera keeps its buffers circulating).
LcStreamed lc_stream(cam::Camera& camera, int count, double timeout_s) {
  LcStreamed out;
  const cam::FrameFormat f = camera.format();
  const bool rgb_order = f.pixel_format == "BGR888";
  imucal::qemu::StreamedFrames& frames = out;
  frames = imucal::qemu::stream_frames(camera, count, timeout_s, [&](const cam::Frame& frame) {
    const auto w = static_cast<std::size_t>(frame.width);
    const auto h = static_cast<std::size_t>(frame.height);
    const bool shape_ok = frame.width == f.width && frame.height == f.height &&
                          frame.pixel_format == f.pixel_format && frame.stride >= 3 * w &&
                          frame.data.size() >= frame.stride * (h - 1) + 3 * w;
    out.frames_ok = out.frames_ok && shape_ok;
    if (!shape_ok) return;
    int lo = 255;
    int hi = 0;
    for (std::size_t y = 0; y < h; y += 7) {
      for (std::size_t x = 0; x < w; x += 5) {
        const int l = lc_luma(frame.data.data() + y * frame.stride + 3 * x, rgb_order);
        lo = std::min(lo, l);
        hi = std::max(hi, l);
      }
    }
    out.pixels_vary = out.pixels_vary && hi > lo;
    out.luma_min = std::min(out.luma_min, lo);
    out.luma_max = std::max(out.luma_max, hi);
    out.bars = lc_bar_luma(frame, rgb_order);
  });
  return out;
}

TimeNs lc_median(std::vector<TimeNs> v) {
  if (v.empty()) return 0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// The checks every stream gets; `after_ns` is a stamp every frame must follow (the last one of
// an earlier stream), 0 for none.
void lc_check_stream(const LcStreamed& s, int count, const std::string& what, TimeNs after_ns) {
  check(s.error.empty() && static_cast<int>(s.t_ns.size()) == count,
        what + ": " + std::to_string(count) + " frames",
        s.error.empty() ? std::to_string(s.t_ns.size()) + " frames in " + std::to_string(s.elapsed_s) + " s"
                        : s.error);
  if (s.t_ns.empty()) return;
  check(s.frames_ok, what + ": every frame has the configured size and format and a full buffer");
  check(s.pixels_vary, what + ": the pixels are vimc's pattern, not one value",
        "luma " + std::to_string(s.luma_min) + ".." + std::to_string(s.luma_max));
  std::string bar_text;
  bool falling = s.bars.size() == 8;
  for (std::size_t i = 0; i < s.bars.size(); ++i) {
    bar_text += (i == 0 ? "" : " ") + std::to_string(s.bars[i]);
    falling = falling && (i == 0 || s.bars[i] < s.bars[i - 1]);
  }
  check(falling, what + ": the colour bars' luma falls from left to right (channel order, stride)",
        "bar luma " + bar_text);
  bool increasing = s.t_ns.front() > after_ns;
  bool consecutive = true;
  std::vector<TimeNs> lag_ns;
  for (std::size_t i = 0; i < s.t_ns.size(); ++i) {
    if (i > 0) {
      increasing = increasing && s.t_ns[i] > s.t_ns[i - 1];
      consecutive = consecutive && s.sequence[i] == s.sequence[i - 1] + 1;
    }
    lag_ns.push_back(s.dequeued_ns[i] - s.t_ns[i]);
  }
  check(increasing, what + ": timestamps increase" + (after_ns > 0 ? ", after those before the stop" : ""));
  check(consecutive, what + ": sequence numbers consecutive",
        std::to_string(s.sequence.front()) + ".." + std::to_string(s.sequence.back()));
  const TimeNs min_lag_ns = *std::min_element(lag_ns.begin(), lag_ns.end());
  const TimeNs max_lag_ns = *std::max_element(lag_ns.begin(), lag_ns.end());
  // vimc stamps a buffer as it copies the finished frame into it, so the stamp precedes its
  // dequeue; within 1 s shows the clock is CLOCK_MONOTONIC.
  check(min_lag_ns >= 0 && max_lag_ns < imucal::kNsPerSecond,
        what + ": stamps on CLOCK_MONOTONIC, before their dequeue and within 1 s of it",
        "stamp to dequeue " + std::to_string(min_lag_ns / 1000) + ".." + std::to_string(max_lag_ns / 1000) +
            " us, median " + std::to_string(lc_median(lag_ns) / 1000) + " us");
  const auto whole_us = std::count_if(s.t_ns.begin(), s.t_ns.end(), [](TimeNs t) { return t % 1000 == 0; });
  std::printf("  %s: %zd of %zu stamps are whole microseconds\n", what.c_str(),
              static_cast<std::ptrdiff_t>(whole_us), s.t_ns.size());
  if (s.t_ns.size() > 1) {
    const double span_s = imucal::ns_to_s(s.t_ns.back() - s.t_ns.front());
    std::printf("  %s: %.2f frames/s by the stamps, frame interval median %.1f ms\n", what.c_str(),
                static_cast<double>(s.t_ns.size() - 1) / span_s,
                imucal::ns_to_s(imucal::median_interval_ns(s.t_ns)) * 1e3);
  }
}

std::string lc_format_text(const cam::FrameFormat& f) {
  char rate[32];
  std::snprintf(rate, sizeof rate, "%g", f.rate_hz);
  return f.pixel_format + " " + std::to_string(f.width) + "x" + std::to_string(f.height) + " at " + rate +
         " Hz";
}

// The list, an unknown id, and the vimc camera's id (argv[1] or the one whose id names vimc).
std::string lc_list_checks(const std::string& wanted) {
  auto ids = cam::list_libcamera_cameras();
  std::string all;
  std::string vimc;
  if (ids.ok()) {
    for (const auto& id : *ids) {
      all += (all.empty() ? "'" : ", '") + id + "'";
      if (wanted.empty() ? contains(id, "vimc") : id == wanted) vimc = id;
    }
  }
  check(ids.ok() && !vimc.empty(), "list_libcamera_cameras() finds the vimc camera",
        ids.ok() ? (all.empty() ? "no cameras" : all) : ids.error().message);
  auto unknown = cam::open_libcamera_camera("platform/vimc.9 Sensor Z");
  check(!unknown.ok() && unknown.error().code == Errc::kNotFound &&
            contains(unknown.error().message, "platform/vimc.9 Sensor Z") &&
            (vimc.empty() || contains(unknown.error().message, vimc)),
        "an unknown id is kNotFound, naming it and the cameras found",
        unknown.ok() ? "opened" : unknown.error().message);
  return vimc;
}

// Formats: the list, refusals with their reasons, and BGR888 636x480 set and read back.
bool lc_format_checks(cam::Camera& camera) {
  auto list = camera.formats();
  std::string pixel_formats;
  if (list.ok()) {
    for (const auto& f : *list) {
      if (!contains(pixel_formats, f.pixel_format))
        pixel_formats += (pixel_formats.empty() ? "" : " ") + f.pixel_format;
    }
  }
  check(list.ok() && !list->empty() && contains(pixel_formats, "BGR888"), "formats() lists BGR888",
        list.ok() ? std::to_string(list->size()) + " entries, pixel formats " + pixel_formats
                  : list.error().message);
  if (!list.ok()) return false;

  // libcamera turns the pipeline's size range into the common sizes inside it
  // (StreamFormats::sizes), which ignores vimc's multiples of 6; formats() lists only those the
  // pipeline takes as they are, so every listed entry is set.
  int taken = 0;
  int refused = 0;
  std::string adjusted;  // each size once (the pixel formats list the same sizes)
  std::string other;
  for (const auto& f : *list) {
    auto s = camera.set_format(f);
    const std::string size = std::to_string(f.width) + "x" + std::to_string(f.height);
    if (s.ok()) {
      ++taken;
    } else if (s.error().code == Errc::kUnsupported && contains(s.error().message, "adjusted")) {
      ++refused;
      if (!contains(" " + adjusted + " ", " " + size + " ")) adjusted += (adjusted.empty() ? "" : " ") + size;
    } else {
      other += (other.empty() ? "" : "; ") + s.error().message;
    }
  }
  check(other.empty() && refused == 0 && taken == static_cast<int>(list->size()),
        "every listed format is set (formats() leaves out the sizes vimc would adjust)",
        std::to_string(taken) + " set" +
            (adjusted.empty() ? ""
                              : "; " + std::to_string(refused) + " refused as adjusted, sizes " + adjusted) +
            (other.empty() ? "" : "; other errors: " + other));

  auto grey = camera.set_format({636, 480, "R8", 0.0});
  check(!grey.ok() && grey.error().code == Errc::kUnsupported && contains(grey.error().message, "'R8'") &&
            contains(grey.error().message, "BGR888"),
        "R8 refused, naming it and what the camera offers", grey.ok() ? "accepted" : grey.error().message);
  auto odd = camera.set_format({640, 480, "BGR888", 0.0});
  check(!odd.ok() && odd.error().code == Errc::kUnsupported && contains(odd.error().message, "640x480") &&
            contains(odd.error().message, "636x480"),
        "BGR888 640x480 refused: vimc would adjust it to 636x480",
        odd.ok() ? "accepted" : odd.error().message);
  auto huge = camera.set_format({99999, 3, "BGR888", 0.0});
  check(!huge.ok() && huge.error().code == Errc::kUnsupported && contains(huge.error().message, "99999x3"),
        "BGR888 99999x3 refused", huge.ok() ? "accepted" : huge.error().message);
  // vimc's pipeline has no FrameDurationLimits control: its rate cannot be set, only 0 is taken.
  auto rate = camera.set_format({636, 480, "BGR888", 15.0});
  check(!rate.ok() && rate.error().code == Errc::kUnsupported,
        "BGR888 636x480 at 15 Hz refused (no frame rate control)",
        rate.ok() ? "accepted" : rate.error().message);

  const cam::FrameFormat want{636, 480, "BGR888", 0.0};
  auto set = camera.set_format(want);
  check(set.ok(), "set_format BGR888 636x480 (rate 0)", set.ok() ? "" : set.error().message);
  const cam::FrameFormat f = camera.format();
  check(f.width == want.width && f.height == want.height && f.pixel_format == want.pixel_format &&
            f.rate_hz == 0.0,
        "format() reads it back", lc_format_text(f));
  return set.ok();
}

// The frame held across stop() is compared with a copy taken before it.
bool lc_same_pixels(const cam::Frame& frame, const std::vector<std::uint8_t>& copy) {
  return frame.valid() && std::equal(frame.data.begin(), frame.data.end(), copy.begin(), copy.end());
}

}  // namespace

// `imucal record` on a rig of this camera and the kernel's MPU-6000 driver (the qemu.iio rig:
// i2c-stub, inv-mpu6050 and imucal-irq-i2c, tests/qemu/iio_stub_rig.hpp), while the data-ready
// pulses come: the IMU's samples and the camera's frames (BGR888, recorded as their luma) in one
// log on one clock, which `imucal info` reads.
void lc_record_checks(const std::string& id, const std::string& cli) {
  namespace q = imucal::qemu;
  if (!fs::exists(q::kParams)) {
    std::printf(
        "  record: not run: the IMU's modules are not loaded (i2c-stub, i2c-dev, inv-mpu6050-i2c, "
        "imucal-irq-i2c)\n");
    return;
  }
  check(q::prepare_stub() && q::attach(true), "the IMU rig: inv-mpu6050 on i2c-stub with an interrupt");
  const std::string tmp = std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp";
  const std::string config = tmp + "/libcamera-rig.yaml";
  const std::string log = tmp + "/libcamera.imulog";
  std::ofstream(config) << "name: qemu-libcamera\n"
                        << "imu: {bus: i2c, device: /dev/i2c-0, driver: auto, rate_hz: 200, dlpf_hz: 98}\n"
                        << "cameras:\n  - {name: cam0, backend: libcamera, device: '" << id
                        << "', width: 636, height: 480, rate_hz: 0, pixel_format: BGR888}\n"
                        << "target: {target_type: checkerboard, targetCols: 7, targetRows: 6, "
                        << "rowSpacingMeters: 0.06, colSpacingMeters: 0.06}\n";
  q::Pulses pulses(200.0);
  pulses.start(
      200 * 120);  // until the recording has ended (stop() below): its start in a loaded guest took seconds
  auto run = [&](const std::string& args, std::string& out) {
    const std::string out_path = tmp + "/cli.out";
    const int rc = std::system((cli + " " + args + " >" + out_path + " 2>&1").c_str());
    out = q::read_text(out_path);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  };
  std::string out;
  const int rc = run("record --config " + config + " --duration 3 --output " + log + " --force", out);
  pulses.stop();
  check(rc == 0, "imucal record: the kernel's IMU driver and the libcamera camera into one log", out);
  std::string info;
  const int irc = run("info --json " + log, info);
  std::int64_t samples = 0, frames = 0;
  std::string cam_device;
  try {
    const auto j = nlohmann::json::parse(info);
    samples = j.at("imu_streams").at(0).at("count");
    frames = j.at("camera_streams").at(0).at("count");
    cam_device = j.at("camera_streams").at(0).at("device");
  } catch (const std::exception& e) {
    cam_device = std::string("(") + e.what() + ")";
  }
  // vimc's frame rate under TCG falls to a few per second while imucal encodes (8 in 3 s seen).
  check(irc == 0 && samples >= 500 && frames >= 3 && cam_device == id,
        "imucal info reads it: IMU samples and the camera's frames",
        std::to_string(samples) + " samples, " + std::to_string(frames) + " frames from " + cam_device);
}

int main(int argc, char** argv) {
  const TimeNs begin_ns = imucal::monotonic_now_ns();
  // libcamera logs at INFO to stderr, a line per configure(); its warnings are enough here. Run
  // the program through `env LIBCAMERA_LOG_LEVELS='*:DEBUG'` to see everything.
  ::setenv("LIBCAMERA_LOG_LEVELS", "*:WARN", 0);
  // Without its IPA module the vimc pipeline handler makes no camera; a missing package is a
  // skip (exit 77, as run-in-qemu.sh's own), not a failure of the backend.
  const fs::path ipa = fs::path(IMUCAL_LIBCAMERA_IPA_DIR) / "ipa_vimc.so";
  if (std::error_code ec; !fs::exists(ipa, ec)) {
    std::printf(
        "SKIP: libcamera's vimc IPA module %s is missing: install the package libcamera-ipa "
        "(scripts/install-deps.sh --test)\n",
        ipa.c_str());
    return 77;
  }
  lc_fake_udev_database();
  const std::string id = lc_list_checks(argc > 1 && std::string(argv[1]) != "auto" ? argv[1] : "");
  if (id.empty()) {
    std::printf("FAIL: no vimc camera; %d failed check(s)\n", failures);
    return 1;
  }
  auto opened = cam::open_libcamera_camera(id);
  if (!opened.ok()) {
    std::printf("FAIL - open '%s': %s\n", id.c_str(), opened.error().message.c_str());
    return 1;
  }
  cam::Camera& camera = **opened;
  check(std::string(camera.backend()) == "libcamera" && camera.id() == id, "open '" + id + "'",
        "default " + lc_format_text(camera.format()));
  check(camera.timestamp_meaning() == cam::TimestampMeaning::kStartOfExposure,
        "timestamp_meaning() is start of exposure (libcamera's SensorTimestamp)");
  auto twice = cam::open_libcamera_camera(id);
  check(!twice.ok() && twice.error().code == Errc::kDevice, "a second open of the acquired camera is kDevice",
        twice.ok() ? "opened" : twice.error().message);

  std::vector<TimeNs> all_lag_ns;
  int all_frames = 0;
  double all_elapsed_s = 0.0;
  auto gather = [&](const LcStreamed& s) {
    for (std::size_t i = 0; i < s.t_ns.size(); ++i) all_lag_ns.push_back(s.dequeued_ns[i] - s.t_ns[i]);
    all_frames += static_cast<int>(s.t_ns.size());
    all_elapsed_s += s.elapsed_s;
  };

  if (lc_format_checks(camera)) {
    constexpr int kFrames = 20;
    auto s = camera.start();
    check(s.ok(), "start", s.ok() ? "" : s.error().message);
    LcStreamed first = lc_stream(camera, kFrames, 30.0);
    lc_check_stream(first, kFrames, "stream", 0);
    gather(first);
    const auto c = camera.counters();
    check(c.frames == kFrames && c.dropped == 0 && c.incomplete == 0 && c.errors == 0,
          "counters: " + std::to_string(kFrames) + " frames, none dropped or incomplete, no errors",
          std::to_string(c.frames) + " frames, " + std::to_string(c.dropped) + " dropped, " +
              std::to_string(c.incomplete) + " incomplete, " + std::to_string(c.errors) + " errors");

    // camera.hpp: frames still held after stop() stay valid until released.
    cam::Frame held = std::move(first.last);
    const std::vector<std::uint8_t> copy(held.data.begin(), held.data.end());
    auto stopped = camera.stop();
    check(stopped.ok() && lc_same_pixels(held, copy), "stop() with a frame held; its pixels stay readable",
          stopped.ok() ? std::to_string(copy.size()) + " bytes unchanged" : stopped.error().message);
    check(camera.stop().ok(), "stop() again (idempotent)");
    auto none = camera.dequeue();
    check(none.ok() && !none->valid(), "dequeue() after stop(): no frame, no error",
          none.ok() ? "" : none.error().message);

    s = camera.start();
    check(s.ok(), "restart with the old frame still held", s.ok() ? "" : s.error().message);
    LcStreamed again = lc_stream(camera, 10, 30.0);
    const TimeNs before_ns = first.t_ns.empty() ? 0 : first.t_ns.back();
    lc_check_stream(again, 10, "restart", before_ns);
    gather(again);
    if (!again.sequence.empty())
      std::printf("  restart: sequence starts again at %u\n", again.sequence.front());
    check(lc_same_pixels(held, copy), "the frame held since before the stop is unchanged after the restart");
    held.release();  // belongs to the stopped session: must not be queued into the new one
    again.last.release();
    LcStreamed more = lc_stream(camera, 5, 30.0);
    check(more.error.empty() && more.t_ns.size() == 5 && !again.sequence.empty() &&
              more.sequence.front() == again.sequence.back() + 1,
          "releasing the old frame leaves the new stream going",
          more.error.empty() ? std::to_string(more.t_ns.size()) + " more frames" : more.error);
    gather(more);
    const auto c2 = camera.counters();
    check(c2.dropped == 0 && c2.incomplete == 0 && c2.errors == 0, "counters after the restart: no loss",
          std::to_string(c2.frames) + " frames, " + std::to_string(c2.dropped) + " dropped, " +
              std::to_string(c2.errors) + " errors");
    more.last.release();
    check(camera.stop().ok(), "stop");

    // The other channel order: the bars must come out the same.
    auto rgb = camera.set_format({636, 480, "RGB888", 0.0});
    check(rgb.ok(), "set_format RGB888 636x480 after the stop", rgb.ok() ? "" : rgb.error().message);
    if (rgb.ok()) {
      s = camera.start();
      LcStreamed other = lc_stream(camera, 3, 30.0);
      lc_check_stream(other, 3, "RGB888", 0);
      gather(other);
      other.last.release();
      check(s.ok() && camera.stop().ok(), "RGB888 start and stop", s.ok() ? "" : s.error().message);
    }
  }

  opened->reset();  // the recording opens the camera itself
  if (argc > 2) lc_record_checks(id, argv[2]);

  if (!all_lag_ns.empty()) {
    std::printf(
        "  figures: %d frames at 636x480, %.1f frames/s received; stamp to dequeue median %.2f ms, "
        "max %.2f ms\n",
        all_frames, static_cast<double>(all_frames) / all_elapsed_s,
        imucal::ns_to_s(lc_median(all_lag_ns)) * 1e3,
        imucal::ns_to_s(*std::max_element(all_lag_ns.begin(), all_lag_ns.end())) * 1e3);
  }
  std::printf("  run took %.1f s\n", imucal::ns_to_s(imucal::monotonic_now_ns() - begin_ns));
  std::printf("%s: %d failed check(s)\n", failures == 0 ? "PASS" : "FAIL", failures);
  return failures == 0 ? 0 : 1;
}
