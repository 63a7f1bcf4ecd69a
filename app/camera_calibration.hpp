// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Camera intrinsic calibration of a camera stream in a session log: the target is searched in
// every frame on all cores (or the detections stored in the log by an earlier run are reused),
// then calib::calibrate_camera_intrinsics. Method and outputs: docs/camera-calibration.md.
//
// calibrate_camera_log needs OpenCV, libapriltag and Ceres: it is compiled into the camera module
// libimucal_camera.so (app/camera_module.hpp); programs call it through app::calibrate_camera
// (app/solvers.hpp), which loads the module. The result writers are in app/results/camera_results.hpp.
// detect_target_in_stream is the target search alone, shared with the camera-IMU calibration
// (app/camimu_calibration.hpp).

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "calib/camera_chain.hpp"
#include "calib/camera_intrinsics.hpp"
#include "calib/camera_model_choice.hpp"
#include "calib/target_detection.hpp"
#include "core/frame.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/split_check.hpp"
#include "core/target.hpp"
#include "log/session_log.hpp"

namespace imucal::app {

/// What the target search over one camera stream of a log depends on.
struct StreamDetectionRequest {
  std::string log_path;  // the log `reader` reads
  TargetDescription target;
  calib::DetectionOptions detection;
  int threads = 0;  // detection workers; 0 = all cores
  /// Use detections stored for the same frames, target and detector (in the log, else in the
  /// cache), instead of searching the frames again.
  bool reuse_detections = true;
  /// Store new detections in the log itself (the service, in the logs it writes). The log is
  /// otherwise never written.
  bool store_detections = false;
  /// Else store them in a cache file in this folder, named after the stream's content
  /// (log::SessionLogReader::frame_fingerprint); empty = no cache.
  std::string cache_dir;
  /// Use the readable frames of a stream with damaged frames (else that is an error).
  bool allow_damaged = false;
  ProgressFn progress;
};

/// The target found in one camera stream: observations in time order (the frames searched, with
/// empty observations where the target was not found; reused sets hold the frames with the target).
struct StreamDetections {
  std::int64_t frames = 0;  // frames read (or searched by the run whose detections were reused)
  int frames_with_target = 0;
  int frames_failed = 0;    // frames that could not be decoded or searched
  std::string key;          // detection_key of the target and options
  std::string reused_from;  // "the log" or the cache file, when the detections were reused
  std::string stored_in;    // "the log" or the cache file, when new detections were stored
  double wall_s = 0.0;      // 0 when reused
  int threads = 0;
  std::vector<calib::TargetObservation> observations;
  std::vector<std::string> warnings;
};

/// Searches every frame of camera stream `stream_id` on worker threads, or reuses the detections
/// the log holds for the same key; stores new ones when the log is complete and undamaged.
/// Errors: kInsufficientData (the stream holds no frames), the detector's and the log's.
[[nodiscard]] Result<StreamDetections> detect_target_in_stream(const log::SessionLogReader& reader,
                                                               int stream_id,
                                                               const StreamDetectionRequest& request);

struct CameraCalibrationRequest {
  std::string log_path;
  /// What the results and messages call the log: the file the user gave when log_path is its
  /// import (a ROS bag's, in the cache); empty: log_path.
  std::string log_name;
  const std::string& shown_log() const { return log_name.empty() ? log_path : log_name; }
  std::string camera;  // camera stream name; empty = the first
  TargetDescription target;
  std::string target_source;  // for the outputs: the file, or where in the log it came from
  calib::DetectionOptions detection;
  calib::CameraIntrinsicsOptions intrinsics;
  /// The model chosen by the evidence among these (calib/camera_model_choice.hpp; empty: the
  /// model of `intrinsics`). For a chain, each camera's own.
  std::vector<CameraModelKind> model_candidates;
  /// The shutter (docs/camera-calibration.md, "Rolling shutter"): kGlobal solves each view with
  /// its own pose, as always; otherwise the views are also solved on a trajectory with the line
  /// delay freed (kAuto keeps rolling only by the evidence) or held (line_delay_s). `known` is
  /// the camera's readout direction and stamped row (and a line delay to start from).
  calib::ShutterSolveOptions shutter{calib::ShutterSolveOptions::Mode::kGlobal, std::nullopt};
  Shutter known_shutter;
  /// known_shutter's stamp_row was named (--stamp-row, the rig configuration's rolling camera);
  /// else the row comes from the log's camera stream (app/camimu_inputs.hpp stamp_row_from_stream).
  bool known_stamp_row = false;
  int threads = 0;  // detection workers; 0 = all cores
  /// One camera: the solve (and its self-check) takes at most this many of the views with the
  /// target, spread evenly over the recording (spread_views); 0: every view. Consecutive views
  /// of a video repeat each other (docs/camera-calibration.md, "Views").
  int max_views = kDefaultMaxViews;
  static constexpr int kDefaultMaxViews = 400;
  /// The self-check (app/camera_self_check.hpp): this many consecutive parts of the recording
  /// calibrated apart and compared; 0 or 1: none (the CLI asks for the halves).
  int self_check_parts = 0;
  /// Calibrate from the readable part of a damaged log (else a damaged log is refused).
  bool allow_damaged = false;
  /// As StreamDetectionRequest: reuse stored detections; store new ones in the log (else in
  /// the cache folder, when given).
  bool reuse_detections = true;
  bool store_detections = false;
  std::string cache_dir;
  ProgressFn detection_progress;
  ProgressFn solve_progress;
};

/// At most `max_views` of the views with the target (the empty ones left out), spread evenly: the
/// first of each of max_views equal runs of consecutive views (all of them when there are no
/// more, or max_views is 0).
std::vector<calib::TargetObservation> spread_views(const std::vector<calib::TargetObservation>& views,
                                                   int max_views);

struct CameraCalibrationReport {
  std::string log_path;
  int stream_id = 0;
  CameraStreamInfo stream;
  TargetDescription target;
  std::string target_source;
  std::string software_version;  // of the imucal that wrote the log
  std::int64_t frames = 0;       // frames read (or searched by the run whose detections were reused)
  int frames_with_target = 0;
  int frames_failed = 0;  // frames that could not be decoded or searched
  std::string detection_key;
  std::string detections_reused_from;  // StreamDetections::reused_from
  std::string detections_stored_in;    // StreamDetections::stored_in
  double detection_wall_s = 0.0;       // 0 when reused
  int detection_threads = 0;
  /// Views with the target that the solve did not take (CameraCalibrationRequest::max_views).
  int views_not_chosen = 0;
  calib::CameraIntrinsicsResult intrinsics;
  /// The model chosen by the evidence (`--model auto`: CameraCalibrationRequest::choose_model).
  std::optional<calib::CameraModelChoice> model_choice;
  /// The line delay's sigma (s per row; NaN: global, held or not determined) and why this
  /// shutter (empty: global, nothing asked).
  double line_delay_sigma_s = std::numeric_limits<double>::quiet_NaN();
  std::string shutter_choice;
  /// The parts of the recording calibrated apart (kNotRun unless asked for).
  SplitCheck self_check;
  std::vector<std::string> warnings;  // of the detection, the log and the solve
};

/// Several camera streams of one log calibrated together (calib/camera_chain.hpp).
struct CameraChainRequest {
  /// The log, target, detection, threads, cache and damage policy as for one camera; its
  /// `camera` is not used, and `intrinsics` holds the rejection rules of every camera.
  CameraCalibrationRequest base;
  std::vector<std::string> cameras;     // stream names, cam0 first; at least two
  std::vector<CameraModelKind> models;  // one per camera
  /// Each camera's shutter as known (empty: base.known_shutter for every camera).
  std::vector<Shutter> shutters;
  /// Its `intrinsics` are set from base, and its `threads` too unless given (> 0).
  calib::CameraChainOptions chain;
};

struct CameraChainReport {
  /// Per camera: the stream, its detection figures, and its intrinsics from the joint solve.
  std::vector<CameraCalibrationReport> cameras;
  calib::CameraChainResult chain;
  SplitCheck self_check;              // of the chain (kNotRun unless asked for)
  std::vector<std::string> warnings;  // of the detections, the log and the joint solve
};

/// The detection over every named stream (or the stored detections), then the joint solve.
/// Errors as calibrate_camera_log's, and the chain's (a camera that shares no view).
[[nodiscard]] Result<CameraChainReport> calibrate_camera_chain_log(const CameraChainRequest& request);

/// Runs the detection (or reuses stored detections) and the intrinsics solve. Errors: the log's
/// (kNotFound, kCorrupt: a damaged log without allow_damaged), kInsufficientData (too few views
/// with the target), the solver's.
[[nodiscard]] Result<CameraCalibrationReport> calibrate_camera_log(const CameraCalibrationRequest& request);

}  // namespace imucal::app
