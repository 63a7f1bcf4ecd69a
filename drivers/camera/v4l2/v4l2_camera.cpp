// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/camera/v4l2/v4l2_camera.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <numeric>
#include <vector>

namespace imucal::drivers::camera {
namespace {

class SystemV4l2Io final : public V4l2Io {
 public:
  int open(const std::string& path) override {
    const int fd = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
    return fd < 0 ? -errno : fd;
  }
  void close(int fd) override { ::close(fd); }
  int ioctl(int fd, unsigned long request, void* arg) override {
    int r = 0;
    do {
      r = ::ioctl(fd, request, arg);
    } while (r < 0 && errno == EINTR);
    return r < 0 ? -errno : r;
  }
  void* mmap(std::size_t length, int fd, off_t offset) override {
    void* p = ::mmap(nullptr, length, PROT_READ, MAP_SHARED, fd, offset);
    return p == MAP_FAILED ? nullptr : p;
  }
  void munmap(void* address, std::size_t length) override { ::munmap(address, length); }
  TimeNs monotonic_now_ns() override { return imucal::monotonic_now_ns(); }
};

constexpr std::uint32_t kCapture = V4L2_BUF_TYPE_VIDEO_CAPTURE;
constexpr int kMaxBuffers = VIDEO_MAX_FRAME;

// What the camera and its frames share: the descriptor (closed when the camera goes), the
// counters (read from any thread), and the lock that orders a frame's requeue, which may come
// from another thread, against stop() and close.
struct DeviceState {
  std::shared_ptr<V4l2Io> io;
  std::string path;
  std::mutex mutex;
  int fd = -1;  // written under `mutex`
  std::atomic<std::uint64_t> frames{0};
  std::atomic<std::uint64_t> dropped{0};
  std::atomic<std::uint64_t> incomplete{0};
  std::atomic<std::uint64_t> errors{0};

  int ioctl(unsigned long request, void* arg) { return fd < 0 ? -EBADF : io->ioctl(fd, request, arg); }
};

// The mmap buffers of one start(). Unmapped when the camera and every frame holding one of them
// are done with it, so a frame kept past stop() or the camera's end still reads valid memory
// (the kernel keeps an orphaned buffer's pages while they are mapped).
struct BufferSet {
  struct Mapping {
    void* address = nullptr;
    std::size_t length = 0;
  };
  explicit BufferSet(std::shared_ptr<DeviceState> d) : device(std::move(d)) {}
  BufferSet(const BufferSet&) = delete;
  BufferSet& operator=(const BufferSet&) = delete;
  ~BufferSet() {
    for (const auto& m : mappings) device->io->munmap(m.address, m.length);
  }

  // Gives buffer `index` back to the driver while the stream that owns it runs.
  void requeue(std::uint32_t index) {
    std::lock_guard lock(device->mutex);
    if (!live) return;
    v4l2_buffer buf{};
    buf.type = kCapture;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = index;
    if (device->ioctl(VIDIOC_QBUF, &buf) < 0) ++device->errors;
  }

