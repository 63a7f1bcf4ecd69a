// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Loading one IMU stream from a session log under a damage policy: what every command that
// works on a recorded stream (calibrate, allan, the rig service) does before its method.

#include <memory>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "log/session_log.hpp"

namespace imucal::app {

/// What to do with a damaged (corrupt or truncated) log.
enum class DamagePolicy {
  kRefuse,  // fail: a damaged log is usually a recording to repeat
  kAllow,   // use what is readable
};

/// One IMU stream read from a log. The reader stays open for the log's metadata and health.
struct LoadedStream {
  std::unique_ptr<log::SessionLogReader> reader;
  int stream_id = 0;
  ImuStreamInfo info;
  std::vector<ImuSample> samples;

  bool damaged() const { return reader->health().damaged; }
  /// "the log is damaged (what)" for a damaged log, empty otherwise; callers add what it
  /// means for their result.
  std::string damage_warning() const;
};

/// Opens `path`, applies `policy`, finds the IMU stream `stream_name` (empty: the first) and
/// reads all its samples. Errors carry the path as context. A damaged log refused by the
/// policy fails with Errc::kCorrupt and the remedy "allow_damaged", so that a caller can say
/// how to allow it in its own terms.
[[nodiscard]] Result<LoadedStream> load_imu_stream(const std::string& path, const std::string& stream_name,
                                                   DamagePolicy policy);

}  // namespace imucal::app
