// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/camera/camera.hpp"

namespace imucal::drivers::camera {

const char* timestamp_meaning_name(TimestampMeaning meaning) {
  switch (meaning) {
    case TimestampMeaning::kStartOfExposure:
      return "start-of-exposure";
    case TimestampMeaning::kMidExposure:
      return "mid-exposure";
    case TimestampMeaning::kEndOfFrame:
      return "end-of-frame";
  }
  return "unknown";
}

Frame& Frame::operator=(Frame&& other) noexcept {
  if (this == &other) return *this;
  release();
  t_ns = other.t_ns;
  exposure_ns = other.exposure_ns;
  sequence = other.sequence;
  width = other.width;
  height = other.height;
  pixel_format = std::move(other.pixel_format);
  stride = other.stride;
  data = other.data;
  release_action_ = std::move(other.release_action_);
  other.release_action_ = nullptr;
  other.data = {};
  return *this;
}

void Frame::release() {
  if (release_action_) {
    auto action = std::move(release_action_);
    release_action_ = nullptr;
    action();
  }
  data = {};
}

TimeNs mid_exposure_ns(const Frame& frame, TimestampMeaning meaning) {
  switch (meaning) {
    case TimestampMeaning::kStartOfExposure:
      return frame.t_ns + frame.exposure_ns / 2;
    case TimestampMeaning::kMidExposure:
      return frame.t_ns;
    case TimestampMeaning::kEndOfFrame:
      return frame.t_ns - frame.exposure_ns / 2;
  }
  return frame.t_ns;
}

}  // namespace imucal::drivers::camera