  std::shared_ptr<DeviceState> device;
  std::vector<Mapping> mappings;
  bool live = false;  // streaming; written under device->mutex
};

std::string errno_text(int negative_errno) { return std::strerror(-negative_errno); }

std::string format_rate(double rate_hz) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", rate_hz);
  return buf;
}

std::string describe(const FrameFormat& f) {
  std::string s = f.pixel_format + " " + std::to_string(f.width) + "x" + std::to_string(f.height);
  if (f.rate_hz > 0) s += " at " + format_rate(f.rate_hz) + " fps";
  return s;
}

double fraction_rate(const v4l2_fract& time_per_frame) {
  return time_per_frame.numerator == 0
             ? 0.0
             : static_cast<double>(time_per_frame.denominator) / time_per_frame.numerator;
}

// The offered formats in a few lines: the sizes and rates of the pixel format asked for, and
// the names of the others (a device like vivid offers thousands of combinations).
std::string describe_offer(const std::vector<FrameFormat>& list, const std::string& pixel_format) {
  std::vector<std::string> names;
  std::string sizes;
  std::string last_size;
  for (const auto& f : list) {
    if (names.empty() || names.back() != f.pixel_format) {
      if (std::find(names.begin(), names.end(), f.pixel_format) == names.end())
        names.push_back(f.pixel_format);
    }
    if (f.pixel_format != pixel_format) continue;
    const std::string size = std::to_string(f.width) + "x" + std::to_string(f.height);
    if (size != last_size) {
      sizes += (sizes.empty() ? "" : "; ") + size + (f.rate_hz > 0 ? " at" : "");
      last_size = size;
    }
    if (f.rate_hz > 0) sizes += " " + format_rate(f.rate_hz);
  }
  std::string all;
  for (const auto& n : names) all += (all.empty() ? "" : ", ") + n;
  std::string s = "pixel formats " + (all.empty() ? std::string("(none listed)") : all);
  if (!sizes.empty()) {
    s += "; " + pixel_format + " sizes and rates (fps): " + sizes;
  } else {
    s += " (" + pixel_format + " is not among them)";
  }
  return s;
}

class V4l2Camera final : public Camera {
 public:
  V4l2Camera(std::shared_ptr<DeviceState> device, const V4l2Options& options)
      : device_(std::move(device)), options_(options) {}
  ~V4l2Camera() override {
    (void)stop();
    std::lock_guard lock(device_->mutex);
    if (device_->fd >= 0) device_->io->close(device_->fd);
    device_->fd = -1;
  }
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  const char* backend() const override { return "v4l2"; }
  const std::string& id() const override { return device_->path; }

  Result<std::vector<FrameFormat>> formats() override;
  Status set_format(const FrameFormat& format) override;
  FrameFormat format() const override { return format_; }
  Status start() override;
  Status stop() override;
  int fd() const override { return device_->fd; }
  Result<Frame> dequeue() override;
  TimestampMeaning timestamp_meaning() const override { return meaning_; }
  CameraCounters counters() const override {
    CameraCounters c;
    c.frames = device_->frames.load();
    c.dropped = device_->dropped.load();
    c.incomplete = device_->incomplete.load();
    c.errors = device_->errors.load();
    return c;
  }

  // After open: the capabilities and the device's current format.
  Status check_device();

 private:
  Error ioctl_error(const char* what, int r) const {
    return make_error(Errc::kDevice, device_->path + ": " + what + " failed: " + errno_text(r));
  }
  Status read_current_format();
  void append_sizes(std::uint32_t fourcc, std::vector<FrameFormat>& out);
  void append_rates(std::uint32_t fourcc, int width, int height, std::vector<FrameFormat>& out);
  Error refusal(const FrameFormat& asked, const std::string& offered);
  Status set_rate(const FrameFormat& asked, double& rate_hz);
  Status map_buffers(BufferSet& set, std::uint32_t count, std::uint32_t& flags);
  Status apply_timestamp_policy(std::uint32_t flags);
  void free_buffers();
  Error dequeue_error(int r);
  void count_sequence(std::uint32_t sequence);
  Status check_clock(TimeNs t_ns, TimeNs dequeued_ns);
  void fill_frame(Frame& frame, const v4l2_buffer& buf);

