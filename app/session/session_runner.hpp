// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The host of a session engine for the service and for replay: it records the session into its
// own folder (<state_dir>/sessions/<rig>-<UTC time>/: session.imulog with every sample, frame and
// message, the result files and report.html), runs the solves on a worker thread and hands
// results back on the engine's thread, and writes the accepted record through the storage
// function it is given. Devices stay with the caller: it feeds samples and frames in.
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "app/session/session_engine.hpp"
#include "app/session/view_coverage.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::log {
class SessionLogWriter;
}
namespace imucal::calib {
class TargetDetector;
}
namespace imucal::acq {
class CameraStream;
}

namespace imucal::acq {
struct PublishedFrame;
}

namespace imucal::app::session {

struct RunnerOptions {
  /// Session folders are made under <state_dir>/sessions/.
  std::string state_dir = "/var/lib/imucal";
  /// Runs a function on the engine's thread later (the service: boost::asio::post). Empty:
  /// solves and writes run inline, on the caller's thread (replay, tests).
  std::function<void(std::function<void()>)> post;
  /// Every message the engine emits, for observers (the control socket).
  std::function<void(const SessionMessage&)> broadcast;
  /// Probes the devices and reads the stored calibration (preflight step).
  std::function<PreflightReport()> preflight;
  /// Reopens the devices after a fault.
  std::function<Status()> recover;
  /// Completes the record the final solve built before it is reviewed (the service keeps the
  /// cameras of the stored record when the session calibrated none). Runs on the worker thread.
  std::function<Status(CalibrationRecord& record)> complete_record;
  /// Writes the record to the rig's storage, syncs and reads it back; returns where it went
  /// ("slot B, sequence 4, file /var/lib/imucal/calibration.bin"), which the end of the session
  /// names. Runs on the worker thread.
  std::function<Result<std::string>(const CalibrationRecord& record)> write_storage;
  /// Problems that concern the service's operator log, not the session (a report not drawn,
  /// a session log event that could not be stored). Default: stderr.
  std::function<void(const std::string&)> warn;
  /// Log metadata added to every session log (rig_config, source, device settings).
  std::vector<std::pair<std::string, std::string>> metadata;
  /// Write the HTML report of the final solve into the session folder.
  bool report = true;
  /// Replay: no log is written (the session folder still receives the results).
  bool write_log = true;
  /// Replay: the session folder to use instead of a new one.
  std::string session_dir;
  /// A camera frame waits for a free place in its stream's pool instead of being dropped when
  /// the encoder falls behind: for the virtual rig, whose frames come as fast as it computes
  /// (acq::CameraStreamOptions::block_when_full).
  bool frames_wait_for_encoder = false;
  /// The live view (docs/service.md, "Live view"): while `view_watched` says someone watches,
  /// each camera's recorded frames, shrunk to at most `view_width` columns with the target's
  /// corners and the camera's coverage, at most `view_rate_hz` a camera (wall clock). Called on
  /// on_frame()'s thread. Empty: no view is made.
  std::function<void(ViewFrame&&)> view_frame;
  std::function<bool()> view_watched;
  double view_rate_hz = 4.0;
  int view_width = 320;
};

/// The motion step's own log in a session folder: the IMU and the cameras from the step's start
/// to its end, what the camera-IMU calibration reads (`imucal calibrate camimu` reads it too).
inline constexpr const char* kMotionLogFile = "motion.imulog";

/// Runs a solve job and writes the final one's result files into `dir`: the static calibration
/// and, with job.camimu, the camera intrinsics (camera.yaml) and the camera-IMU calibration
/// (camimu/) of the motion log with the static result as the IMU's prior. Shared by the
/// service and replay.
/// `motion_log`: where the motion log is (empty: `dir`/motion.imulog); replay reads the live
/// session's and leaves it as it is (store_detections false).
struct MotionLogSource {
  std::string path;
  bool store_detections = true;
};
SolveOutcome run_solve(const SolveJob& job, const RigConfig& config, const ImuStreamInfo& info,
                       const std::string& dir,
                       const std::function<void(double, const std::string&)>& progress,
                       const MotionLogSource& motion_log = {});

class SessionRunner final : public EngineHost {
 public:
  SessionRunner(const RigConfig& config, const ImuStreamInfo& info, RunnerOptions options);
  ~SessionRunner() override;
  SessionRunner(const SessionRunner&) = delete;
  SessionRunner& operator=(const SessionRunner&) = delete;

