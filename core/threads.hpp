// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The worker-thread count of an option where 0 means "one per core", and independent jobs run
// side by side on that many threads.

#include <algorithm>
#include <cstdlib>
#include <functional>
#include <thread>
#include <vector>

namespace imucal {

/// `requested` when it is positive; otherwise one thread per core, and at least one.
inline int threads_or_cores(int requested) {
  return requested > 0 ? requested : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

/// Caps OpenMP at one thread per team unless the environment sets OMP_THREAD_LIMIT. The only
/// OpenMP user is Debian's CHOLMOD 3 (Ceres' sparse Cholesky), whose factorization asks for a team
/// of four whatever the machine or --threads says: on two cores their hand-overs cost 150,000
/// context switches and 1-1.5 s of CPU in a camera-IMU calibration of a 35 s recording, for the
/// same solution (docs/camimu-calibration.md, "Method"). libgomp reads the variable when it is
/// loaded, with the first module: call this at the start of main.
inline void limit_openmp_teams() { setenv("OMP_THREAD_LIMIT", "1", /*overwrite=*/0); }

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
