// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/camera/libcamera/libcamera_camera.hpp"

#include <libcamera/libcamera.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <sstream>

namespace imucal::drivers::camera {

namespace lc = libcamera;

// Buffers, their mappings and the requests of one start(). Frames still held after stop() keep
// it alive; their requests are then not queued again.
struct LibcameraCamera::Session {
  struct Mapping {
    void* address = MAP_FAILED;
    std::size_t length = 0;
    const std::uint8_t* plane0 = nullptr;
  };

  std::shared_ptr<lc::Camera> camera;
  lc::Stream* stream = nullptr;
  std::unique_ptr<lc::FrameBufferAllocator> allocator;
  std::vector<std::unique_ptr<lc::Request>> requests;  // cookie = index
  std::vector<Mapping> mappings;                       // by request cookie
  std::atomic<bool> streaming{false};
  std::atomic<std::uint64_t> requeue_errors{0};

  ~Session() {
    for (const Mapping& m : mappings) {
      if (m.address != MAP_FAILED) ::munmap(m.address, m.length);
    }
    requests.clear();  // before their buffers
    if (allocator) allocator->free(stream);
  }

  void requeue(lc::Request* request) {
    if (!streaming) return;
    request->reuse(lc::Request::ReuseBuffers);
    if (camera->queueRequest(request) < 0) ++requeue_errors;
  }
};

namespace {

void signal_fd(int fd) {
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto n =
      ::write(fd, &one, sizeof one);  // a lost wake-up is covered by those pending
}

TimeNs clock_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

// One CameraManager per process (libcamera aborts on a second one), shared by every camera and
// list call and destroyed when the last of them is done.
Result<std::shared_ptr<lc::CameraManager>> shared_manager() {
  static std::mutex mutex;
  static std::weak_ptr<lc::CameraManager> current;
  std::lock_guard lock(mutex);
  if (auto manager = current.lock()) return manager;
  auto manager = std::make_shared<lc::CameraManager>();
  if (const int ret = manager->start(); ret < 0) {
    return make_error(Errc::kDevice,
                      std::string("libcamera: the camera manager did not start: ") + std::strerror(-ret));
  }
  current = manager;
  return manager;
}

std::string offered_text(const lc::StreamFormats& formats) {
  std::ostringstream s;
  bool first = true;
  for (const lc::PixelFormat& pf : formats.pixelformats()) {
    s << (first ? "" : "; ") << pf.toString() << " " << formats.range(pf).toString();
    first = false;
  }
  return first ? std::string("nothing") : s.str();
}

lc::StreamRole role_of(LibcameraOptions::Role role) {
  return role == LibcameraOptions::Role::kRaw ? lc::StreamRole::Raw : lc::StreamRole::Viewfinder;
}

}  // namespace

Result<std::vector<std::string>> list_libcamera_cameras() {
  auto manager = shared_manager();
  if (!manager.ok()) return manager.error();
  std::vector<std::string> ids;
  for (const auto& camera : (*manager)->cameras()) ids.push_back(camera->id());
  return ids;
}

Result<std::unique_ptr<LibcameraCamera>> open_libcamera_camera(const std::string& id,
                                                               const LibcameraOptions& options) {
  if (options.buffers < 0)
    return make_error(Errc::kInvalidArgument, "libcamera: buffers must not be negative");
  auto manager = shared_manager();
  if (!manager.ok()) return manager.error();
  std::string found;
  for (const auto& camera : (*manager)->cameras()) found += (found.empty() ? "" : ", ") + camera->id();
  std::shared_ptr<lc::Camera> camera = (*manager)->get(id);
  if (!camera) {
    return make_error(
        Errc::kNotFound,
        "libcamera: no camera '" + id + "'; " +
            (found.empty() ? "no cameras found (libcamera " + lc::CameraManager::version() +
                                 "; check that the sensor's driver is loaded and the user may open "
                                 "/dev/media* and /dev/video*)"
                           : "found: " + found));
  }
  if (camera->acquire() < 0) {
    return make_error(Errc::kDevice, "libcamera: camera '" + id +
                                         "' is in use (by another process, or opened already by this one)");
  }
  auto cam = std::unique_ptr<LibcameraCamera>(new LibcameraCamera(id, *manager, camera, options));
  if (cam->event_fd_ < 0)
    return make_error(Errc::kIo, std::string("libcamera: eventfd: ") + std::strerror(errno));
  if (!cam->config_ || cam->config_->empty()) {
    return make_error(Errc::kUnsupported,
                      "libcamera: camera '" + id + "' offers no stream for the " +
                          (options.role == LibcameraOptions::Role::kRaw ? "raw" : "viewfinder") + " role");
  }
  const lc::StreamConfiguration& cfg = cam->config_->at(0);
  cam->format_ = {static_cast<int>(cfg.size.width), static_cast<int>(cfg.size.height),
                  cfg.pixelFormat.toString(), 0.0};
  return cam;
}

LibcameraCamera::LibcameraCamera(std::string id, std::shared_ptr<lc::CameraManager> manager,
                                 std::shared_ptr<lc::Camera> camera, LibcameraOptions options)
    : id_(std::move(id)), manager_(std::move(manager)), camera_(std::move(camera)), options_(options) {
  event_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC | EFD_SEMAPHORE);
  config_ = camera_->generateConfiguration({role_of(options_.role)});
  // Both are emitted from the camera manager's thread.
  camera_->requestCompleted.connect(this, &LibcameraCamera::on_request_completed);
  camera_->disconnected.connect(this, &LibcameraCamera::on_disconnected);
}

