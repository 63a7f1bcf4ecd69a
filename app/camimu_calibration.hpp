// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Camera-IMU calibration of a session log: the IMU stream converted to nominal SI, the cameras of
// camchain YAMLs matched to the log's camera streams, the target found in their frames (or the
// detections stored by an earlier run reused, as `calibrate camera` does), then
// calib::calibrate_camimu. Inputs and outputs: docs/camimu-calibration.md.
//
// calibrate_camimu_log needs OpenCV, libapriltag and Ceres: it is compiled into the camera module
// libimucal_camera.so (app/camera_module.hpp); programs call it through app::calibrate_camimu
// (app/solvers.hpp). The inputs that need no solver are in app/camimu_inputs.hpp, the result
// writers in app/results/camimu_results.hpp.

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "app/calibration_check.hpp"
#include "app/camimu_inputs.hpp"
#include "app/results/thermal_results.hpp"
#include "calib/camimu_calibration.hpp"
#include "calib/target_detection.hpp"
#include "core/camimu_calibration.hpp"
#include "core/frame.hpp"
#include "core/imu.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/target.hpp"
#include "core/thermal_model.hpp"

namespace imucal::app {

struct CamImuRequest {
  std::string log_path;
  /// What the results and messages call the log: the file the user gave when log_path is its
  /// import (a ROS bag's, in the cache); empty: log_path.
  std::string log_name;
  const std::string& shown_log() const { return log_name.empty() ? log_path : log_name; }
  std::string imu_stream;  // IMU stream name; empty = the first
  /// The cameras' intrinsics, cam0..camN in order (the CLI reads them from camchain YAMLs,
  /// read_camchain_files; the service takes its own intrinsics solve's).
  std::vector<CamchainCamera> cameras;
  TargetDescription target;
  std::string target_source;  // for the outputs: the file, or where in the log it came from
  calib::DetectionOptions detection;
  /// The IMU noise (options.noise) and where it is from (the CLI reads a Kalibr imu.yaml,
  /// read_kalibr_imu_noise); empty: CamImuNoise's defaults, the MPU-6000 datasheet's.
  std::optional<calib::CamImuNoise> imu_noise;
  std::string imu_noise_source;
  /// The --imu file's rostopic (chooses the IMU stream when imu_stream is empty; for imu.yaml) and
  /// update_rate (for imu.yaml; 0: the stream's rate).
  std::string imu_rostopic;
  double imu_update_rate = 0.0;
  /// A prior static calibration (--imu-intrinsics) and a g-sensitivity (--gsens): initial values
  /// and fixed blocks (app::imu_prior).
  std::optional<NamedCalibration> imu_intrinsics;
  std::optional<GsensInput> gsens;
  /// A thermal model (calibrate thermal -o, or the session's fit): the IMU samples are corrected
  /// to its reference temperature before the solve.
  std::optional<ThermalFile> thermal;
  /// Model, spline, noise weights, fixed blocks (merged with those the priors fix), threads.
  calib::CamImuOptions options;
  std::string gravity_source;
  int threads = 0;  // detection workers; 0 = all cores
  /// The self-check (app/camimu_self_check.hpp): this many consecutive parts calibrated apart
  /// and compared; 0 or 1: none.
  int self_check_parts = 2;
  bool allow_damaged = false;
  bool reuse_detections = true;
  bool store_detections = false;  // in the log; else in cache_dir when given (StreamDetectionRequest)
  std::string cache_dir;
  /// Detection progress per camera (index into cameras), then the solver's.
  std::function<void(int camera, double fraction)> detection_progress;
  calib::CamImuProgressFn solve_progress;
};

/// One camera as it entered the problem.
struct CamImuCameraReport {
  std::string name;                              // cam0, ...
  std::string source;                            // the camchain YAML and its key
  std::string rostopic;                          // as given, else /STREAM/image_raw
  std::optional<std::vector<int>> cam_overlaps;  // as given (CamchainCamera::cam_overlaps)
  CameraStreamInfo stream;                       // the log's stream
  int stream_id = 0;
  std::int64_t frames = 0;
  int frames_with_target = 0;
  std::string detection_key;
  std::string detections_reused_from;  // StreamDetections::reused_from
  std::string detections_stored_in;    // StreamDetections::stored_in
  double detection_wall_s = 0.0;
  /// The held intrinsics' standard deviations, from the camera file's covariance, in Kalibr's
  /// order (kalibr_intrinsics, kalibr_distortion); NaN where the file gives none.
  std::vector<double> intrinsics_sigma, distortion_coeffs_sigma;
};

struct CamImuReport {
  std::string log_path;
  std::string log_software_version;  // of the imucal that wrote the log
  ImuStreamInfo imu_stream;
  std::size_t imu_samples = 0;
  std::string imu_rostopic = "/imu0";
  double imu_update_rate = 0.0;  // Hz, as given (the --imu file's), else the stream's
  TargetDescription target;
  std::string target_source;
  std::string noise_source;  // the imu.yaml, or "defaults (MPU-6000 datasheet)"
  std::string imu_intrinsics_source;
  std::string gsens_source;
  std::string gravity_source;
  /// The thermal model the IMU samples were corrected with, on the stream's input units.
  std::optional<ThermalModel> thermal;
  std::string thermal_source;
  calib::CamImuOptions options;  // as solved (noise, fixed blocks, initial model)
  std::vector<CamImuCameraReport> cameras;
  CamImuCalibrationResult result;
  std::vector<std::string> notes;     // what was assumed (defaults, frames of the priors)
  std::vector<std::string> warnings;  // of the log, the detection and the estimator
};

/// Runs the whole calibration. Errors: the inputs' (kNotFound, kCorrupt), the log's (kCorrupt
/// for a damaged log without allow_damaged), kInsufficientData (no frames, no target), the
/// estimator's (kInvalidArgument, kInsufficientData, kSolverFailed).
[[nodiscard]] Result<CamImuReport> calibrate_camimu_log(const CamImuRequest& request);

}  // namespace imucal::app
