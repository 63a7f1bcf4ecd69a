// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/camera/fake/virtual_camera.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>

namespace imucal::drivers::camera::fake {
FrameRenderer test_pattern_renderer(int width, int height, std::uint64_t seed) {
  const std::size_t w = static_cast<std::size_t>(std::max(width, 1));
  const std::size_t h = static_cast<std::size_t>(std::max(height, 1));
  auto texture = std::make_shared<std::vector<std::uint8_t>>(w * h);
  std::uint64_t state = seed * 0x9E3779B97F4A7C15ull + 1;
  for (std::size_t r = 0; r < h; ++r) {
    for (std::size_t c = 0; c < w; ++c) {
      state ^= state << 13;
      state ^= state >> 7;
      state ^= state << 17;
      const double smooth =
          96.0 + 64.0 * std::sin(static_cast<double>(c) * 0.031) * std::cos(static_cast<double>(r) * 0.047);
      (*texture)[r * w + c] =
          static_cast<std::uint8_t>(std::clamp(smooth + static_cast<double>(state % 9) - 4.0, 0.0, 255.0));
    }
  }
  return [texture, w, h](TimeNs, std::uint32_t k, std::span<std::uint8_t> px) -> Status {
    if (px.size() != w * h) return make_error(Errc::kInvalidArgument, "test pattern: wrong buffer size");
    const std::size_t shift = (3 * static_cast<std::size_t>(k)) % w;
    for (std::size_t r = 0; r < h; ++r) {
      const std::uint8_t* src = texture->data() + r * w;
      std::uint8_t* dst = px.data() + r * w;
      std::memcpy(dst, src + shift, w - shift);
      std::memcpy(dst + (w - shift), src, shift);
    }
    return {};
  };
}

Result<std::unique_ptr<VirtualCamera>> VirtualCamera::create(const VirtualCameraOptions& options,
                                                             FrameRenderer renderer) {
  if (options.width < 8 || options.height < 8 || options.width > 8192 || options.height > 8192) {
    return make_error(Errc::kInvalidArgument, "virtual camera: width and height must be 8..8192 pixels");
  }
  if (!(options.rate_hz > 0.0) || options.rate_hz > 1000.0) {
    return make_error(Errc::kInvalidArgument, "virtual camera: the frame rate must be in (0, 1000] Hz");
  }
  const double period_ns = 1e9 / options.rate_hz;
  if (options.exposure_ns <= 0 || static_cast<double>(options.exposure_ns) >= period_ns) {
    return make_error(Errc::kInvalidArgument,
                      "virtual camera: the exposure must be positive and shorter than the frame period");
  }
  if (options.buffers < 1 || options.buffers > 64) {
    return make_error(Errc::kInvalidArgument, "virtual camera: buffers must be 1..64");
  }
  if (!renderer) return make_error(Errc::kInvalidArgument, "virtual camera: no renderer");
  std::unique_ptr<VirtualCamera> camera(new VirtualCamera(options, std::move(renderer)));
  camera->event_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (camera->event_fd_ < 0) {
    return make_error(Errc::kIo, std::string("virtual camera: eventfd: ") + std::strerror(errno));
  }
  return camera;
}

VirtualCamera::VirtualCamera(const VirtualCameraOptions& options, FrameRenderer renderer)
    : options_(options), renderer_(std::move(renderer)) {
  period_ns_ = static_cast<TimeNs>(std::llround(1e9 / options_.rate_hz));
  buffers_.resize(static_cast<std::size_t>(options_.buffers));
  for (auto& b : buffers_) b.resize(static_cast<std::size_t>(options_.width) * options_.height);
}

VirtualCamera::~VirtualCamera() {
  (void)stop();
  if (event_fd_ >= 0) ::close(event_fd_);
}

Result<std::vector<FrameFormat>> VirtualCamera::formats() { return std::vector<FrameFormat>{format()}; }

FrameFormat VirtualCamera::format() const {
  return FrameFormat{options_.width, options_.height, "GREY", options_.rate_hz};
}

Status VirtualCamera::set_format(const FrameFormat& f) {
  const bool rate_ok = f.rate_hz == 0.0 || std::abs(f.rate_hz - options_.rate_hz) < 1e-9 * options_.rate_hz;
  if (f.width != options_.width || f.height != options_.height || f.pixel_format != "GREY" || !rate_ok) {
    return make_error(Errc::kUnsupported,
                      "virtual camera " + options_.id + ": format " + std::to_string(f.width) + "x" +
                          std::to_string(f.height) + " " + f.pixel_format + " is not offered; it offers " +
                          std::to_string(options_.width) + "x" + std::to_string(options_.height) +
                          " GREY at " + std::to_string(options_.rate_hz) + " Hz");
  }
  return {};
}

Status VirtualCamera::start() {
  std::lock_guard lock(mutex_);
  if (streaming_) return make_error(Errc::kInvalidArgument, "virtual camera: already streaming");
  free_.clear();
  for (int i = 0; i < options_.buffers; ++i) free_.push_back(i);
  ready_.clear();
  streaming_ = true;
  stopping_ = false;
  if (!options_.clock) thread_ = std::thread([this] { thread_main(); });
  return {};
}

Status VirtualCamera::stop() {
  {
    std::lock_guard lock(mutex_);
    if (!streaming_) return {};
    streaming_ = false;
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard lock(mutex_);
  ready_.clear();
  return {};
}

TimeNs VirtualCamera::frame_time_ns(std::uint32_t k) const {
  return options_.first_frame_ns + static_cast<TimeNs>(k) * period_ns_;
}

bool VirtualCamera::finished(std::uint32_t k) const {
  if (options_.frame_limit != 0 && k >= options_.frame_limit) return true;
  return options_.stall_after && k >= *options_.stall_after;
}

bool VirtualCamera::due(std::uint32_t k, TimeNs now) const {
  return !finished(k) && now >= frame_time_ns(k) + options_.exposure_ns / 2;
}

Status VirtualCamera::produce(std::uint32_t k) {
  if (free_.empty()) {
    ++counters_.dropped;  // the consumer holds every buffer: the device has nowhere to put it
    return {};
  }
  const int b = free_.back();
  free_.pop_back();
  auto& pixels = buffers_[static_cast<std::size_t>(b)];
  Status st = renderer_(frame_time_ns(k), k, pixels);
  if (!st.ok()) {
    free_.push_back(b);
    return st;
  }
  ready_.emplace_back(b, k);
  return {};
}

void VirtualCamera::thread_main() {
  std::unique_lock lock(mutex_);
  while (!stopping_ && !finished(next_)) {
    const std::uint32_t k = next_;
    const TimeNs due_ns = frame_time_ns(k) + options_.exposure_ns / 2;
    // steady_clock is CLOCK_MONOTONIC with nanosecond ticks on Linux (libstdc++).
    const auto deadline = std::chrono::steady_clock::time_point(std::chrono::nanoseconds(due_ns));
    if (wake_.wait_until(lock, deadline, [this] { return stopping_; })) break;
    // A frame whose time has long passed (the renderer could not keep up) is lost, as a sensor
    // that was not read out in time loses it; stamps never drift behind the clock.
    const TimeNs late_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::steady_clock::now().time_since_epoch())
                               .count() -
                           due_ns;
    if (late_ns > period_ns_) {
      ++counters_.dropped;
      ++next_;
      continue;
    }
    if (free_.empty()) {
      ++counters_.dropped;
      ++next_;
      continue;
    }
    const int b = free_.back();
    free_.pop_back();
    lock.unlock();
    // Render without the lock: dequeue() and releases go on meanwhile.
    Status st = renderer_(frame_time_ns(k), k, buffers_[static_cast<std::size_t>(b)]);
    lock.lock();
    ++next_;
    if (!st.ok()) {
      free_.push_back(b);
      render_error_ = st.error();
      render_failed_ = true;
      break;
    }
    ready_.emplace_back(b, k);
    const std::uint64_t one = 1;
    (void)!::write(event_fd_, &one, sizeof one);
  }
}

Frame VirtualCamera::make_frame(int buffer, std::uint32_t k) {
  Frame f;
  f.t_ns = frame_time_ns(k);
  f.exposure_ns = options_.exposure_ns;
  f.sequence = k;
  f.width = options_.width;
  f.height = options_.height;
  f.pixel_format = "GREY";
  f.stride = static_cast<std::size_t>(options_.width);
  f.data = buffers_[static_cast<std::size_t>(buffer)];
  f.set_release([this, buffer] {
    std::lock_guard lock(mutex_);
    free_.push_back(buffer);
  });
  ++counters_.frames;
  return f;
}

Result<Frame> VirtualCamera::dequeue() {
  std::lock_guard lock(mutex_);
  if (lost_ || (options_.disconnect_after && counters_.frames >= *options_.disconnect_after)) {
    lost_ = true;
    return make_error(Errc::kNotFound, "camera " + options_.id + " (sim) disconnected");
  }
  if (render_failed_) return render_error_.context("virtual camera " + options_.id);
  if (!streaming_) return Frame{};
  if (options_.clock) {
    const TimeNs now = options_.clock();
    while (due(next_, now)) {
      const std::uint32_t k = next_++;
      Status st = produce(k);
      if (!st.ok())
        return st.error().context("virtual camera " + options_.id + " frame " + std::to_string(k));
    }
  }
  if (ready_.empty()) {
    std::uint64_t drained = 0;
    (void)!::read(event_fd_, &drained, sizeof drained);
    return Frame{};
  }
  const auto [buffer, k] = ready_.front();
  ready_.pop_front();
  return make_frame(buffer, k);
}

CameraCounters VirtualCamera::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace imucal::drivers::camera::fake
