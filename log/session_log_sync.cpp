// SPDX-License-Identifier: BSD-3-Clause
// A session-log writer shared by threads (log/session_log.hpp synchronized_writer()).

#include <mutex>

#include "log/session_log.hpp"

namespace imucal::log {
namespace {

class SynchronizedWriter final : public SessionLogWriter {
 public:
  explicit SynchronizedWriter(SessionLogWriter& inner) : inner_(inner) {}

  Status set_metadata(const std::string& key, const std::string& value) override {
    std::lock_guard lock(mutex_);
    return inner_.set_metadata(key, value);
  }
  Result<int> add_imu_stream(const ImuStreamInfo& info) override {
    std::lock_guard lock(mutex_);
    return inner_.add_imu_stream(info);
  }
  Result<int> add_camera_stream(const CameraStreamInfo& info) override {
    std::lock_guard lock(mutex_);
    return inner_.add_camera_stream(info);
  }
  Status append_imu(int stream_id, std::span<const ImuSample> samples) override {
    std::lock_guard lock(mutex_);
    return inner_.append_imu(stream_id, samples);
  }
  Status append_frame(int stream_id, const CameraFrame& frame) override {
    std::lock_guard lock(mutex_);
    return inner_.append_frame(stream_id, frame);
  }
  Status append_event(const Event& event) override {
    std::lock_guard lock(mutex_);
    return inner_.append_event(event);
  }
  Status flush() override {
    std::lock_guard lock(mutex_);
    return inner_.flush();
  }
  Status close() override {
    std::lock_guard lock(mutex_);
    return inner_.close();
  }

 private:
  SessionLogWriter& inner_;
  std::mutex mutex_;
};

}  // namespace

std::unique_ptr<SessionLogWriter> synchronized_writer(SessionLogWriter& inner) {
  return std::make_unique<SynchronizedWriter>(inner);
}

}  // namespace imucal::log