  std::shared_ptr<DeviceState> device_;
  V4l2Options options_;
  FrameFormat format_;
  std::uint32_t bytesperline_ = 0;
  std::shared_ptr<BufferSet> buffers_;  // set while streaming
  TimestampMeaning meaning_ = TimestampMeaning::kEndOfFrame;
  bool stamp_at_dequeue_ = false;
  bool has_exposure_ = false;
  bool have_sequence_ = false;
  std::uint32_t last_sequence_ = 0;
};

Status V4l2Camera::check_device() {
  const std::string& path = device_->path;
  v4l2_capability cap{};
  if (int r = device_->ioctl(VIDIOC_QUERYCAP, &cap); r < 0) {
    return make_error(Errc::kUnsupported,
                      path + " is not a V4L2 device (VIDIOC_QUERYCAP failed: " + errno_text(r) +
                          "). Name a video capture node; `v4l2-ctl --list-devices` "
                          "lists them.");
  }
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  const std::string what = std::string("V4L2 device '") + reinterpret_cast<const char*>(cap.card) +
                           "' (driver " + reinterpret_cast<const char*>(cap.driver) + ")";
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) {
    const bool mplane = (caps & V4L2_CAP_VIDEO_CAPTURE_MPLANE) != 0;
    return make_error(Errc::kUnsupported,
                      path + ": " + what +
                          (mplane ? " captures through the multi-planar API only, which this backend does "
                                    "not support; try the libcamera backend"
                                  : " is not a video capture device (it may be an output, metadata or "
                                    "codec node of the same hardware)") +
                          ". `v4l2-ctl --list-devices` shows the nodes of each device.");
  }
  if ((caps & V4L2_CAP_STREAMING) == 0) {
    return make_error(Errc::kUnsupported, path + ": " + what +
                                              " has no streaming I/O (read() only), which gives no frame "
                                              "timestamps; it cannot be used for calibration.");
  }
  return read_current_format();
}

Status V4l2Camera::read_current_format() {
  v4l2_format f{};
  f.type = kCapture;
  if (int r = device_->ioctl(VIDIOC_G_FMT, &f); r < 0) return ioctl_error("VIDIOC_G_FMT", r);
  format_.width = static_cast<int>(f.fmt.pix.width);
  format_.height = static_cast<int>(f.fmt.pix.height);
  format_.pixel_format = fourcc_name(f.fmt.pix.pixelformat);
  bytesperline_ = f.fmt.pix.bytesperline;
  v4l2_streamparm p{};
  p.type = kCapture;
  format_.rate_hz = device_->ioctl(VIDIOC_G_PARM, &p) == 0 ? fraction_rate(p.parm.capture.timeperframe) : 0.0;
  return {};
}

Result<std::vector<FrameFormat>> V4l2Camera::formats() {
  std::vector<FrameFormat> out;
  for (std::uint32_t i = 0; i < 1000; ++i) {
    v4l2_fmtdesc desc{};
    desc.index = i;
    desc.type = kCapture;
    const int r = device_->ioctl(VIDIOC_ENUM_FMT, &desc);
    if (r == -EINVAL) break;  // the end of the list
    if (r < 0) return ioctl_error("VIDIOC_ENUM_FMT", r);
    append_sizes(desc.pixelformat, out);
  }
  return out;
}

// Discrete sizes one by one; a stepwise or continuous range as its two ends. A driver without
// VIDIOC_ENUM_FRAMESIZES gets one entry of size 0x0 (any size; set_format() will tell).
void V4l2Camera::append_sizes(std::uint32_t fourcc, std::vector<FrameFormat>& out) {
  for (std::uint32_t i = 0; i < 1000; ++i) {
    v4l2_frmsizeenum size{};
    size.index = i;
    size.pixel_format = fourcc;
    if (device_->ioctl(VIDIOC_ENUM_FRAMESIZES, &size) < 0) {
      if (i == 0) out.push_back({0, 0, fourcc_name(fourcc), 0.0});
      return;
    }
    if (size.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
      append_rates(fourcc, static_cast<int>(size.discrete.width), static_cast<int>(size.discrete.height),
                   out);
      continue;
    }
    append_rates(fourcc, static_cast<int>(size.stepwise.min_width),
                 static_cast<int>(size.stepwise.min_height), out);
    append_rates(fourcc, static_cast<int>(size.stepwise.max_width),
                 static_cast<int>(size.stepwise.max_height), out);
    return;
  }
}