LibcameraCamera::~LibcameraCamera() {
  (void)stop();
  camera_->requestCompleted.disconnect(this);
  camera_->disconnected.disconnect(this);
  camera_->release();
  if (event_fd_ >= 0) ::close(event_fd_);
}

void LibcameraCamera::on_request_completed(lc::Request* request) {
  if (request->status() == lc::Request::RequestCancelled) return;  // stop(): nobody waits for it
  {
    std::lock_guard lock(mutex_);
    completed_.push_back(request);
  }
  signal_fd(event_fd_);
}

void LibcameraCamera::on_disconnected() {
  lost_ = true;
  signal_fd(event_fd_);
}

Result<std::vector<FrameFormat>> LibcameraCamera::formats() {
  std::vector<FrameFormat> out;
  lc::StreamConfiguration& cfg = config_->at(0);
  const lc::StreamFormats formats = cfg.formats();
  // For a size range libcamera lists the common sizes inside it, and the pipeline may adjust
  // some of them (vimc takes multiples of 6 only); each is validated, and only what set_format()
  // would take is listed. Not while streaming: the configuration is the running one then.
  const lc::PixelFormat kept_format = cfg.pixelFormat;
  const lc::Size kept_size = cfg.size;
  const unsigned kept_buffers = cfg.bufferCount;
  for (const lc::PixelFormat& pf : formats.pixelformats()) {
    std::vector<lc::Size> sizes = formats.sizes(pf);
    if (sizes.empty()) sizes.push_back(formats.range(pf).max);
    for (const lc::Size& size : sizes) {
      if (!session_) {
        cfg.pixelFormat = pf;
        cfg.size = size;
        const bool taken = config_->validate() != lc::CameraConfiguration::Invalid && cfg.pixelFormat == pf &&
                           cfg.size == size;
        if (!taken) continue;
      }
      out.push_back({static_cast<int>(size.width), static_cast<int>(size.height), pf.toString(), 0.0});
    }
  }
  if (!session_) {
    cfg.pixelFormat = kept_format;
    cfg.size = kept_size;
    cfg.bufferCount = kept_buffers;
    (void)config_->validate();
  }
  return out;
}

Status LibcameraCamera::check_rate(double rate_hz) const {
  const lc::ControlInfoMap& info = camera_->controls();
  const auto it = info.find(&lc::controls::FrameDurationLimits);
  if (it == info.end()) {
    return make_error(
        Errc::kUnsupported,
        "libcamera: camera '" + id_ + "' has no frame duration control (FrameDurationLimits); give rate 0");
  }
  const lc::ControlValue& min = it->second.min();
  const lc::ControlValue& max = it->second.max();
  if (min.type() == lc::ControlTypeInteger64 && max.type() == lc::ControlTypeInteger64 && !min.isArray()) {
    const double duration_us = 1e6 / rate_hz;
    const auto min_us = static_cast<double>(min.get<std::int64_t>());
    const auto max_us = static_cast<double>(max.get<std::int64_t>());
    if (duration_us < min_us || duration_us > max_us) {
      std::ostringstream s;
      s << "libcamera: camera '" << id_ << "' does not take " << rate_hz << " Hz; it takes " << 1e6 / max_us
        << " to " << 1e6 / min_us << " Hz";
      return make_error(Errc::kUnsupported, s.str());
    }
  }
  return {};
}

