// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The producer side of IMU acquisition: the acquisition thread publishes timestamped samples;
// the stream copies them into one SPSC ring per consumer (live displays, detectors) and into the
// session-log writer's ring, which a writer thread of its own drains in batches. The producer
// never blocks and never allocates while publishing: a full ring drops the sample for that
// reader only and counts it (stats()), it is never silent.
//
// Threads: add_consumer() and start_log() before the first publish(); publish() and
// post_event() from the one producer thread; each consumer's pop from one thread of its own;
// stats() from anywhere.

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/ring_buffer.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "log/session_log.hpp"

namespace imucal::acq {

/// A consumer's end of the stream.
class ImuConsumer {
 public:
  ImuConsumer(std::string name, std::size_t capacity) : name_(std::move(name)), ring_(capacity) {}

  /// Pops up to out.size() samples, oldest first.
  [[nodiscard]] std::size_t pop(std::span<ImuSample> out) { return ring_.try_pop_bulk(out); }
  [[nodiscard]] bool pop(ImuSample& out) { return ring_.try_pop(out); }

  const std::string& name() const { return name_; }
  std::size_t capacity() const { return ring_.capacity(); }
  /// Samples this consumer missed because its ring was full.
  std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }
  std::uint64_t delivered() const { return delivered_.load(std::memory_order_relaxed); }

 private:
  friend class ImuStream;
  std::string name_;
  SpscRingBuffer<ImuSample> ring_;
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> delivered_{0};
};

struct ImuStreamOptions {
  /// Samples the log ring holds; at 8 kHz, 65536 samples ride out an 8 s storage stall.
  std::size_t log_queue_capacity = 1 << 16;
  /// Most samples per append_imu() call.
  std::size_t log_batch_max = 2048;
  /// The writer thread sleeps this long when its ring is empty.
  TimeNs writer_idle_sleep_ns = 2'000'000;
  /// The writer thread calls flush() at least this often while samples arrive.
  TimeNs flush_interval_ns = 500'000'000;
  std::size_t event_queue_capacity = 256;
};

struct ImuConsumerStats {
  std::string name;
  std::uint64_t delivered = 0;
  std::uint64_t dropped = 0;
};

struct ImuStreamStats {
  std::uint64_t published = 0;
  std::uint64_t log_written = 0;  // samples appended by the writer thread
  std::uint64_t log_dropped = 0;  // samples the log ring had no room for
  std::uint64_t log_batches = 0;  // append_imu() calls
  std::uint64_t events_written = 0;
  std::uint64_t events_dropped = 0;
  std::size_t log_queue_high_water = 0;  // most samples waiting in the log ring at once
  std::vector<ImuConsumerStats> consumers;
};

class ImuStream {
 public:
  explicit ImuStream(ImuStreamOptions options = {});
  ~ImuStream();  // stops the writer thread (its error, if any, is lost: call stop() first)
  ImuStream(const ImuStream&) = delete;
  ImuStream& operator=(const ImuStream&) = delete;

  /// Adds a consumer with a ring of at least `capacity` samples.
  std::shared_ptr<ImuConsumer> add_consumer(std::string name, std::size_t capacity);

  /// Starts the writer thread, which appends to `writer` under `stream_id`. The writer is
  /// borrowed and must not be used by anyone else until stop() returns.
  [[nodiscard]] Status start_log(log::SessionLogWriter& writer, int stream_id);

  /// Producer: hands samples to every consumer and to the log. Never blocks.
  void publish(std::span<const ImuSample> samples);
  /// Producer: queues an event for the log (a fault, a gap). Never blocks; counted when full.
  void post_event(log::Event event);

  /// True once the writer thread failed to write; it stops writing then (see stop()).
  bool log_failed() const { return log_failed_.load(std::memory_order_acquire); }

  /// Stops the writer thread after it has written everything queued and flushed. Returns the
  /// first write error, if any. Idempotent.
  [[nodiscard]] Status stop();

  ImuStreamStats stats() const;

 private:
  void writer_loop();

  ImuStreamOptions options_;
  std::vector<std::shared_ptr<ImuConsumer>> consumers_;
  SpscRingBuffer<ImuSample> log_ring_;
  SpscRingBuffer<log::Event> event_ring_;
  log::SessionLogWriter* writer_ = nullptr;
  int stream_id_ = -1;
  std::thread thread_;
  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> log_failed_{false};
  std::mutex error_mutex_;
  Error error_;

  std::atomic<std::uint64_t> published_{0};
  std::atomic<std::uint64_t> log_written_{0};
  std::atomic<std::uint64_t> log_dropped_{0};
  std::atomic<std::uint64_t> log_batches_{0};
  std::atomic<std::uint64_t> events_written_{0};
  std::atomic<std::uint64_t> events_dropped_{0};
  std::atomic<std::size_t> log_high_water_{0};
};

}  // namespace imucal::acq