// Discrete intervals one by one (as rates); a range as its fastest and slowest rate; rate 0
// when the driver lists none.
void V4l2Camera::append_rates(std::uint32_t fourcc, int width, int height, std::vector<FrameFormat>& out) {
  const std::size_t before = out.size();
  const std::string name = fourcc_name(fourcc);
  for (std::uint32_t i = 0; i < 1000; ++i) {
    v4l2_frmivalenum ival{};
    ival.index = i;
    ival.pixel_format = fourcc;
    ival.width = static_cast<std::uint32_t>(width);
    ival.height = static_cast<std::uint32_t>(height);
    if (device_->ioctl(VIDIOC_ENUM_FRAMEINTERVALS, &ival) < 0) break;
    if (ival.type == V4L2_FRMIVAL_TYPE_DISCRETE) {
      out.push_back({width, height, name, fraction_rate(ival.discrete)});
      continue;
    }
    out.push_back({width, height, name, fraction_rate(ival.stepwise.min)});
    out.push_back({width, height, name, fraction_rate(ival.stepwise.max)});
    break;
  }
  if (out.size() == before) out.push_back({width, height, name, 0.0});
}

Error V4l2Camera::refusal(const FrameFormat& asked, const std::string& offered) {
  std::string msg =
      device_->path + ": the device does not take " + describe(asked) + "; it offered " + offered;
  if (auto list = formats(); list.ok()) msg += ". It lists " + describe_offer(*list, asked.pixel_format);
  msg += ". Set the camera's width, height, pixel_format and rate_hz to one it lists.";
  return make_error(Errc::kUnsupported, msg);
}

Status V4l2Camera::set_format(const FrameFormat& format) {
  const std::string& path = device_->path;
  if (buffers_) {
    return make_error(Errc::kInvalidArgument,
                      path + ": set_format() while streaming; stop() the camera first");
  }
  const std::uint32_t fourcc = fourcc_from_name(format.pixel_format);
  if (fourcc == 0 || format.width <= 0 || format.height <= 0 || !(format.rate_hz >= 0.0) ||
      !std::isfinite(format.rate_hz)) {
    return make_error(Errc::kInvalidArgument, path + ": invalid format '" + describe(format) +
                                                  "': the pixel format must be a fourcc of up to 4 "
                                                  "characters, the size positive, the rate >= 0");
  }
  v4l2_format f{};
  f.type = kCapture;
  f.fmt.pix.width = static_cast<std::uint32_t>(format.width);
  f.fmt.pix.height = static_cast<std::uint32_t>(format.height);
  f.fmt.pix.pixelformat = fourcc;
  f.fmt.pix.field = V4L2_FIELD_NONE;
  if (int r = device_->ioctl(VIDIOC_S_FMT, &f); r < 0) {
    if (r == -EBUSY) {
      return make_error(Errc::kDevice, path +
                                           ": VIDIOC_S_FMT: device busy; another program streams from it (" +
                                           "`fuser " + path + "` names it)");
    }
    if (r == -EINVAL) return refusal(format, "nothing (VIDIOC_S_FMT: Invalid argument)");
    return ioctl_error("VIDIOC_S_FMT", r);
  }
  const FrameFormat got{static_cast<int>(f.fmt.pix.width), static_cast<int>(f.fmt.pix.height),
                        fourcc_name(f.fmt.pix.pixelformat), 0.0};
  if (got.width != format.width || got.height != format.height || f.fmt.pix.pixelformat != fourcc) {
    return refusal(format, describe(got));
  }
  if (f.fmt.pix.field != V4L2_FIELD_NONE && f.fmt.pix.field != V4L2_FIELD_ANY) {
    return make_error(Errc::kUnsupported,
                      path + ": " + describe(format) + " is interlaced on this device (field " +
                          std::to_string(f.fmt.pix.field) + "); calibration needs progressive frames");
  }
  double rate_hz = 0.0;
  IMUCAL_TRY(set_rate(format, rate_hz));
  format_ = got;
  format_.rate_hz = rate_hz;
  bytesperline_ = f.fmt.pix.bytesperline;
  return {};
}