  SessionEngine& engine() { return engine_; }
  /// Creates the session folder and log, then starts the engine. Fails when a session runs or
  /// the folder or log cannot be created (nothing started then).
  [[nodiscard]] Status start(const std::vector<std::string>& steps);
  /// Samples in time order: stored while the session records, then given to the engine.
  void on_samples(std::span<const ImuSample> samples);
  /// True while the motion step runs: the host streams its cameras then and hands the frames to
  /// on_frame().
  bool wants_frames() const;
  /// A frame of the configured camera `camera` (index into cameras[]) as the device delivered it,
  /// its stamp marking `meaning`. It goes through acquisition's camera stream
  /// (acquisition/camera_stream.hpp: the luma of its pixel format, the stamp moved to
  /// mid-exposure, a slot of a fixed pool, encoded and appended to the motion log on the stream's
  /// own thread), is searched for the target here, and is counted by the engine (target seen or
  /// not). The device buffer is released before this returns. A frame outside the motion step, or
  /// one the stream dropped (counted, and reported when the step's log closes), is not counted.
  void on_frame(std::size_t camera, drivers::camera::Frame& frame, drivers::camera::TimestampMeaning meaning);
  /// An IMU or camera fault (`source` "imu", "cam0", "storage"): stored and given to the engine.
  void fault(const std::string& source, const std::string& text);
  /// A warning that changes nothing in the session (SessionEngine::note).
  void note(const std::string& text) { engine_.note(text); }
  const std::string& session_dir() const { return dir_; }
  std::string log_path() const { return dir_.empty() ? std::string() : dir_ + "/session.imulog"; }
  /// Waits until the worker has run every job queued so far (tests, shutdown). Their results
  /// are posted to the engine's thread as usual.
  void drain();
  /// True while the worker has a solve or a write queued or running.
  bool busy();

  // EngineHost
  void emit(const SessionMessage& message) override;
  PreflightReport preflight() override;
  void solve(const SolveJob& job) override;
  void write(const CalibrationRecord& record) override;
  Status recover() override;
  void recording_finished() override;

 private:
  void run_on_worker(std::function<void()> work);
  void worker_loop();
  void close_log();
  Status open_motion_log();
  /// The camera's stream in the motion log, made at its first frame (its format and the meaning
  /// of its stamps are the device's).
  Result<acq::CameraStream*> camera_stream(std::size_t camera, const drivers::camera::Frame& frame,
                                           drivers::camera::TimestampMeaning meaning);
  void close_motion_log();
  /// The live view's frame of a recorded frame, when it is watched and its camera's turn has come.
  void send_view(std::size_t camera, const acq::PublishedFrame& f, const std::vector<Eigen::Vector2d>& px,
                 const std::vector<int>& ids);
  void sync_motion_log();
  void motion_log_error(const Error& error);
  void warn(const std::string& text) const;

  RigConfig config_;
  ImuStreamInfo info_;
  RunnerOptions options_;
  SessionEngine engine_;
  std::string dir_;
  std::unique_ptr<log::SessionLogWriter> log_;
  int stream_id_ = -1;
  bool recording_ = false;
  // The motion step's log and the live target detection.
  std::unique_ptr<log::SessionLogWriter> motion_log_;
  // The motion log shared by this thread (samples) and the cameras' encoder threads (frames).
  std::unique_ptr<log::SessionLogWriter> motion_shared_;
  int motion_imu_id_ = -1;
  std::vector<int> motion_camera_ids_;  // -1 until the camera's first frame declares its stream
  std::vector<std::unique_ptr<acq::CameraStream>> camera_streams_;
  // Each camera's live detections, stored in the motion log when it closes so that the final
  // solve's intrinsics reuse them instead of searching every frame again.
  struct LiveDetections {
    std::int64_t frames = 0;
    std::vector<std::pair<TimeNs, std::string>> found;  // (frame time, encoded observation)
  };
  std::vector<LiveDetections> live_;
  // Each camera's coverage (made at its first frame) and when it last gave the live view a frame.
  std::vector<ViewCoverage> coverage_;
  std::vector<std::chrono::steady_clock::time_point> view_sent_;
  std::unique_ptr<calib::TargetDetector> detector_;
  TimeNs motion_step_start_ns_ = -1;  // the motion step the log was opened for
  // One worker runs solves and writes in order.
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> jobs_;
  bool running_job_ = false;
  bool stop_ = false;
  std::thread worker_;
};

}  // namespace imucal::app::session
