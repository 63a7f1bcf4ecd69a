// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Camera frames and stream descriptions shared by drivers, acquisition and calib.

#include <cstdint>
#include <string>
#include <vector>

#include "core/time.hpp"

namespace imucal {

/// One camera frame. `encoding` names what `data` holds: "png" (lossless, any bit depth),
/// "webp" (lossless), "gray8" (raw width*height bytes), or a V4L2-style fourcc for raw formats.
/// t_ns is the mid-exposure time on CLOCK_MONOTONIC when the backend knows it, else the
/// backend's own timestamp; `timestamp_source` in the stream info says which.
struct CameraFrame {
  TimeNs t_ns = 0;
  int width = 0;
  int height = 0;
  std::string encoding = "png";
  std::vector<std::uint8_t> data;
  TimeNs exposure_ns = 0;
  std::uint32_t sequence = 0;
  std::uint32_t flags = 0;  // bit 0: a frame was dropped before this one
};

struct CameraStreamInfo {
  std::string name = "cam0";
  int width = 0;
  int height = 0;
  double rate_hz = 0.0;
  std::string backend;  // "v4l2", "libcamera", "aravis", "sim", "euroc"
  std::string device;
  std::string timestamp_source;  // "mid-exposure", "end-of-frame", "start-of-frame"
};

}  // namespace imucal