// The frame interval through VIDIOC_S_PARM; a rate of 0 keeps the device's. The rate the driver
// chose must match the one asked (to 0.1 %), like the size.
Status V4l2Camera::set_rate(const FrameFormat& asked, double& rate_hz) {
  v4l2_streamparm p{};
  p.type = kCapture;
  const bool can_read = device_->ioctl(VIDIOC_G_PARM, &p) == 0;
  const double current = can_read ? fraction_rate(p.parm.capture.timeperframe) : 0.0;
  if (asked.rate_hz == 0.0) {
    rate_hz = current;
    return {};
  }
  if (!can_read || (p.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) == 0) {
    return make_error(Errc::kUnsupported,
                      device_->path +
                          ": the device does not let the frame rate be set (no "
                          "V4L2_CAP_TIMEPERFRAME); it runs at " +
                          (current > 0 ? format_rate(current) + " fps" : std::string("an unknown rate")) +
                          ". Set rate_hz to 0 to take the device's rate.");
  }
  // timeperframe = 1000 / (rate * 1000), reduced: exact for integer and NTSC-style rates.
  const auto milli_hz = static_cast<std::uint32_t>(std::llround(asked.rate_hz * 1000.0));
  const std::uint32_t g = std::gcd(1000u, milli_hz);
  p.parm.capture.timeperframe.numerator = 1000u / g;
  p.parm.capture.timeperframe.denominator = milli_hz / g;
  if (int r = device_->ioctl(VIDIOC_S_PARM, &p); r < 0) return ioctl_error("VIDIOC_S_PARM", r);
  rate_hz = fraction_rate(p.parm.capture.timeperframe);
  if (std::abs(rate_hz - asked.rate_hz) > 1e-3 * asked.rate_hz) {
    FrameFormat got = asked;
    got.rate_hz = rate_hz;
    return refusal(asked, describe(got));
  }
  return {};
}

Status V4l2Camera::map_buffers(BufferSet& set, std::uint32_t count, std::uint32_t& flags) {
  for (std::uint32_t i = 0; i < count; ++i) {
    v4l2_buffer buf{};
    buf.type = kCapture;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (int r = device_->ioctl(VIDIOC_QUERYBUF, &buf); r < 0) return ioctl_error("VIDIOC_QUERYBUF", r);
    if (i == 0) flags = buf.flags;
    void* address = device_->io->mmap(buf.length, device_->fd, static_cast<off_t>(buf.m.offset));
    if (address == nullptr) {
      return make_error(Errc::kIo, device_->path + ": mmap of buffer " + std::to_string(i) + " (" +
                                       std::to_string(buf.length) +
                                       " bytes) failed: " + std::strerror(errno));
    }
    set.mappings.push_back({address, buf.length});
  }
  return {};
}

