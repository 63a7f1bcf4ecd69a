// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/camera/aravis/aravis_camera.hpp"

#include <arv.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>

namespace imucal::drivers::camera {

// The streaming state. Frames still held after stop() keep it (and the ArvStream) alive; their
// buffers then go back to glib instead of to the stream.
struct AravisCamera::Stream {
  ArvStream* stream = nullptr;
  int event_fd = -1;
  unsigned long new_buffer_handler = 0;
  std::atomic<bool> streaming{false};

  // Host time of each completed buffer, taken in the stream thread by the new-buffer signal
  // (emitted right after the buffer enters the output queue). The k-th buffer popped belongs to
  // the k-th signal: one stream thread pushes and signals in order. A buffer popped in the gap
  // between its push and its signal takes the pop time and its signal is skipped.
  std::mutex mutex;
  std::deque<TimeNs> arrivals;
  std::uint64_t arrivals_to_skip = 0;

  // This stream's share of the counters.
  std::uint64_t id_gaps = 0;
  std::uint64_t underruns = 0;
  std::uint64_t packets = 0;

  ~Stream() {
    if (stream != nullptr) g_object_unref(stream);
  }

  TimeNs take_arrival() {
    std::lock_guard lock(mutex);
    if (arrivals.empty()) {
      ++arrivals_to_skip;
      return monotonic_now_ns();
    }
    const TimeNs t = arrivals.front();
    arrivals.pop_front();
    return t;
  }
};

namespace {

void signal_fd(int fd) {
  const std::uint64_t one = 1;
  // A full counter (2^64 - 2 pending wake-ups) cannot happen; a failed write loses nothing but
  // a wake-up that the pending ones already give.
  [[maybe_unused]] const auto n = ::write(fd, &one, sizeof one);
}

void on_new_buffer(ArvStream* /*stream*/, void* data) {
  auto* s = static_cast<AravisCamera::Stream*>(data);
  const TimeNs now = monotonic_now_ns();
  {
    std::lock_guard lock(s->mutex);
    if (s->arrivals_to_skip > 0) {
      --s->arrivals_to_skip;
    } else {
      s->arrivals.push_back(now);
    }
  }
  signal_fd(s->event_fd);
}

/// The error a GError describes, with context; frees it.
Error take_error(Errc code, const std::string& what, GError* error) {
  std::string message = what;
  if (error != nullptr) {
    message += ": ";
    message += error->message;
    g_error_free(error);
  }
  return make_error(code, message);
}

std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& s : items) out += (out.empty() ? "" : ", ") + s;
  return out;
}

std::string bounds_text(int min, int max, int increment) {
  std::ostringstream s;
  s << min << " to " << max;
  if (increment > 1) s << " in steps of " << increment;
  return s.str();
}

bool in_bounds(int value, int min, int max, int increment) {
  return value >= min && value <= max && (increment <= 1 || (value - min) % increment == 0);
}

}  // namespace

std::vector<std::string> list_aravis_cameras(bool fake_interface) {
  if (fake_interface) arv_enable_interface("Fake");
  arv_update_device_list();
  std::vector<std::string> ids;
  const unsigned n = arv_get_n_devices();
  for (unsigned i = 0; i < n; ++i) {
    if (const char* id = arv_get_device_id(i)) ids.emplace_back(id);
  }
  return ids;
}

Result<std::unique_ptr<AravisCamera>> open_aravis_camera(const std::string& id,
                                                         const AravisOptions& options) {
  if (options.buffers < 2) {
    return make_error(Errc::kInvalidArgument,
                      "aravis: buffers must be at least 2 (got " + std::to_string(options.buffers) + ")");
  }
  if (options.fake_interface) arv_enable_interface("Fake");
  GError* error = nullptr;
  ArvCamera* camera = arv_camera_new(id.c_str(), &error);
  if (camera == nullptr) {
    const bool not_found =
        error == nullptr || g_error_matches(error, ARV_DEVICE_ERROR, ARV_DEVICE_ERROR_NOT_FOUND);
    if (!not_found) return take_error(Errc::kDevice, "aravis: cannot open camera '" + id + "'", error);
    if (error != nullptr) g_error_free(error);
    const std::vector<std::string> ids = list_aravis_cameras(options.fake_interface);
    std::string message = "aravis: no camera '" + id + "'; ";
    message += ids.empty() ? "no cameras found (GigE Vision on every network interface, USB3 Vision); check "
                             "power, cable, the network interface's address and the USB permissions"
                           : "found: " + join(ids);
    return make_error(Errc::kNotFound, message);
  }
  auto cam = std::unique_ptr<AravisCamera>(new AravisCamera(id, camera, options));
  if (cam->event_fd_ < 0) {
    return make_error(Errc::kIo, std::string("aravis: eventfd: ") + std::strerror(errno));
  }
  if (!options.features.empty()) IMUCAL_TRY(cam->set_features(options.features));
  IMUCAL_TRY(cam->read_format());
  return cam;
}

