// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: stored target detections as `calibrate camera` and `calibrate camimu` read them
// back (app/camera_calibration.cpp): a detection cache file (log/target_detections.hpp) of
// arbitrary bytes, or one detection's text (app/results/camera_results.hpp), the first byte
// choosing which. Every detection read is decoded and checked against a 42-point target
// (calib::check_observation); one that passes must index only the target's points, which this
// target does with the ids it was given (a sanitizer report otherwise). Any bytes must give
// detections or an error with a message, never a crash or an exception.

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "app/results/camera_results.hpp"
#include "calib/observation_check.hpp"
#include "calib/target_detection.hpp"
#include "log/target_detections.hpp"

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

constexpr int kTargetPoints = 42;  // a checkerboard of 7 x 6 inner corners

void use(const std::string& text, imucal::TimeNs t_ns) {
  auto o = imucal::app::decode_detection(text, t_ns);
  if (!o.ok()) {
    require(!o.error().message.empty());
    return;
  }
  const imucal::Status usable = imucal::calib::check_observation(*o, kTargetPoints);
  if (!usable.ok()) {
    require(!usable.error().message.empty());
    return;
  }
  // What the estimators do with a checked observation: index the points by its ids.
  static const std::vector<double> points(kTargetPoints, 1.0);
  double sum = 0.0;
  require(o->px.size() == o->ids.size());
  for (std::size_t k = 0; k < o->ids.size(); ++k)
    sum += points[static_cast<std::size_t>(o->ids[k])] * o->px[k].x();
  (void)sum;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal;
  if (size == 0) return 0;
  if (data[0] % 2 == 1) {
    use(std::string(reinterpret_cast<const char*>(data) + 1, size - 1), 1);
    return 0;
  }
  static const std::string path = "/tmp/imucal-fuzz-detections-" + std::to_string(::getpid()) + ".sqlite";
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    if (size > 1) require(std::fwrite(data + 1, 1, size - 1, f) == size - 1);
    std::fclose(f);
  }
  auto set = log::read_detection_cache(path, "k");
  if (!set.ok()) {
    require(!set.error().message.empty());
  } else if (*set) {
    for (const auto& d : (*set)->detections) use(d.data, d.t_ns);
  }
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
  return 0;
}