Status V4l2Camera::apply_timestamp_policy(std::uint32_t flags) {
  const std::uint32_t type = flags & V4L2_BUF_FLAG_TIMESTAMP_MASK;
  const bool soe = (flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
  stamp_at_dequeue_ = false;
  if (type == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
    meaning_ = soe ? TimestampMeaning::kStartOfExposure : TimestampMeaning::kEndOfFrame;
    return {};
  }
  if (!options_.stamp_at_dequeue) {
    const char* kind = type == V4L2_BUF_FLAG_TIMESTAMP_COPY ? "copy" : "unknown";
    return make_error(Errc::kUnsupported,
                      "camera " + device_->path +
                          ": the driver does not stamp frames on CLOCK_MONOTONIC (its timestamp type is "
                          "'" +
                          kind +
                          "'), so its frames cannot be put on the IMU's clock. Allow stamping at dequeue "
                          "time (end of frame plus the wake-up latency) or use another driver.")
        .with_remedy("stamp_at_dequeue", "true");
  }
  stamp_at_dequeue_ = true;
  meaning_ = TimestampMeaning::kEndOfFrame;
  return {};
}

void V4l2Camera::free_buffers() {
  buffers_.reset();
  v4l2_requestbuffers req{};
  req.type = kCapture;
  req.memory = V4L2_MEMORY_MMAP;
  (void)device_->ioctl(VIDIOC_REQBUFS, &req);
}

Status V4l2Camera::start() {
  if (buffers_) return {};
  const std::string& path = device_->path;
  v4l2_requestbuffers req{};
  req.count = static_cast<std::uint32_t>(options_.buffers);
  req.type = kCapture;
  req.memory = V4L2_MEMORY_MMAP;
  if (int r = device_->ioctl(VIDIOC_REQBUFS, &req); r < 0) {
    if (r == -EBUSY) {
      return make_error(Errc::kDevice,
                        path + ": VIDIOC_REQBUFS: device busy; another program streams from it");
    }
    if (r == -EINVAL) {
      return make_error(Errc::kUnsupported, path + ": the driver does not offer mmap streaming buffers");
    }
    return ioctl_error("VIDIOC_REQBUFS", r);
  }
  if (req.count == 0) return make_error(Errc::kDevice, path + ": the driver granted no buffers");

  buffers_ = std::make_shared<BufferSet>(device_);
  std::uint32_t flags = 0;
  Status s = map_buffers(*buffers_, req.count, flags);
  if (s.ok()) s = apply_timestamp_policy(flags);
  for (std::uint32_t i = 0; s.ok() && i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = kCapture;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (int r = device_->ioctl(VIDIOC_QBUF, &buf); r < 0) s = ioctl_error("VIDIOC_QBUF", r);
  }
  int type = kCapture;
  if (s.ok()) {
    if (int r = device_->ioctl(VIDIOC_STREAMON, &type); r < 0) s = ioctl_error("VIDIOC_STREAMON", r);
  }
  if (!s.ok()) {
    free_buffers();
    return s;
  }
  v4l2_queryctrl qc{};
  qc.id = V4L2_CID_EXPOSURE_ABSOLUTE;
  has_exposure_ = device_->ioctl(VIDIOC_QUERYCTRL, &qc) == 0 && (qc.flags & V4L2_CTRL_FLAG_DISABLED) == 0;
  have_sequence_ = false;
  std::lock_guard lock(device_->mutex);
  buffers_->live = true;
  return {};
}

Status V4l2Camera::stop() {
  if (!buffers_) return {};
  int type = kCapture;
  int r = 0;
  {
    // No frame requeues its buffer once the stream is off.
    std::lock_guard lock(device_->mutex);
    buffers_->live = false;
    r = device_->ioctl(VIDIOC_STREAMOFF, &type);
  }
  // Unmaps the buffers unless frames still hold them (then the last of them does), and frees
  // them in the driver (which orphans mapped ones until they are unmapped).
  buffers_.reset();
  v4l2_requestbuffers req{};
  req.type = kCapture;
  req.memory = V4L2_MEMORY_MMAP;
  const int r_free = device_->ioctl(VIDIOC_REQBUFS, &req);
  // A device that is gone has nothing left to stop.
  if (r < 0 && r != -ENODEV) return ioctl_error("VIDIOC_STREAMOFF", r);
  if (r_free < 0 && r_free != -ENODEV) return ioctl_error("VIDIOC_REQBUFS (free)", r_free);
  return {};
}

Error V4l2Camera::dequeue_error(int r) {
  ++device_->errors;
  const std::string& path = device_->path;
  switch (-r) {
    case ENODEV:
      return make_error(Errc::kNotFound, "camera " + path + " disconnected (VIDIOC_DQBUF: " + errno_text(r) +
                                             "); check its cable and power, then start the session again");
    case EIO:
      return make_error(Errc::kDevice, "camera " + path +
                                           " disconnected or failed (VIDIOC_DQBUF: " + errno_text(r) +
                                           "); check its cable and power, then start the session again");
    default:
      return ioctl_error("VIDIOC_DQBUF", r);
  }
}

// Sequence numbers count every frame the driver produced, also those it had no buffer for.
void V4l2Camera::count_sequence(std::uint32_t sequence) {
  if (have_sequence_) {
    const std::uint32_t step = sequence - last_sequence_;  // modulo 2^32
    if (step > 1 && step < 0x80000000u) device_->dropped += step - 1;
  }
  have_sequence_ = true;
  last_sequence_ = sequence;
}

// A driver that flags its stamps as monotonic but takes them from another clock (realtime, a
// device counter) would put every frame at a wrong time without any other sign; a stamp far
// from CLOCK_MONOTONIC at dequeue exposes it. Bounds: a frame may wait in the driver's done
// queue while the caller is busy (up to an hour is accepted), and some drivers stamp the
// scheduled end of a frame slightly ahead of its delivery (vivid, by most of a frame period).
Status V4l2Camera::check_clock(TimeNs t_ns, TimeNs dequeued_ns) {
  constexpr TimeNs kMaxAheadNs = 2 * kNsPerSecond;
  constexpr TimeNs kMaxBehindNs = 3600 * kNsPerSecond;
  if (t_ns <= dequeued_ns + kMaxAheadNs && t_ns >= dequeued_ns - kMaxBehindNs) return {};
  ++device_->errors;
  char offset[32];
  std::snprintf(offset, sizeof offset, "%+.3f", ns_to_s(t_ns - dequeued_ns));
  return make_error(Errc::kDevice, "camera " + device_->path + ": a frame is stamped " + offset +
                                       " s from CLOCK_MONOTONIC at its dequeue; the driver flags its "
                                       "timestamps as monotonic but they are on another clock. Report it to "
                                       "the driver's maintainers; stamp_at_dequeue does not help here.");
}

void V4l2Camera::fill_frame(Frame& frame, const v4l2_buffer& buf) {
  const auto& mapping = buffers_->mappings[buf.index];
  frame.sequence = buf.sequence;
  frame.width = format_.width;
  frame.height = format_.height;
  frame.pixel_format = format_.pixel_format;
  frame.stride = bytesperline_;
  const std::size_t used =
      buf.bytesused == 0 || buf.bytesused > mapping.length ? mapping.length : buf.bytesused;
  frame.data = {static_cast<const std::uint8_t*>(mapping.address), used};
  if (has_exposure_) {
    // The current setting (100 us units): the frame's own under manual exposure.
    v4l2_control c{};
    c.id = V4L2_CID_EXPOSURE_ABSOLUTE;
    if (device_->ioctl(VIDIOC_G_CTRL, &c) == 0) frame.exposure_ns = static_cast<TimeNs>(c.value) * 100'000;
  }
  frame.set_release([set = buffers_, index = buf.index] { set->requeue(index); });
}

Result<Frame> V4l2Camera::dequeue() {
  if (!buffers_) return make_error(Errc::kInvalidArgument, device_->path + ": dequeue() before start()");
  v4l2_buffer buf{};
  buf.type = kCapture;
  buf.memory = V4L2_MEMORY_MMAP;
  const int r = device_->ioctl(VIDIOC_DQBUF, &buf);
  if (r == -EAGAIN) return Frame{};
  if (r < 0) return dequeue_error(r);
  // Taken at once: the stamp of drivers that give none on CLOCK_MONOTONIC (stamp_at_dequeue).
  const TimeNs dequeued_ns = device_->io->monotonic_now_ns();
  if (buf.index >= buffers_->mappings.size()) {
    ++device_->errors;
    return make_error(Errc::kDevice, device_->path + ": the driver returned buffer " +
                                         std::to_string(buf.index) + " of " +
                                         std::to_string(buffers_->mappings.size()));
  }
  count_sequence(buf.sequence);
  // A damaged frame, or one shorter than the format (a truncated transfer), is counted and its
  // buffer goes straight back. Compressed formats have no bytesperline and are not checked.
  const std::size_t expected =
      static_cast<std::size_t>(bytesperline_) * static_cast<std::size_t>(format_.height);
  if ((buf.flags & V4L2_BUF_FLAG_ERROR) != 0 ||
      (expected > 0 && buf.bytesused != 0 && buf.bytesused < expected)) {
    ++device_->incomplete;
    buffers_->requeue(buf.index);
    return Frame{};
  }
  // The clock is known from the buffers at start(); a driver that changes it later is held to
  // the same policy.
  if (!stamp_at_dequeue_ && (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) != V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
    if (Status s = apply_timestamp_policy(buf.flags); !s.ok()) {
      buffers_->requeue(buf.index);
      return s.error();
    }
  }
  const TimeNs t_ns = stamp_at_dequeue_ ? dequeued_ns
                                        : static_cast<TimeNs>(buf.timestamp.tv_sec) * kNsPerSecond +
                                              static_cast<TimeNs>(buf.timestamp.tv_usec) * 1000;
  if (Status s = check_clock(t_ns, dequeued_ns); !s.ok()) {
    buffers_->requeue(buf.index);
    return s.error();
  }
  Frame frame;
  frame.t_ns = t_ns;
  fill_frame(frame, buf);
  ++device_->frames;
  return Result<Frame>(std::move(frame));
}

Error open_error(const std::string& path, int r) {
  const std::string what = "cannot open camera " + path + ": " + errno_text(r);
  switch (-r) {
    case ENOENT:
    case ENODEV:
    case ENXIO:
      return make_error(Errc::kNotFound,
                        what +
                            ". Check that the camera is connected and which node it has "
                            "(`v4l2-ctl --list-devices`), and the camera's device in the rig "
                            "configuration.");
    case EACCES:
    case EPERM:
      return make_error(Errc::kIo, what +
                                       ". Add the user to the group video (`sudo usermod -aG video $USER`, "
                                       "then log in again) or run as a user of that group.");
    default:
      return make_error(Errc::kIo, what);
  }
}

}  // namespace