AravisCamera::AravisCamera(std::string id, ArvCamera* camera, AravisOptions options)
    : id_(std::move(id)), camera_(camera), options_(std::move(options)), clock_(options_.clock) {
  event_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC | EFD_SEMAPHORE);
  // Emitted from the device's heartbeat thread (GigE Vision) when control is lost.
  control_lost_handler_ =
      g_signal_connect(arv_camera_get_device(camera_), "control-lost", G_CALLBACK(on_control_lost), this);
}

AravisCamera::~AravisCamera() {
  (void)stop();
  ArvDevice* device = arv_camera_get_device(camera_);
  if (control_lost_handler_ != 0) g_signal_handler_disconnect(device, control_lost_handler_);
  // Last reference: the device's heartbeat thread is joined here, before the state its signal
  // handler touched goes away.
  g_object_unref(camera_);
  if (event_fd_ >= 0) ::close(event_fd_);
}

void AravisCamera::on_control_lost(void* /*device*/, void* self) {
  auto* cam = static_cast<AravisCamera*>(self);
  cam->lost_ = true;
  signal_fd(cam->event_fd_);
}

bool AravisCamera::is_gige() const { return arv_camera_is_gv_device(camera_) != 0; }

Status AravisCamera::read_format() {
  GError* error = nullptr;
  FrameFormat f;
  int x = 0, y = 0;
  arv_camera_get_region(camera_, &x, &y, &f.width, &f.height, &error);
  if (error != nullptr) return take_error(Errc::kDevice, "aravis: " + id_ + ": reading Width/Height", error);
  const char* pixel_format = arv_camera_get_pixel_format_as_string(camera_, &error);
  if (error != nullptr) return take_error(Errc::kDevice, "aravis: " + id_ + ": reading PixelFormat", error);
  f.pixel_format = pixel_format != nullptr ? pixel_format : "";
  if (arv_camera_is_frame_rate_available(camera_, nullptr)) {
    f.rate_hz = arv_camera_get_frame_rate(camera_, &error);
    if (error != nullptr)
      return take_error(Errc::kDevice, "aravis: " + id_ + ": reading the frame rate", error);
  }
  format_ = f;
  return {};
}

Result<AravisBounds> AravisCamera::bounds() {
  AravisBounds b;
  GError* error = nullptr;
  guint n = 0;
  const char** names = arv_camera_dup_available_pixel_formats_as_strings(camera_, &n, &error);
  if (error != nullptr)
    return take_error(Errc::kDevice, "aravis: " + id_ + ": reading PixelFormat entries", error);
  for (guint i = 0; i < n; ++i) b.pixel_formats.emplace_back(names[i]);
  g_free(names);
  arv_camera_get_width_bounds(camera_, &b.width_min, &b.width_max, &error);
  if (error == nullptr) b.width_increment = std::max(1, arv_camera_get_width_increment(camera_, &error));
  if (error == nullptr) arv_camera_get_height_bounds(camera_, &b.height_min, &b.height_max, &error);
  if (error == nullptr) b.height_increment = std::max(1, arv_camera_get_height_increment(camera_, &error));
  if (error != nullptr)
    return take_error(Errc::kDevice, "aravis: " + id_ + ": reading Width/Height bounds", error);
  b.rate_available = arv_camera_is_frame_rate_available(camera_, nullptr) != 0;
  if (b.rate_available) {
    arv_camera_get_frame_rate_bounds(camera_, &b.rate_min_hz, &b.rate_max_hz, &error);
    if (error != nullptr)
      return take_error(Errc::kDevice, "aravis: " + id_ + ": reading frame rate bounds", error);
  }
  return b;
}

