// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: the session log reader (log/session_log.hpp) on a damaged file. The input is
// written to a file and opened as a log; every stream, sample, frame and event is read, with the
// salvage of the readable part where the reader finds damage. Any bytes must give a log or an error with a
// message, never a crash, an exception or a sanitizer report; a log the reader calls undamaged
// must read to the counts it reports.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "log/session_log.hpp"

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

void read_all(const imucal::log::SessionLogReader& reader) {
  using namespace imucal;
  (void)reader.metadata();
  for (const auto& [id, info] : reader.imu_streams()) {
    std::int64_t n = 0;
    const Status s = reader.for_each_imu(id, log::kTimeMin, log::kTimeMax, [&](const ImuSample&) {
      ++n;
      return true;
    });
    const auto count = reader.imu_count(id);
    if (s.ok() && count.ok() && !reader.health().damaged) require(n == *count);
  }
  for (const auto& [id, info] : reader.camera_streams()) {
    (void)reader.frame_times(id);
    (void)reader.frame_count(id);
    (void)reader.for_each_frame(id, log::kTimeMin, log::kTimeMax, [](const CameraFrame&) { return true; });
  }
  (void)reader.events();
  (void)reader.health();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal;
  static const std::string path = "/tmp/imucal-fuzz-session-" + std::to_string(::getpid()) + ".imulog";
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    if (size > 0) require(std::fwrite(data, 1, size, f) == size);
    std::fclose(f);
  }
  auto reader = log::SessionLogReader::open(path);
  if (!reader.ok()) {
    require(!reader.error().message.empty());
  } else {
    read_all(**reader);
  }
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
  return 0;
}