std::shared_ptr<V4l2Io> system_v4l2_io() { return std::make_shared<SystemV4l2Io>(); }

std::string fourcc_name(std::uint32_t fourcc) {
  std::string s;
  for (int i = 0; i < 4; ++i) s += static_cast<char>((fourcc >> (8 * i)) & 0x7F);
  if ((fourcc & (1u << 31)) != 0) s += "-BE";
  return s;
}

std::uint32_t fourcc_from_name(const std::string& name) {
  std::string base = name;
  std::uint32_t big_endian = 0;
  if (base.size() > 3 && base.compare(base.size() - 3, 3, "-BE") == 0) {
    base.resize(base.size() - 3);
    big_endian = 1u << 31;
  }
  if (base.empty() || base.size() > 4) return 0;
  base.resize(4, ' ');
  std::uint32_t fourcc = 0;
  for (int i = 0; i < 4; ++i) {
    const auto c = static_cast<unsigned char>(base[static_cast<std::size_t>(i)]);
    if (c < 0x20 || c > 0x7E) return 0;
    fourcc |= static_cast<std::uint32_t>(c) << (8 * i);
  }
  return fourcc | big_endian;
}

Result<std::unique_ptr<Camera>> open_v4l2_camera(const std::string& device_path, V4l2Options options) {
  if (device_path.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no V4L2 device given; set the camera's device (e.g. /dev/video0)");
  }
  if (options.buffers < 1 || options.buffers > kMaxBuffers) {
    return make_error(Errc::kInvalidArgument, "V4L2 buffers must be 1.." + std::to_string(kMaxBuffers) +
                                                  ", not " + std::to_string(options.buffers));
  }
  auto device = std::make_shared<DeviceState>();
  device->io = options.io ? options.io : system_v4l2_io();
  device->path = device_path;
  const int fd = device->io->open(device_path);
  if (fd < 0) return open_error(device_path, fd);
  device->fd = fd;
  auto camera = std::make_unique<V4l2Camera>(device, options);
  IMUCAL_TRY(camera->check_device());
  return std::unique_ptr<Camera>(std::move(camera));
}

}  // namespace imucal::drivers::camera