Result<std::vector<FrameFormat>> AravisCamera::formats() {
  auto b = bounds();
  if (!b.ok()) return b.error();
  std::vector<FrameFormat> out;
  for (const auto& pf : b->pixel_formats) out.push_back({b->width_max, b->height_max, pf, b->rate_max_hz});
  return out;
}

Status AravisCamera::set_format(const FrameFormat& format) {
  if (stream_)
    return make_error(Errc::kInvalidArgument,
                      "aravis: " + id_ + ": stop the stream before changing the format");
  auto b = bounds();
  if (!b.ok()) return b.error();
  const std::string who = "aravis: camera " + id_;
  if (!format.pixel_format.empty() && std::find(b->pixel_formats.begin(), b->pixel_formats.end(),
                                                format.pixel_format) == b->pixel_formats.end()) {
    return make_error(Errc::kUnsupported, who + " does not offer pixel format '" + format.pixel_format +
                                              "'; it offers " + join(b->pixel_formats));
  }
  const int width = format.width > 0 ? format.width : format_.width;
  const int height = format.height > 0 ? format.height : format_.height;
  if (!in_bounds(width, b->width_min, b->width_max, b->width_increment) ||
      !in_bounds(height, b->height_min, b->height_max, b->height_increment)) {
    return make_error(Errc::kUnsupported,
                      who + " does not accept " + std::to_string(width) + "x" + std::to_string(height) +
                          "; it takes widths " + bounds_text(b->width_min, b->width_max, b->width_increment) +
                          " and heights " + bounds_text(b->height_min, b->height_max, b->height_increment));
  }
  if (format.rate_hz > 0.0 && !b->rate_available) {
    return make_error(Errc::kUnsupported,
                      who +
                          " has no frame rate setting (AcquisitionFrameRate); give rate 0 and "
                          "set its trigger or rate features instead");
  }
  GError* error = nullptr;
  if (!format.pixel_format.empty()) {
    arv_camera_set_pixel_format_from_string(camera_, format.pixel_format.c_str(), &error);
    if (error != nullptr) return take_error(Errc::kDevice, who + ": setting PixelFormat", error);
  }
  arv_camera_set_region(camera_, 0, 0, width, height, &error);
  if (error != nullptr) return take_error(Errc::kDevice, who + ": setting Width/Height", error);
  if (format.rate_hz > 0.0) {
    if (Status rate = apply_rate(format.rate_hz); !rate.ok()) {
      // Put the size and pixel format back, so that a refusal leaves the device as it was.
      arv_camera_set_pixel_format_from_string(camera_, format_.pixel_format.c_str(), nullptr);
      arv_camera_set_region(camera_, 0, 0, format_.width, format_.height, nullptr);
      return rate;
    }
  }
  IMUCAL_TRY(read_format());
  const bool adjusted =
      format_.width != width || format_.height != height ||
      (!format.pixel_format.empty() && format_.pixel_format != format.pixel_format) ||
      (format.rate_hz > 0.0 && std::abs(format_.rate_hz - format.rate_hz) > 1e-3 * format.rate_hz);
  if (adjusted) {
    std::ostringstream s;
    s << who << " adjusted the format: asked " << width << "x" << height << " " << format.pixel_format
      << " at " << format.rate_hz << " Hz, got " << format_.width << "x" << format_.height << " "
      << format_.pixel_format << " at " << format_.rate_hz << " Hz";
    return make_error(Errc::kUnsupported, s.str());
  }
  return {};
}

Status AravisCamera::apply_rate(double rate_hz) {
  // The rate's bounds depend on the size and pixel format just set: read them again.
  auto b = bounds();
  if (!b.ok()) return b.error();
  if (rate_hz < b->rate_min_hz || rate_hz > b->rate_max_hz) {
    std::ostringstream s;
    s << "aravis: camera " << id_ << " does not take " << rate_hz << " Hz at " << format_.width << "x"
      << format_.height << "; it takes " << b->rate_min_hz << " to " << b->rate_max_hz << " Hz";
    return make_error(Errc::kUnsupported, s.str());
  }
  // Note: Aravis also turns the frame-start trigger off here (a fixed rate is free-running).
  GError* error = nullptr;
  arv_camera_set_frame_rate(camera_, rate_hz, &error);
  if (error != nullptr)
    return take_error(Errc::kDevice, "aravis: camera " + id_ + ": setting the frame rate", error);
  return {};
}

