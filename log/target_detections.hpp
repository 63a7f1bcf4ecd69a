// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Target detections stored in a session log, so that the frames of a camera stream are searched
// for the calibration target once: `imucal calibrate camera` stores what it found and later runs
// read it back. Schema and guarantees: docs/session-log.md ("Stored target detections").
//
// The detections live in two tables of their own (target_detection_sets, target_detections),
// created when first needed; no existing table is touched. A set is written in one transaction:
// it is there completely or not at all. A set is keyed by the stream and a caller-chosen key
// (the fingerprint of the target description and of the detector); what a detection holds is
// the caller's text (the log does not interpret it).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::log {

/// The detection of one frame, as the caller encoded it.
struct StoredDetection {
  TimeNs t_ns = 0;
  std::string data;
};

/// The detections of one camera stream for one key.
struct DetectionSet {
  std::string target_key;                   // fingerprint of what produced the detections
  std::string description;                  // for people (the target, the detector); not interpreted
  std::int64_t frames = 0;                  // frames searched; frames without a detection have no row
  std::string created_utc;                  // set by write_target_detections
  std::vector<StoredDetection> detections;  // in time order
};

/// The set stored for (stream_id, target_key), or nullopt when the log holds none (including a
/// log from before these tables existed). Opens the log read-only. Errc::kCorrupt when the
/// tables are there but unreadable.
[[nodiscard]] Result<std::optional<DetectionSet>> read_target_detections(const std::string& log_path,
                                                                         int stream_id,
                                                                         const std::string& target_key);

/// Stores `set` for `stream_id` in the existing log at `log_path`, replacing a set with the same
/// key, in one transaction (a failure or a power cut leaves the log as it was). Refuses a log it
/// cannot write (read-only file or folder, a writer still holding it: Errc::kIo) and a file that
/// is not a session log (Errc::kCorrupt); callers must not write into a log the reader found
/// damaged.
[[nodiscard]] Status write_target_detections(const std::string& log_path, int stream_id,
                                             const DetectionSet& set);

/// A detection cache: a SQLite file of its own (application id kDetectionCacheApplicationId)
/// holding the sets of one camera stream's content, so that a log that must not be written (a
/// dataset, a fixture, someone else's recording) is still searched once. The caller names the
/// file after the stream's content (SessionLogReader::frame_fingerprint); the tables are the
/// log's, with stream_id 0. docs/session-log.md ("Detection cache").
inline constexpr int kDetectionCacheApplicationId = 0x494D4443;  // "IMDC"

/// The set stored in the cache file for `target_key`, or nullopt when there is none (or no file).
/// Errc::kCorrupt when the file is not a detection cache or is unreadable.
[[nodiscard]] Result<std::optional<DetectionSet>> read_detection_cache(const std::string& cache_path,
                                                                       const std::string& target_key);

/// Stores `set` in the cache file (created with its folder when missing), replacing a set with
/// the same key, in one transaction.
[[nodiscard]] Status write_detection_cache(const std::string& cache_path, const DetectionSet& set);

}  // namespace imucal::log
