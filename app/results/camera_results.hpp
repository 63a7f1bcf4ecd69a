// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera calibration's pieces that need no solver, no OpenCV and no detector, so the
// program can use them before (or without) loading the camera module: where the target comes
// from, the key and text form of stored detections, and the result schemas (Kalibr camchain YAML
// with imucal's keys, JSON). Schemas: docs/camera-calibration.md.

#include <map>
#include <string>

#include "app/camera_calibration.hpp"
#include "calib/target_detection.hpp"
#include "core/result.hpp"
#include "core/target.hpp"

namespace imucal::app {

struct TargetChoice {
  TargetDescription target;
  std::string source;  // "rig_config metadata" or "target metadata"
};

/// The calibration target a log names: the `target` of its `rig_config` metadata (written by
/// recordings), else its `target` metadata key (Kalibr YAML, written by the simulator).
/// Errc::kNotFound when it names none (the caller asks for --target); kCorrupt when the one it
/// names is malformed.
[[nodiscard]] Result<TargetChoice> target_from_log_metadata(
    const std::map<std::string, std::string>& metadata);

/// Fingerprint of what a detection depends on: the target description, the detection options,
/// and the detector (imucal's version and the stored format). Two runs with equal keys find the
/// same corners, so stored detections with this key may be reused.
std::string detection_key(const TargetDescription& target, const calib::DetectionOptions& options);

/// A detection as stored in the log (compact JSON: width, height, ids, px as u0 v0 u1 v1 ...)
/// and back; the pixels round-trip exactly.
std::string encode_detection(const calib::TargetObservation& observation);
[[nodiscard]] Result<calib::TargetObservation> decode_detection(const std::string& text, TimeNs t_ns);

/// Kalibr camchain YAML (`cam0:` with camera_model, intrinsics, distortion_model,
/// distortion_coeffs, resolution, rostopic) plus imucal's keys under `cam0: imucal:`.
std::string camera_result_yaml(const CameraCalibrationReport& report);
/// Several cameras: every camera as camera_result_yaml's cam0 (cam0 ... camN), with Kalibr's
/// T_cn_cnm1 (camN >= 1) and cam_overlaps (the cameras it shares at least `min_shared_views`
/// views with), and the chain's figures under camN.imucal (time offset against cam0, the
/// sigmas of T_cn_cnm1 and of the baseline, shared views); null where not determined.
std::string camera_chain_yaml(const CameraChainReport& report, int min_shared_views);
/// The same as JSON with every camera's views and figures (as camera_result_json's).
std::string camera_chain_json(const CameraChainReport& report, int min_shared_views);

/// Everything of the YAML plus the views (with their reasons), the coverage grid, the
/// covariance and the timings, as JSON (indented, ending in a newline).
std::string camera_result_json(const CameraCalibrationReport& report);

}  // namespace imucal::app
