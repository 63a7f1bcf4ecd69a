// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Target observations read back from a file (the detection cache, a log) are checked against the
// target before any of their ids indexes its points.

#include <string>

#include "calib/target_detection.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// Whether `o` can be used against a target of `target_points` points: one pixel per id, ids
/// within [0, target_points), finite pixels. kCorrupt naming the first fault (the id, the
/// target's point count). Inline: the estimators (imucal_calib_camera), the detection cache's
/// reader (imucal_app_camera) and the fuzz target use it without linking the detector.
[[nodiscard]] inline Status check_observation(const TargetObservation& o, int target_points) {
  const std::string at = "the detection at t_ns " + std::to_string(o.t_ns);
  if (o.px.size() != o.ids.size()) {
    return make_error(Errc::kCorrupt, at + " holds " + std::to_string(o.ids.size()) + " point ids but " +
                                          std::to_string(o.px.size()) + " pixel positions");
  }
  for (std::size_t i = 0; i < o.ids.size(); ++i) {
    const int id = o.ids[i];
    if (id < 0 || id >= target_points) {
      return make_error(Errc::kCorrupt, at + " holds point id " + std::to_string(id) +
                                            ", outside the target's " + std::to_string(target_points) +
                                            " points (ids 0-" + std::to_string(target_points - 1) + ")");
    }
    if (!o.px[i].allFinite()) {
      return make_error(Errc::kCorrupt, at + " holds a pixel position of point id " + std::to_string(id) +
                                            " that is not a finite number");
    }
  }
  return {};
}

}  // namespace imucal::calib
