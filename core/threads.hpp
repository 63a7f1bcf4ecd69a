#pragma once
// The worker-thread count of an option where 0 means "one per core".

#include <algorithm>
#include <thread>

namespace imucal {

/// `requested` when it is positive; otherwise one thread per core, and at least one.
inline int threads_or_cores(int requested) {
  return requested > 0 ? requested : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

}  // namespace imucal
