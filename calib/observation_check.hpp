#pragma once
// Target observations read back from a file (the detection cache, a log) are checked against the
// target before any of their ids indexes its points.

#include "calib/target_detection.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// Whether `o` can be used against a target of `target_points` points: one pixel per id, ids
/// within [0, target_points), finite pixels. kCorrupt naming the first fault (the id, the
/// target's point count).
[[nodiscard]] Status check_observation(const TargetObservation& o, int target_points);

}  // namespace imucal::calib