Status AravisCamera::set_features(const std::string& features) {
  if (stream_)
    return make_error(Errc::kInvalidArgument, "aravis: " + id_ + ": stop the stream before setting features");
  GError* error = nullptr;
  if (!arv_device_set_features_from_string(arv_camera_get_device(camera_), features.c_str(), &error)) {
    return take_error(Errc::kInvalidArgument, "aravis: camera " + id_ + ": features '" + features + "'",
                      error);
  }
  return read_format();
}

Status AravisCamera::execute(const std::string& command) {
  GError* error = nullptr;
  arv_camera_execute_command(camera_, command.c_str(), &error);
  if (error != nullptr) return take_error(Errc::kDevice, "aravis: camera " + id_ + ": " + command, error);
  return {};
}

Status AravisCamera::start() {
  if (lost_) return make_error(Errc::kDevice, "aravis: camera " + id_ + " lost; reopen it");
  if (stream_) return {};
  GError* error = nullptr;
  const guint payload = arv_camera_get_payload(camera_, &error);
  if (error != nullptr)
    return take_error(Errc::kDevice, "aravis: camera " + id_ + ": reading PayloadSize", error);
  auto st = std::make_shared<Stream>();
  st->event_fd = event_fd_;
  st->stream = arv_camera_create_stream(camera_, nullptr, nullptr, &error);
  if (st->stream == nullptr)
    return take_error(Errc::kDevice, "aravis: camera " + id_ + ": creating the stream", error);
  for (int i = 0; i < options_.buffers; ++i)
    arv_stream_push_buffer(st->stream, arv_buffer_new_allocate(payload));
  st->new_buffer_handler = g_signal_connect(st->stream, "new-buffer", G_CALLBACK(on_new_buffer), st.get());
  arv_stream_set_emit_signals(st->stream, TRUE);
  st->streaming = true;

  exposure_ns_ = 0;
  if (arv_camera_is_exposure_time_available(camera_, nullptr)) {
    const double exposure_us = arv_camera_get_exposure_time(camera_, &error);
    if (error == nullptr) exposure_ns_ = static_cast<TimeNs>(std::llround(exposure_us * 1e3));
    g_clear_error(&error);
  }
  clock_.clear();
  have_frame_id_ = false;
  stream_ = st;
  arv_camera_set_acquisition_mode(camera_, ARV_ACQUISITION_MODE_CONTINUOUS, &error);
  if (error == nullptr) arv_camera_start_acquisition(camera_, &error);
  if (error != nullptr) {
    const Error e = take_error(Errc::kDevice, "aravis: camera " + id_ + ": starting acquisition", error);
    (void)stop();
    return e;
  }
  return {};
}

Status AravisCamera::stop() {
  if (!stream_) return {};
  Status result;
  if (!lost_) {
    GError* error = nullptr;
    arv_camera_stop_acquisition(camera_, &error);
    if (error != nullptr)
      result = take_error(Errc::kDevice, "aravis: camera " + id_ + ": stopping acquisition", error);
  }
  arv_stream_set_emit_signals(stream_->stream, FALSE);
  g_signal_handler_disconnect(stream_->stream, stream_->new_buffer_handler);
  update_stream_statistics();
  dropped_base_ = dropped_.load();
  packets_base_ = packets_lost_.load();
  stream_->streaming = false;
  stream_.reset();
  std::uint64_t pending = 0;
  while (::read(event_fd_, &pending, sizeof pending) == sizeof pending) {
  }
  if (lost_) signal_fd(event_fd_);  // the loss stays visible to a waiting loop
  return result;
}

void AravisCamera::count_frame_id(std::uint64_t frame_id) {
  if (have_frame_id_) {
    std::uint64_t gap = 0;
    if (frame_id > last_frame_id_) {
      gap = frame_id - last_frame_id_ - 1;
    } else if (last_frame_id_ <= 0xFFFF && last_frame_id_ - frame_id > 0x8000) {
      // GigE Vision's 16-bit block id wrapped; it skips 0.
      gap = (0xFFFF - last_frame_id_) + (frame_id > 0 ? frame_id - 1 : 0);
    }  // else: the device restarted its counter; nothing is known about what was lost
    stream_->id_gaps += gap;
  }
  last_frame_id_ = frame_id;
  have_frame_id_ = true;
}

