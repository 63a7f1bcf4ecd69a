// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The recording session around the acquisition loop: record_imu_session() creates the session
// log, writes the metadata (rig configuration, driver settings, mounting, timing), records for a
// given duration of sample time, in the loop the caller chooses (imu_acquisition.hpp step() or
// the event loop of asio_acquisition.hpp), and closes the log with the counters of every stage.

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "acquisition/camera_acquisition.hpp"
#include "acquisition/camera_stream.hpp"
#include "acquisition/imu_acquisition.hpp"
#include "acquisition/imu_stream.hpp"
#include "acquisition/timestamp.hpp"
#include "core/imu.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::acq {

/// How record_imu_session() drives the acquisition.
enum class RecordLoop {
  /// ImuSource::step() in a loop: for the simulated rig, whose clock advances only when
  /// the loop waits (deterministic, as fast as the host computes).
  kStep,
  /// ImuSource::service() on a Boost.Asio event loop (asio_acquisition.hpp): for a real
  /// clock (a rig, or the real-time simulated rig). The line's fd and a poll timer wake it.
  kEventLoop,
};

/// A camera recorded beside the IMU.
struct RecordCamera {
  /// Opened and configured (set_format); the recorder starts it after the log exists and stops it
  /// at the end. Borrowed.
  drivers::camera::Camera* camera = nullptr;
  /// The stream's name, backend and device as the log describes it; size, rate and timestamp
  /// source are filled in from the camera.
  CameraStreamInfo info;
  CameraStreamOptions stream;
};

struct RecordOptions {
  std::string log_path;
  bool overwrite = false;
  double duration_s = 10.0;   // of sample time
  ImuStreamInfo stream_info;  // name, units, conversion, device settings
  /// Metadata written before recording (e.g. "rig_config" as JSON, "source": "sim").
  std::vector<std::pair<std::string, std::string>> metadata;
  ImuStreamOptions stream;
  /// Receives the recorded fraction in [0, 1] (may be empty).
  ProgressFn progress;
  RecordLoop loop = RecordLoop::kStep;
  /// kEventLoop only: SIGINT and SIGTERM end the recording early but cleanly (everything
  /// acquired so far written, counters stored, log closed; RecordSummary::interrupted). The
  /// handlers are installed before the log is created and removed after it is closed.
  bool stop_on_signals = false;
  /// Cameras recorded into the same log on the same clock. A camera that fails or stalls
  /// while recording is reported in the log's events and the summary; the IMU goes on.
  std::vector<RecordCamera> cameras;
  /// A camera silent for longer than this is reported (once per silence).
  TimeNs camera_stall_timeout_ns = 2 * kNsPerSecond;
};

/// What one camera of a recording did.
struct CameraRecordSummary {
  std::string name;
  CameraAcquisitionStats stats;
};

struct RecordSummary {
  std::uint64_t samples = 0;
  double duration_s = 0.0;        // first to last sample time
  double rate_hz = 0.0;           // measured
  double period_error_ppm = 0.0;  // the chip's rate against nominal, as estimated
  TimestamperStats timing;
  ImuStreamStats stream;
  AcquisitionStats acquisition;
  bool interrupted = false;  // ended early by a signal (RecordOptions::stop_on_signals)
  int signal = 0;            // which one
  std::vector<CameraRecordSummary> cameras;
};

/// Records `options.duration_s` of samples through `acquisition` (imucal's own driver or the
/// kernel's, imu_source.hpp) into a new session log, in the loop `options.loop` names. Driver
/// counters and the timing/stream counters are stored in the log's metadata.
[[nodiscard]] Result<RecordSummary> record_imu_session(ImuSource& acquisition, const RecordOptions& options);

/// Session-log metadata written by record_imu_session(), for other writers of IMU sessions:
/// "imu.timing" (timestamper counters), "imu.driver" (settings and failure counters per
/// cause), "imu.mounting".
std::string timing_metadata_json(const RecordSummary& summary, const TimestamperOptions& options);
std::string driver_metadata_json(const drivers::mpu6000::Mpu6000& driver);
std::string mounting_metadata_json(const MountingMap& mounting);
/// "camera.<name>" metadata: the stream's and the device's counters.
std::string camera_metadata_json(const CameraAcquisitionStats& stats);

}  // namespace imucal::acq
