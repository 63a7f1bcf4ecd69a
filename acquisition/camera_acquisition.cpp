// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/camera_acquisition.hpp"

#include <cstdio>

namespace imucal::acq {

CameraAcquisition::CameraAcquisition(drivers::camera::Camera& camera, std::string name,
                                     std::unique_ptr<CameraStream> stream, EventSink events,
                                     TimeNs stall_timeout_ns)
    : camera_(camera),
      name_(std::move(name)),
      stream_(std::move(stream)),
      events_(std::move(events)),
      stall_timeout_ns_(stall_timeout_ns) {}

void CameraAcquisition::post(TimeNs host_t_ns, std::string message) {
  if (!events_) return;
  log::Event e;
  e.t_ns = host_t_ns - stream_->time_offset_ns();
  e.kind = "fault";
  e.message = std::move(message);
  events_(std::move(e));
}

bool CameraAcquisition::service(TimeNs now_ns) {
  if (failed_) return false;
  if (last_frame_host_ns_ < 0) last_frame_host_ns_ = now_ns;
  while (true) {
    auto frame = camera_.dequeue();
    if (!frame.ok()) {
      failed_ = true;
      failure_ = frame.error().message;
      post(now_ns, "camera " + name_ + " failed: " + failure_ +
                       "; recording goes on without it (check the cable and the device, then record again)");
      return false;
    }
    if (!frame->valid()) break;
    last_frame_host_ns_ = now_ns;
    if (silent_) {
      silent_ = false;
      post(now_ns, "camera " + name_ + " delivers frames again");
    }
    stream_->publish(*frame);
  }
  if (!silent_ && now_ns - last_frame_host_ns_ > stall_timeout_ns_) {
    silent_ = true;
    ++stalls_;
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%.1f", ns_to_s(now_ns - last_frame_host_ns_));
    post(now_ns, "camera " + name_ + " delivered no frame for " + seconds +
                     " s (a stalled camera, a trigger that never comes, or a lost link)");
  }
  return true;
}

CameraAcquisitionStats CameraAcquisition::stats() const {
  CameraAcquisitionStats s;
  s.stream = stream_->stats();
  s.device = camera_.counters();
  s.stalls = stalls_;
  s.failed = failed_;
  s.failure = failure_;
  return s;
}

}  // namespace imucal::acq