void AravisCamera::update_stream_statistics() {
  guint64 completed = 0, failures = 0, underruns = 0;
  arv_stream_get_statistics(stream_->stream, &completed, &failures, &underruns);
  stream_->underruns = underruns;
  if (ARV_IS_GV_STREAM(stream_->stream)) {
    guint64 resent = 0, missing = 0;
    arv_gv_stream_get_statistics(ARV_GV_STREAM(stream_->stream), &resent, &missing);
    stream_->packets = resent + missing;
  }
  // A GigE Vision frame lost for want of a buffer also leaves a gap in the block ids; the fake
  // camera's does not. The larger count covers both without counting a frame twice.
  dropped_ = dropped_base_ + std::max(stream_->id_gaps, stream_->underruns);
  packets_lost_ = packets_base_ + stream_->packets;
}

Result<Frame> AravisCamera::dequeue() {
  if (lost_) {
    return make_error(Errc::kDevice,
                      "aravis: camera " + id_ +
                          " lost (control-lost: its heartbeat failed; check power, cable and that "
                          "no other host took control), reopen it");
  }
  if (!stream_) return Frame{};
  std::uint64_t token = 0;
  [[maybe_unused]] const auto n = ::read(event_fd_, &token, sizeof token);  // one wake-up consumed
  while (true) {
    ArvBuffer* buffer = arv_stream_try_pop_buffer(stream_->stream);
    if (buffer == nullptr) {
      update_stream_statistics();
      return Frame{};
    }
    const TimeNs received_ns = stream_->take_arrival();
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    count_frame_id(arv_buffer_get_frame_id(buffer));
    Frame frame;
    if (status == ARV_BUFFER_STATUS_SUCCESS) frame = make_frame(buffer, received_ns);
    if (!frame.valid()) {
      ++incomplete_;
      arv_stream_push_buffer(stream_->stream, buffer);
      continue;
    }
    ++frames_;
    update_stream_statistics();
    return frame;
  }
}

Frame AravisCamera::make_frame(ArvBuffer* buffer, TimeNs received_ns) {
  Frame frame;
  std::size_t size = 0;
  const auto* data = static_cast<const std::uint8_t*>(arv_buffer_get_image_data(buffer, &size));
  if (data == nullptr || size == 0) return frame;  // no image part (chunk data only, or damaged)
  const ArvPixelFormat pixel_format = arv_buffer_get_image_pixel_format(buffer);
  int x_padding = 0, y_padding = 0;
  arv_buffer_get_image_padding(buffer, &x_padding, &y_padding);
  frame.width = arv_buffer_get_image_width(buffer);
  frame.height = arv_buffer_get_image_height(buffer);
  frame.stride = static_cast<std::size_t>(frame.width) * ARV_PIXEL_FORMAT_BIT_PER_PIXEL(pixel_format) / 8 +
                 static_cast<std::size_t>(std::max(0, x_padding));
  frame.pixel_format = format_.pixel_format;
  frame.sequence = static_cast<std::uint32_t>(arv_buffer_get_frame_id(buffer));
  frame.exposure_ns = exposure_ns_;
  const auto device_ns = static_cast<TimeNs>(arv_buffer_get_timestamp(buffer));
  if (device_ns != 0) {
    (void)clock_.add(device_ns, received_ns);
    frame.t_ns = clock_.to_host(device_ns);
  } else {
    frame.t_ns = received_ns;  // a device that does not stamp: the host's arrival time
  }
  frame.data = {data, size};
  frame.set_release([stream = stream_, buffer] {
    if (stream->streaming) {
      arv_stream_push_buffer(stream->stream, buffer);
    } else {
      g_object_unref(buffer);
    }
  });
  return frame;
}

CameraCounters AravisCamera::counters() const {
  CameraCounters c;
  c.frames = frames_;
  c.dropped = dropped_;
  c.incomplete = incomplete_;
  c.packets_lost = packets_lost_;
  c.errors = errors_;
  return c;
}

}  // namespace imucal::drivers::camera
