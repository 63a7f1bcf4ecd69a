// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera side of acquisition: the acquisition thread hands each dequeued frame to publish(),
// which copies its pixels (converted to 8-bit grey) into a free slot of a fixed pool and gives the
// device buffer straight back; an encoder thread of the stream's own encodes the slots losslessly
// (PNG or WebP, log/frame_codec.hpp) and appends them to the session log. Memory is bounded by
// the pool (queue_frames x width x height bytes) whatever the frame rate. When the encoder or the
// disk falls behind, the pool runs out and publish() drops the frame and counts it: the
// acquisition thread never waits, so IMU samples, which have their own ring and writer, are
// never lost for a camera's sake. (Simulated clocks wait instead: block_when_full.)
//
// Pixel formats recorded: 8-bit grey (V4L2 GREY, GenICam Mono8, libcamera R8) as is, and the
// luma of packed YUV 4:2:2 (YUYV, UYVY); see supported_pixel_formats().
//
// Threads: publish() from one producer thread; stats() from anywhere.

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/ring_buffer.hpp"
#include "core/frame.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/camera/camera.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"

namespace imucal::acq {

struct CameraStreamOptions {
  /// Frames waiting for the encoder; bounds the memory at queue_frames x width x height bytes.
  std::size_t queue_frames = 16;
  /// "png" (fast zlib settings, ~3x smaller than raw) or "webp" (lossless, smaller, slower).
  std::string encoding = "png";
  /// PNG only: zlib level 0-9, or log::kPngFast (OpenCV's fast default settings).
  int png_level = -1;
  /// For simulated clocks: publish() waits for a free slot instead of dropping the frame.
  bool block_when_full = false;
  /// Subtracted from every stamp (simulated sessions store trajectory time).
  TimeNs time_offset_ns = 0;
  /// The encoder thread sleeps this long when nothing is queued.
  TimeNs idle_sleep_ns = 2'000'000;
};

struct CameraStreamStats {
  std::uint64_t published = 0;       // frames handed to publish()
  std::uint64_t written = 0;         // frames appended to the log
  std::uint64_t queue_dropped = 0;   // no free slot: the encoder or the disk fell behind
  std::uint64_t device_dropped = 0;  // gaps in the device's sequence numbers
  std::uint64_t wrong_size = 0;      // frames of another size than the stream's (not recorded)
  std::uint64_t encoded_bytes = 0;
  std::size_t queue_high_water = 0;  // most frames waiting at once
};

/// A frame as publish() recorded it, for a caller that also looks at it (the service searches it
/// for the target): 8-bit grey rows without padding and the stamp the log holds. Valid only
/// during the call.
struct PublishedFrame {
  std::span<const std::uint8_t> grey;
  int width = 0;
  int height = 0;
  TimeNs t_ns = 0;
  TimeNs exposure_ns = 0;
  std::uint32_t sequence = 0;
};

/// The pixel formats publish() can record.
const std::vector<std::string>& supported_pixel_formats();

class CameraStream {
 public:
  /// `format` is the camera's configured format; `meaning` what its stamps mark. Fails for a
  /// pixel format that cannot be recorded (the message lists those that can).
  [[nodiscard]] static Result<std::unique_ptr<CameraStream>> create(
      const drivers::camera::FrameFormat& format, drivers::camera::TimestampMeaning meaning,
      CameraStreamOptions options = {});
  ~CameraStream();  // stops the encoder thread (its error, if any, is lost: call stop() first)
  CameraStream(const CameraStream&) = delete;
  CameraStream& operator=(const CameraStream&) = delete;

  /// How the log describes the stream's stamps: "mid-exposure" for cameras that stamp the start
  /// or the middle of the exposure (stamps are moved to mid-exposure with the frame's exposure
  /// time), else the camera's own meaning.
  std::string timestamp_source() const;

  /// Starts the encoder thread appending to `writer` (shared with other threads: use
  /// log::synchronized_writer) under `stream_id`.
  [[nodiscard]] Status start_log(log::SessionLogWriter& writer, int stream_id);

  /// Producer: copies the frame into a free slot and releases it. False when it was not recorded
  /// (dropped, wrong size, or the log failed). `inspect`, when given, sees the recorded frame on
  /// this thread before the encoder does.
  bool publish(drivers::camera::Frame& frame, const std::function<void(const PublishedFrame&)>& inspect = {});

  TimeNs time_offset_ns() const { return options_.time_offset_ns; }
  bool log_failed() const { return log_failed_.load(std::memory_order_acquire); }

  /// Encodes and writes everything queued, then stops the encoder thread. Returns the first
  /// encoding or write error. Idempotent.
  [[nodiscard]] Status stop();

  CameraStreamStats stats() const;

 private:
  struct Slot {
    log::Image image;  // 8-bit grey, handed to the encoder as it is
    TimeNs t_ns = 0;
    TimeNs exposure_ns = 0;
    std::uint32_t sequence = 0;
    std::uint32_t flags = 0;
  };

  CameraStream(const drivers::camera::FrameFormat& format, drivers::camera::TimestampMeaning meaning,
               CameraStreamOptions options);
  void encoder_loop();
  Status write_slot(Slot& slot);
  void fail(const Error& error);

  drivers::camera::FrameFormat format_;
  drivers::camera::TimestampMeaning meaning_;
  int layout_ = 0;  // how publish() takes the luma (camera_stream.cpp Layout), from the pixel format
  CameraStreamOptions options_;
  std::vector<Slot> slots_;
  SpscRingBuffer<int> free_;    // encoder -> producer
  SpscRingBuffer<int> filled_;  // producer -> encoder
  log::SessionLogWriter* writer_ = nullptr;
  int stream_id_ = -1;
  std::thread thread_;
  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> log_failed_{false};
  std::mutex error_mutex_;
  Error error_;
  bool have_sequence_ = false;
  std::uint32_t last_sequence_ = 0;
  bool drop_pending_ = false;  // the next recorded frame carries "dropped before"

  std::atomic<std::uint64_t> published_{0};
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> queue_dropped_{0};
  std::atomic<std::uint64_t> device_dropped_{0};
  std::atomic<std::uint64_t> wrong_size_{0};
  std::atomic<std::uint64_t> encoded_bytes_{0};
  std::atomic<std::size_t> high_water_{0};
};

}  // namespace imucal::acq
