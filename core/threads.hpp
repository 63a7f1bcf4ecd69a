// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The worker-thread count of an option where 0 means "one per core", and independent jobs run
// side by side on that many threads.

#include <algorithm>
#include <functional>
#include <thread>
#include <vector>

namespace imucal {

/// `requested` when it is positive; otherwise one thread per core, and at least one.
inline int threads_or_cores(int requested) {
  return requested > 0 ? requested : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

/// Runs job(0) ... job(jobs - 1), `workers` of them at a time, and returns when all are done.
inline void run_side_by_side(int jobs, int workers, const std::function<void(int)>& job) {
  workers = std::max(1, workers);
  for (int first = 0; first < jobs; first += workers) {
    std::vector<std::thread> pool;
    for (int j = first; j < std::min(jobs, first + workers); ++j) pool.emplace_back(job, j);
    for (auto& t : pool) t.join();
  }
}

}  // namespace imucal
