// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Progress of long work (recording, simulation, import, export, detection over frames, solves),
// one shape everywhere: the fraction done, in [0, 1]. Programs show it their own way (the CLI's
// progress line, the service's status); an empty function means no one listens.

#include <functional>

namespace imucal {

using ProgressFn = std::function<void(double fraction)>;

/// Reports `done` out of `total` units of work through `progress` (nothing when it is empty;
/// total <= 0 counts as finished).
inline void report_progress(const ProgressFn& progress, double done, double total) {
  if (progress) progress(total > 0.0 ? done / total : 1.0);
}

}  // namespace imucal
