// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/imu_stream.hpp"

#include <chrono>
#include <utility>

namespace imucal::acq {

ImuStream::ImuStream(ImuStreamOptions options)
    : options_(options), log_ring_(options.log_queue_capacity), event_ring_(options.event_queue_capacity) {}

ImuStream::~ImuStream() { (void)stop(); }

std::shared_ptr<ImuConsumer> ImuStream::add_consumer(std::string name, std::size_t capacity) {
  auto consumer = std::make_shared<ImuConsumer>(std::move(name), capacity);
  consumers_.push_back(consumer);
  return consumer;
}

Status ImuStream::start_log(log::SessionLogWriter& writer, int stream_id) {
  if (thread_.joinable()) return make_error(Errc::kInternal, "imu stream: the log writer is already running");
  writer_ = &writer;
  stream_id_ = stream_id;
  stop_requested_.store(false, std::memory_order_release);
  thread_ = std::thread([this] { writer_loop(); });
  return {};
}

void ImuStream::publish(std::span<const ImuSample> samples) {
  if (samples.empty()) return;
  published_.fetch_add(samples.size(), std::memory_order_relaxed);
  for (auto& c : consumers_) {
    const std::size_t n = c->ring_.try_push_bulk(samples);
    c->delivered_.fetch_add(n, std::memory_order_relaxed);
    if (n < samples.size()) c->dropped_.fetch_add(samples.size() - n, std::memory_order_relaxed);
  }
  if (writer_ != nullptr) {
    const std::size_t n = log_ring_.try_push_bulk(samples);
    if (n < samples.size()) log_dropped_.fetch_add(samples.size() - n, std::memory_order_relaxed);
    const std::size_t level = log_ring_.size_approx();
    if (level > log_high_water_.load(std::memory_order_relaxed)) {
      log_high_water_.store(level, std::memory_order_relaxed);
    }
  }
}

void ImuStream::post_event(log::Event event) {
  if (writer_ == nullptr || !event_ring_.try_push(std::move(event))) {
    events_dropped_.fetch_add(1, std::memory_order_relaxed);
  }
}

void ImuStream::writer_loop() {
  std::vector<ImuSample> batch(options_.log_batch_max);
  auto last_flush = std::chrono::steady_clock::now();
  bool dirty = false;
  auto record_error = [this](const Error& e) {
    std::lock_guard<std::mutex> lock(error_mutex_);
    if (!log_failed_.load(std::memory_order_relaxed)) error_ = e;
    log_failed_.store(true, std::memory_order_release);
  };
  for (;;) {
    // Read the stop flag before draining, so that everything published before stop() is written.
    const bool stopping = stop_requested_.load(std::memory_order_acquire);
    bool did_work = false;
    log::Event event;
    while (event_ring_.try_pop(event)) {
      did_work = true;
      if (log_failed()) continue;
      auto s = writer_->append_event(event);
      if (!s.ok()) {
        record_error(s.error().context("writing an event to the session log"));
      } else {
        events_written_.fetch_add(1, std::memory_order_relaxed);
        dirty = true;
      }
    }
    for (;;) {
      const std::size_t n = log_ring_.try_pop_bulk(batch);
      if (n == 0) break;
      did_work = true;
      if (log_failed()) {
        log_dropped_.fetch_add(n, std::memory_order_relaxed);
        continue;
      }
      auto s = writer_->append_imu(stream_id_, std::span<const ImuSample>(batch.data(), n));
      if (!s.ok()) {
        record_error(s.error().context("writing IMU samples to the session log"));
        log_dropped_.fetch_add(n, std::memory_order_relaxed);
        continue;
      }
      log_written_.fetch_add(n, std::memory_order_relaxed);
      log_batches_.fetch_add(1, std::memory_order_relaxed);
      dirty = true;
      if (n < batch.size()) break;
    }
    const auto now = std::chrono::steady_clock::now();
    if (dirty && !log_failed() &&
        (stopping || now - last_flush >= std::chrono::nanoseconds(options_.flush_interval_ns))) {
      auto s = writer_->flush();
      if (!s.ok()) record_error(s.error().context("committing the session log"));
      last_flush = now;
      dirty = false;
    }
    if (stopping && !did_work) break;
    if (!did_work) std::this_thread::sleep_for(std::chrono::nanoseconds(options_.writer_idle_sleep_ns));
  }
}

Status ImuStream::stop() {
  if (thread_.joinable()) {
    stop_requested_.store(true, std::memory_order_release);
    thread_.join();
  }
  writer_ = nullptr;
  if (log_failed()) {
    std::lock_guard<std::mutex> lock(error_mutex_);
    return error_;
  }
  return {};
}

ImuStreamStats ImuStream::stats() const {
  ImuStreamStats s;
  s.published = published_.load(std::memory_order_relaxed);
  s.log_written = log_written_.load(std::memory_order_relaxed);
  s.log_dropped = log_dropped_.load(std::memory_order_relaxed);
  s.log_batches = log_batches_.load(std::memory_order_relaxed);
  s.events_written = events_written_.load(std::memory_order_relaxed);
  s.events_dropped = events_dropped_.load(std::memory_order_relaxed);
  s.log_queue_high_water = log_high_water_.load(std::memory_order_relaxed);
  for (const auto& c : consumers_) s.consumers.push_back({c->name(), c->delivered(), c->dropped()});
  return s;
}

}  // namespace imucal::acq
