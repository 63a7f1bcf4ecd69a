// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/camera_stream.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>

#include "log/frame_codec.hpp"

namespace imucal::acq {
namespace {

namespace cam = drivers::camera;

// kRgb24 holds R, G, B in memory order, kBgr24 B, G, R. The names differ by library: V4L2's
// fourccs name the memory order (RGB3), GenICam's too (RGB8), libcamera's follow DRM, which name
// the bits of a little-endian word from the top (its BGR888 holds R, G, B in memory).
enum class Layout { kGray8, kYuyv, kUyvy, kRgb24, kBgr24 };

Result<Layout> layout_of(const std::string& pixel_format) {
  if (pixel_format == "GREY" || pixel_format == "Mono8" || pixel_format == "R8" || pixel_format == "Y8") {
    return Layout::kGray8;
  }
  if (pixel_format == "YUYV" || pixel_format == "YUY2" || pixel_format == "YUV422_YUYV_Packed") {
    return Layout::kYuyv;
  }
  if (pixel_format == "UYVY" || pixel_format == "YUV422Packed" || pixel_format == "YUV422_8_UYVY") {
    return Layout::kUyvy;
  }
  if (pixel_format == "RGB3" || pixel_format == "RGB8" || pixel_format == "RGB8Packed" ||
      pixel_format == "BGR888") {
    return Layout::kRgb24;
  }
  if (pixel_format == "BGR3" || pixel_format == "BGR8" || pixel_format == "BGR8Packed" ||
      pixel_format == "RGB888") {
    return Layout::kBgr24;
  }
  std::string list;
  for (const auto& f : supported_pixel_formats()) list += (list.empty() ? "" : ", ") + f;
  return make_error(Errc::kUnsupported, "pixel format '" + pixel_format +
                                            "' cannot be recorded; set the camera's pixel_format to one of " +
                                            list);
}

/// Copies the luma of one frame into `out` (width * height bytes). False when the frame's
/// buffer is shorter than its size says.
/// Colour frames become the luma of ITU-R BT.601 (0.299 R + 0.587 G + 0.114 B, in 1/256).
bool copy_luma(const cam::Frame& f, Layout layout, std::uint8_t* out) {
  const std::size_t w = static_cast<std::size_t>(f.width);
  const std::size_t bytes_per_px = layout == Layout::kGray8                               ? 1
                                   : layout == Layout::kRgb24 || layout == Layout::kBgr24 ? 3
                                                                                          : 2;
  const std::size_t stride = f.stride != 0 ? f.stride : w * bytes_per_px;
  if (stride < w * bytes_per_px) return false;
  if (f.data.size() < stride * static_cast<std::size_t>(f.height - 1) + w * bytes_per_px) return false;
  for (int r = 0; r < f.height; ++r) {
    const std::uint8_t* src = f.data.data() + stride * static_cast<std::size_t>(r);
    std::uint8_t* dst = out + w * static_cast<std::size_t>(r);
    if (layout == Layout::kGray8) {
      std::memcpy(dst, src, w);
    } else if (layout == Layout::kRgb24 || layout == Layout::kBgr24) {
      const std::size_t r = layout == Layout::kRgb24 ? 0 : 2;
      for (std::size_t c = 0; c < w; ++c) {
        const std::uint8_t* p = src + 3 * c;
        dst[c] = static_cast<std::uint8_t>((77u * p[r] + 150u * p[1] + 29u * p[2 - r] + 128u) >> 8);
      }
    } else {
      const std::size_t y = layout == Layout::kYuyv ? 0 : 1;  // luma byte of each pixel pair half
      for (std::size_t c = 0; c < w; ++c) dst[c] = src[2 * c + y];
    }
  }
  return true;
}

}  // namespace

const std::vector<std::string>& supported_pixel_formats() {
  static const std::vector<std::string> formats = {"GREY", "Y8",   "Mono8", "R8",   "YUYV",   "YUY2",  "UYVY",
                                                   "RGB3", "BGR3", "RGB8",  "BGR8", "BGR888", "RGB888"};
  return formats;
}

Result<std::unique_ptr<CameraStream>> CameraStream::create(const cam::FrameFormat& format,
                                                           cam::TimestampMeaning meaning,
                                                           CameraStreamOptions options) {
  auto layout = layout_of(format.pixel_format);
  if (!layout.ok()) return layout.error();
  if (format.width <= 0 || format.height <= 0 || format.width > 16384 || format.height > 16384) {
    return make_error(Errc::kInvalidArgument, "camera stream: the frame size must be 1..16384 pixels a side");
  }
  if (options.encoding != "png" && options.encoding != "webp") {
    return make_error(Errc::kInvalidArgument, "camera stream: encoding must be png or webp");
  }
  if (options.queue_frames < 1 || options.queue_frames > 4096) {
    return make_error(Errc::kInvalidArgument, "camera stream: queue_frames must be 1..4096");
  }
  auto stream = std::unique_ptr<CameraStream>(new CameraStream(format, meaning, std::move(options)));
  stream->layout_ = static_cast<int>(*layout);
  return stream;
}

CameraStream::CameraStream(const cam::FrameFormat& format, cam::TimestampMeaning meaning,
                           CameraStreamOptions options)
    : format_(format),
      meaning_(meaning),
      options_(std::move(options)),
      slots_(options_.queue_frames),
      free_(options_.queue_frames),
      filled_(options_.queue_frames) {
  for (std::size_t i = 0; i < slots_.size(); ++i) {
    slots_[i].image = log::Image::zeros(format_.width, format_.height);
    (void)free_.try_push(static_cast<int>(i));
  }
}

CameraStream::~CameraStream() { (void)stop(); }

std::string CameraStream::timestamp_source() const {
  return meaning_ == cam::TimestampMeaning::kEndOfFrame ? cam::timestamp_meaning_name(meaning_)
                                                        : "mid-exposure";
}

Status CameraStream::start_log(log::SessionLogWriter& writer, int stream_id) {
  if (thread_.joinable()) return make_error(Errc::kInvalidArgument, "camera stream: already started");
  writer_ = &writer;
  stream_id_ = stream_id;
  thread_ = std::thread([this] { encoder_loop(); });
  return {};
}

bool CameraStream::publish(cam::Frame& frame, const std::function<void(const PublishedFrame&)>& inspect) {
  published_.fetch_add(1, std::memory_order_relaxed);
  if (have_sequence_ && frame.sequence > last_sequence_ + 1) {
    device_dropped_.fetch_add(frame.sequence - last_sequence_ - 1, std::memory_order_relaxed);
    drop_pending_ = true;
  }
  have_sequence_ = true;
  last_sequence_ = frame.sequence;
  if (frame.width != format_.width || frame.height != format_.height) {
    wrong_size_.fetch_add(1, std::memory_order_relaxed);
    drop_pending_ = true;
    frame.release();
    return false;
  }
  int slot = -1;
  while (!free_.try_pop(slot)) {
    if (!options_.block_when_full || log_failed() || !thread_.joinable()) {
      queue_dropped_.fetch_add(1, std::memory_order_relaxed);
      drop_pending_ = true;
      frame.release();
      return false;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  Slot& s = slots_[static_cast<std::size_t>(slot)];
  if (!copy_luma(frame, static_cast<Layout>(layout_), s.image.data.data())) {
    wrong_size_.fetch_add(1, std::memory_order_relaxed);
    drop_pending_ = true;
    (void)free_.try_push(slot);
    frame.release();
    return false;
  }
  const TimeNs t =
      meaning_ == cam::TimestampMeaning::kEndOfFrame ? frame.t_ns : cam::mid_exposure_ns(frame, meaning_);
  s.t_ns = t - options_.time_offset_ns;
  s.exposure_ns = frame.exposure_ns;
  s.sequence = frame.sequence;
  s.flags = drop_pending_ ? 1u : 0u;
  drop_pending_ = false;
  frame.release();
  if (inspect) {
    // The slot is the producer's until it is pushed to the encoder.
    inspect(PublishedFrame{s.image.data, format_.width, format_.height, s.t_ns, s.exposure_ns, s.sequence});
  }
  (void)filled_.try_push(slot);  // never full: it has as many places as there are slots
  const std::size_t waiting = filled_.size_approx();
  std::size_t hw = high_water_.load(std::memory_order_relaxed);
  while (waiting > hw && !high_water_.compare_exchange_weak(hw, waiting, std::memory_order_relaxed)) {
  }
  return true;
}

Status CameraStream::write_slot(Slot& slot) {
  const log::Image& image = slot.image;
  auto encoded = options_.encoding == "webp" ? log::encode_webp_lossless(image)
                                             : log::encode_png(image, options_.png_level);
  if (!encoded.ok()) return encoded.error().context("encoding frame " + std::to_string(slot.sequence));
  CameraFrame frame;
  frame.t_ns = slot.t_ns;
  frame.width = format_.width;
  frame.height = format_.height;
  frame.encoding = options_.encoding;
  frame.data = std::move(*encoded);
  frame.exposure_ns = slot.exposure_ns;
  frame.sequence = slot.sequence;
  frame.flags = slot.flags;
  encoded_bytes_.fetch_add(frame.data.size(), std::memory_order_relaxed);
  IMUCAL_TRY(writer_->append_frame(stream_id_, frame));
  written_.fetch_add(1, std::memory_order_relaxed);
  return {};
}

void CameraStream::fail(const Error& error) {
  std::lock_guard lock(error_mutex_);
  if (!log_failed_.load()) error_ = error;
  log_failed_.store(true, std::memory_order_release);
}

void CameraStream::encoder_loop() {
  while (true) {
    int slot = -1;
    if (!filled_.try_pop(slot)) {
      if (stop_requested_.load(std::memory_order_acquire) && filled_.empty_approx()) break;
      std::this_thread::sleep_for(std::chrono::nanoseconds(options_.idle_sleep_ns));
      continue;
    }
    if (!log_failed()) {
      Status st = write_slot(slots_[static_cast<std::size_t>(slot)]);
      if (!st.ok()) fail(st.error());
    }
    (void)free_.try_push(slot);
  }
}

Status CameraStream::stop() {
  if (thread_.joinable()) {
    stop_requested_.store(true, std::memory_order_release);
    thread_.join();
  }
  std::lock_guard lock(error_mutex_);
  if (log_failed_.load()) return error_;
  return {};
}

CameraStreamStats CameraStream::stats() const {
  CameraStreamStats s;
  s.published = published_.load(std::memory_order_relaxed);
  s.written = written_.load(std::memory_order_relaxed);
  s.queue_dropped = queue_dropped_.load(std::memory_order_relaxed);
  s.device_dropped = device_dropped_.load(std::memory_order_relaxed);
  s.wrong_size = wrong_size_.load(std::memory_order_relaxed);
  s.encoded_bytes = encoded_bytes_.load(std::memory_order_relaxed);
  s.queue_high_water = high_water_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace imucal::acq
