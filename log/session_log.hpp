// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The session log: one SQLite database (.imulog) per recording. See docs/session-log.md for
// the schema. Writer: WAL mode, batched inserts, commits at a bounded interval, so a power
// cut loses at most that interval and never corrupts what was committed. Reader: streams
// by time range; a damaged or truncated file yields everything readable before the damage
// and says what is wrong.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/frame.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::log {

/// Current schema version written to the `schema_version` metadata key.
inline constexpr int kSessionLogSchemaVersion = 1;

/// Operator prompts, pose boundaries, faults, notes.
struct Event {
  TimeNs t_ns = 0;
  std::string kind;     // e.g. "prompt", "pose_begin", "pose_end", "fault", "note"
  std::string message;  // free text or JSON
};

struct SessionLogWriterOptions {
  /// Longest time between commits; a power cut loses at most this much.
  TimeNs commit_interval_ns = 500'000'000;
  /// Also commit when the IMU samples of the open transaction span this much sample time (0:
  /// off). A writer fed faster than real time (a simulation, the service's virtual rig at
  /// time-scale 0) bounds what a failure such as a kill or a full disk can take with it by data,
  /// not by the wall clock. With this bound on, a log that is not staged also commits its first
  /// IMU samples (with the metadata and streams declared before them) at once, so a log killed
  /// early is a session log with samples, whatever the rate it is fed at.
  TimeNs commit_data_interval_ns = 500'000'000;
  /// Replace an existing file at the path instead of failing.
  bool overwrite = false;
  /// The path is a temporary file that is renamed into place only once closed (an import): a
  /// failure part way leaves nothing worth keeping, so there is no journal and commits are not
  /// synced until close(), which syncs the whole file. The closed log is the same as one written
  /// otherwise. Several times faster for bulk writes (set commit_data_interval_ns to 0 there);
  /// never for recording.
  bool staged = false;
};

/// Writes one session log. Not thread-safe: one writer thread owns it.
class SessionLogWriter {
 public:
  virtual ~SessionLogWriter() = default;

  /// Creates a new log at `path` (fails if it exists unless options.overwrite).
  [[nodiscard]] static Result<std::unique_ptr<SessionLogWriter>> create(
      const std::string& path, const SessionLogWriterOptions& options = {});

  /// Metadata: free keys with JSON or text values (rig config, driver settings, serials).
  /// The writer itself sets "schema_version", "software_version", "created_utc" and
  /// "complete" (on close()).
  [[nodiscard]] virtual Status set_metadata(const std::string& key, const std::string& value) = 0;

  /// Declares a stream; returns its id (unique within the log).
  [[nodiscard]] virtual Result<int> add_imu_stream(const ImuStreamInfo& info) = 0;
  [[nodiscard]] virtual Result<int> add_camera_stream(const CameraStreamInfo& info) = 0;

  [[nodiscard]] virtual Status append_imu(int stream_id, std::span<const ImuSample> samples) = 0;
  [[nodiscard]] Status append_imu(int stream_id, const ImuSample& sample) {
    return append_imu(stream_id, std::span<const ImuSample>(&sample, 1));
  }
  [[nodiscard]] virtual Status append_frame(int stream_id, const CameraFrame& frame) = 0;
  [[nodiscard]] virtual Status append_event(const Event& event) = 0;

  /// Commits what is buffered now.
  [[nodiscard]] virtual Status flush() = 0;
  /// Commits, marks the log complete and closes it. Further calls fail.
  [[nodiscard]] virtual Status close() = 0;
};

/// A writer shared by several threads (the IMU stream's writer thread and each camera's encoder
/// thread): every call on the returned writer takes a mutex and forwards to `inner`, which is
/// borrowed and must outlive it.
std::unique_ptr<SessionLogWriter> synchronized_writer(SessionLogWriter& inner);

/// Summary of what a reader found, including damage.
struct SessionLogHealth {
  bool complete = false;       // the writer closed it cleanly
  bool damaged = false;        // corruption or truncation was found
  std::string damage_message;  // what, and what was still readable
};

/// How a reader is opened.
struct SessionLogReaderOptions {
  /// Keep every IMU sample read by the check of the sample table that opening makes anyway, so
  /// that take_imu() hands them over without reading the file a second time. For a caller that
  /// wants whole streams (a calibration); the samples of every IMU stream are held meanwhile.
  bool preload_imu = false;
};

/// Reads one session log.
class SessionLogReader {
 public:
  virtual ~SessionLogReader() = default;

  /// Opens read-only. A file that is not a session log, or whose schema is newer than this
  /// build understands, is an error; a damaged one opens and reports it in health().
  [[nodiscard]] static Result<std::unique_ptr<SessionLogReader>> open(
      const std::string& path, const SessionLogReaderOptions& options = {});

  virtual const SessionLogHealth& health() const = 0;
  virtual const std::map<std::string, std::string>& metadata() const = 0;

  /// Streams by id.
  virtual const std::map<int, ImuStreamInfo>& imu_streams() const = 0;
  virtual const std::map<int, CameraStreamInfo>& camera_streams() const = 0;
  /// The id of the first IMU stream, or of the one named `name`.
  [[nodiscard]] virtual Result<int> find_imu_stream(const std::string& name = "") const = 0;
  [[nodiscard]] virtual Result<int> find_camera_stream(const std::string& name = "") const = 0;

  /// Visits IMU samples of one stream with t0_ns <= t_ns < t1_ns in time order. The visitor
  /// returns false to stop early. Values are as stored (raw counts or SI, see the stream).
  [[nodiscard]] virtual Status for_each_imu(int stream_id, TimeNs t0_ns, TimeNs t1_ns,
                                            const std::function<bool(const ImuSample&)>& visit) const = 0;
  /// All samples of a stream.
  [[nodiscard]] Result<std::vector<ImuSample>> read_imu(int stream_id) const;
  /// All samples of a stream, like read_imu; a reader opened with preload_imu hands over the ones
  /// it holds (later reads of the stream read the file again).
  [[nodiscard]] virtual Result<std::vector<ImuSample>> take_imu(int stream_id) { return read_imu(stream_id); }

  [[nodiscard]] virtual Status for_each_frame(int stream_id, TimeNs t0_ns, TimeNs t1_ns,
                                              const std::function<bool(const CameraFrame&)>& visit) const = 0;
  /// Frame timestamps only (no image data), cheap.
  [[nodiscard]] virtual Result<std::vector<TimeNs>> frame_times(int stream_id) const = 0;
  /// The identity of a camera stream's content: a 64-bit hash (FNV-1a) of every frame's time,
  /// size, encoding and stored data checksum, in time order. Equal for two copies of a log, and
  /// different once a frame is added, removed or changed. Reads no image data, but the file's
  /// pages that hold it (about the cost of copying the log).
  [[nodiscard]] virtual Result<std::uint64_t> frame_fingerprint(int stream_id) const = 0;

  [[nodiscard]] virtual Result<std::vector<Event>> events() const = 0;

  /// Number of IMU samples / frames in a stream.
  [[nodiscard]] virtual Result<std::int64_t> imu_count(int stream_id) const = 0;
  [[nodiscard]] virtual Result<std::int64_t> frame_count(int stream_id) const = 0;
};

inline constexpr TimeNs kTimeMin = INT64_MIN;
inline constexpr TimeNs kTimeMax = INT64_MAX;

}  // namespace imucal::log