Status LibcameraCamera::set_format(const FrameFormat& format) {
  if (session_)
    return make_error(Errc::kInvalidArgument,
                      "libcamera: " + id_ + ": stop the stream before changing the format");
  lc::StreamConfiguration& cfg = config_->at(0);
  const std::string offered = offered_text(cfg.formats());
  const lc::PixelFormat pf =
      format.pixel_format.empty() ? cfg.pixelFormat : lc::PixelFormat::fromString(format.pixel_format);
  const auto listed = cfg.formats().pixelformats();
  if (!pf.isValid() || std::find(listed.begin(), listed.end(), pf) == listed.end()) {
    return make_error(Errc::kUnsupported, "libcamera: camera '" + id_ + "' does not offer pixel format '" +
                                              format.pixel_format + "'; it offers " + offered);
  }
  const lc::Size size = format.width > 0 && format.height > 0 ? lc::Size(static_cast<unsigned>(format.width),
                                                                         static_cast<unsigned>(format.height))
                                                              : cfg.size;
  if (format.rate_hz > 0.0) IMUCAL_TRY(check_rate(format.rate_hz));
  cfg.pixelFormat = pf;
  cfg.size = size;
  if (options_.buffers > 0) cfg.bufferCount = static_cast<unsigned>(options_.buffers);
  const auto status = config_->validate();
  const std::string asked = size.toString() + "-" + pf.toString();
  if (status == lc::CameraConfiguration::Invalid) {
    return make_error(Errc::kUnsupported,
                      "libcamera: camera '" + id_ + "' refused " + asked + "; it offers " + offered);
  }
  if (cfg.pixelFormat != pf || cfg.size != size) {
    return make_error(Errc::kUnsupported, "libcamera: camera '" + id_ + "' adjusted " + asked + " to " +
                                              cfg.toString() + "; it offers " + offered);
  }
  if (const int ret = camera_->configure(config_.get()); ret < 0) {
    return make_error(Errc::kDevice,
                      "libcamera: camera '" + id_ + "': configure " + asked + ": " + std::strerror(-ret));
  }
  configured_ = true;
  format_ = {static_cast<int>(size.width), static_cast<int>(size.height), pf.toString(), format.rate_hz};
  return {};
}

Status LibcameraCamera::configure() {
  if (config_->validate() == lc::CameraConfiguration::Invalid) {
    return make_error(Errc::kUnsupported,
                      "libcamera: camera '" + id_ + "': its default configuration is invalid");
  }
  if (const int ret = camera_->configure(config_.get()); ret < 0) {
    return make_error(Errc::kDevice, "libcamera: camera '" + id_ + "': configure: " + std::strerror(-ret));
  }
  const lc::StreamConfiguration& cfg = config_->at(0);
  format_ = {static_cast<int>(cfg.size.width), static_cast<int>(cfg.size.height), cfg.pixelFormat.toString(),
             format_.rate_hz};
  configured_ = true;
  return {};
}

Status LibcameraCamera::start() {
  if (session_) return {};
  if (lost_) return make_error(Errc::kDevice, "libcamera: camera '" + id_ + "' was disconnected; reopen it");
  if (!configured_) IMUCAL_TRY(configure());
  const std::string who = "libcamera: camera '" + id_ + "'";
  auto s = std::make_shared<Session>();
  s->camera = camera_;
  s->stream = config_->at(0).stream();
  s->allocator = std::make_unique<lc::FrameBufferAllocator>(camera_);
  if (const int ret = s->allocator->allocate(s->stream); ret < 0) {
    return make_error(Errc::kDevice, who + ": allocating buffers: " + std::strerror(-ret));
  }
  const auto& buffers = s->allocator->buffers(s->stream);
  for (std::size_t i = 0; i < buffers.size(); ++i) {
    std::unique_ptr<lc::Request> request = camera_->createRequest(i);
    if (!request || request->addBuffer(s->stream, buffers[i].get()) < 0) {
      return make_error(Errc::kDevice, who + ": creating request " + std::to_string(i));
    }
    const lc::FrameBuffer::Plane& plane = buffers[i]->planes().front();
    Session::Mapping m;
    m.length = plane.offset + plane.length;
    m.address = ::mmap(nullptr, m.length, PROT_READ, MAP_SHARED, plane.fd.get(), 0);
    if (m.address == MAP_FAILED)
      return make_error(Errc::kIo, who + ": mapping a buffer: " + std::strerror(errno));
    m.plane0 = static_cast<const std::uint8_t*>(m.address) + plane.offset;
    s->mappings.push_back(m);
    s->requests.push_back(std::move(request));
  }
  lc::ControlList controls(lc::controls::controls);
  if (format_.rate_hz > 0.0) {
    const auto duration_us = static_cast<std::int64_t>(std::llround(1e6 / format_.rate_hz));
    const std::array<std::int64_t, 2> limits{duration_us, duration_us};
    controls.set(lc::controls::FrameDurationLimits, lc::Span<const std::int64_t, 2>(limits));
  }
  if (const int ret = camera_->start(&controls); ret < 0) {
    return make_error(Errc::kDevice, who + ": start: " + std::strerror(-ret));
  }
  s->streaming = true;
  session_ = s;
  have_sequence_ = false;
  for (auto& request : s->requests) {
    if (const int ret = camera_->queueRequest(request.get()); ret < 0) {
      (void)stop();
      return make_error(Errc::kDevice, who + ": queueing a request: " + std::strerror(-ret));
    }
  }
  return {};
}

