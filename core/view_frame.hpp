// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A camera frame as the live view shows it (docs/service.md, "Live view"): shrunk, with the
// target's corners found in it and the camera's coverage so far. The session runner
// (app/session) makes it from a frame it records; imucald encodes it and the live view's server
// (daemon/service) sends it to the browsers. A value: it owns its pixels.
#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/session_messages.hpp"
#include "core/time.hpp"

namespace imucal {

struct ViewFrame {
  std::size_t camera = 0;               // index in the configuration
  std::string name;                     // "cam0"
  TimeNs t_ns = 0;                      // the frame's time (mid-exposure, sample clock)
  int width = 0, height = 0;            // the shrunk image
  int full_width = 0, full_height = 0;  // the frame as recorded
  std::vector<std::uint8_t> grey;       // width x height, row-major
  /// The target's corners in the shrunk image's pixels (integer = a pixel's centre), in the
  /// target's point order; none when the target was not found.
  std::vector<Eigen::Vector2d> corners;
  /// Corners per row and rows when every corner of the target was found (so that a row's
  /// corners follow each other in `corners`); {0, 0} otherwise.
  std::array<int, 2> board{0, 0};
  bool seen = false;
  session_msg::CameraCoverage coverage;  // the camera's, this frame included
};

}  // namespace imucal