Status LibcameraCamera::stop() {
  if (!session_) return {};
  session_->streaming = false;  // frames released from now on are not queued again
  errors_ += session_->requeue_errors.exchange(0);
  Status result;
  if (!lost_) {
    if (const int ret = camera_->stop(); ret < 0) {
      result = make_error(Errc::kDevice, "libcamera: camera '" + id_ + "': stop: " + std::strerror(-ret));
    }
  }
  {
    std::lock_guard lock(mutex_);
    completed_.clear();
  }
  std::uint64_t pending = 0;
  while (::read(event_fd_, &pending, sizeof pending) == sizeof pending) {
  }
  if (lost_) signal_fd(event_fd_);
  session_.reset();
  return result;
}

Result<Frame> LibcameraCamera::dequeue() {
  if (lost_) return make_error(Errc::kDevice, "libcamera: camera '" + id_ + "' was disconnected; reopen it");
  if (!session_) return Frame{};
  std::uint64_t token = 0;
  [[maybe_unused]] const auto n = ::read(event_fd_, &token, sizeof token);  // one wake-up consumed
  while (true) {
    lc::Request* request = nullptr;
    {
      std::lock_guard lock(mutex_);
      if (completed_.empty()) return Frame{};
      request = completed_.front();
      completed_.pop_front();
    }
    const lc::FrameBuffer* buffer = request->findBuffer(session_->stream);
    const lc::FrameMetadata& md = buffer->metadata();
    if (have_sequence_ && md.sequence > last_sequence_ + 1) dropped_ += md.sequence - last_sequence_ - 1;
    last_sequence_ = md.sequence;
    have_sequence_ = true;
    if (md.status != lc::FrameMetadata::FrameSuccess || request->status() != lc::Request::RequestComplete) {
      ++incomplete_;
      session_->requeue(request);
      continue;
    }
    ++frames_;
    return make_frame(request);
  }
}

Frame LibcameraCamera::make_frame(lc::Request* request) {
  const lc::FrameBuffer* buffer = request->findBuffer(session_->stream);
  const lc::FrameMetadata& md = buffer->metadata();
  const lc::StreamConfiguration& cfg = config_->at(0);
  const Session::Mapping& m = session_->mappings.at(request->cookie());
  Frame frame;
  frame.width = static_cast<int>(cfg.size.width);
  frame.height = static_cast<int>(cfg.size.height);
  frame.stride = cfg.stride;
  frame.pixel_format = cfg.pixelFormat.toString();
  frame.sequence = md.sequence;
  const auto sensor = request->metadata().get(lc::controls::SensorTimestamp);
  TimeNs t_ns = sensor ? *sensor : static_cast<TimeNs>(md.timestamp);
  // See the header: move a CLOCK_BOOTTIME stamp onto CLOCK_MONOTONIC.
  const TimeNs mono = clock_ns(CLOCK_MONOTONIC);
  const TimeNs boot = clock_ns(CLOCK_BOOTTIME);
  if (std::llabs(t_ns - boot) < std::llabs(t_ns - mono)) t_ns -= boot - mono;
  frame.t_ns = t_ns;
  if (const auto exposure_us = request->metadata().get(lc::controls::ExposureTime)) {
    frame.exposure_ns = static_cast<TimeNs>(*exposure_us) * 1000;
  }
  frame.data = {m.plane0, md.planes().empty() ? std::size_t{0} : std::size_t{md.planes()[0].bytesused}};
  frame.set_release([s = session_, request] { s->requeue(request); });
  return frame;
}

CameraCounters LibcameraCamera::counters() const {
  CameraCounters c;
  c.frames = frames_;
  c.dropped = dropped_;
  c.incomplete = incomplete_;
  c.errors = errors_;
  return c;
}

}  // namespace imucal::drivers::camera
