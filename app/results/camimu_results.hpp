// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The outputs of the camera-IMU calibration, with no solver dependency, for the CLI, the service
// and reports: Kalibr's camchain-imucam.yaml and imu.yaml, the canonical record
// calibration.yaml (the static result's `canonical:` schema) and result.json with every
// parameter, its sigma and the quality figures; result.json read back. Schemas and conversions:
// docs/camimu-calibration.md, "Outputs".

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

#include "app/camimu_calibration.hpp"
#include "core/calibration_record.hpp"
#include "core/camimu_calibration.hpp"
#include "core/imu_model.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// The file names the command writes into its output folder.
inline constexpr const char* kCamchainImucamFile = "camchain-imucam.yaml";
inline constexpr const char* kCamImuImuFile = "imu.yaml";  // the --imu form (flat), for the next run
inline constexpr const char* kCamImuImuResultFile = "imu-imucam.yaml";  // Kalibr's result form (imu0:)
inline constexpr const char* kCamImuCalibrationFile = "calibration.yaml";
inline constexpr const char* kCamImuJsonFile = "result.json";

/// Kalibr's scale-misalignment IMU (kalibr_calibrate_imu_camera --imu-models scale-misalignment):
///   a_raw = M_accel a + b_a
///   w_raw = M_gyro C_gyro_i w + A C_gyro_i a + b_g
/// with M lower triangular. From the Krebs form: M_accel = S_a M_a, M_gyro = S_g M_g,
/// C_gyro_i = C_bg^T, A = B_g (same body frame, same g-sensitivity frame).
struct KalibrImuIntrinsics {
  Eigen::Matrix3d M_accel = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d M_gyro = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d C_gyro_i = Eigen::Matrix3d::Identity();
};
KalibrImuIntrinsics kalibr_from_krebs(const KrebsImuModel& model);

/// The intrinsics camera `i` of the result was solved with, as the stored record and
/// calibration.yaml keep them: the model without its shutter (the line delay is kept beside) and
/// the camera file's sigmas (NaN where it gave none).
CameraIntrinsicsRecord held_intrinsics(const CamImuReport& report, std::size_t i);

/// imu.yaml: the IMU file as Kalibr's --imu reads it (flat: the four noise figures the problem
/// used, rostopic, update_rate), which `calibrate camimu --imu` reads too.
std::string camimu_imu_input_yaml(const CamImuReport& report);

/// camchain-imucam.yaml: per camN Kalibr's keys (camera_model, intrinsics, distortion_model,
/// distortion_coeffs, resolution, rostopic, T_cam_imu as 4 rows, timeshift_cam_imu, T_cn_cnm1
/// from cam1 on) and imucal's sigmas and figures under `camN: imucal:`.
std::string camimu_camchain_yaml(const CamImuReport& report);
/// imu.yaml: Kalibr's IMU result (`imu0:` with the noise figures used, rostopic, update_rate,
/// model, T_i_b, time_offset and, for the extended model, accelerometers.M, gyroscopes.M, A,
/// C_gyro_i), imucal's biases and sigmas under `imu0: imucal:`.
std::string camimu_imu_yaml(const CamImuReport& report);
/// calibration.yaml: the canonical record for the stream's input values (`canonical:` A_a, b_a,
/// A_g, b_g, G and `input_units`, the schema of the static result, so read_imucal_calibration,
/// read_gsens_matrix and `calibrate check` read it), the same on nominal SI, the Krebs form with
/// its sigmas, gravity, the cameras' extrinsics and time offsets.
std::string camimu_calibration_yaml(const CamImuReport& report);
/// result.json (indented, ending in a newline): every parameter with its sigma, quality,
/// warnings, fixed blocks, cameras, biases over time, cross-correlation, inputs, versions.
std::string camimu_result_json(const CamImuReport& report);

/// The result record of a result.json written by camimu_result_json. Errors: kNotFound,
/// kCorrupt (not JSON, a key missing or of the wrong type), naming the file.
[[nodiscard]] Result<CamImuCalibrationResult> read_camimu_result(const std::string& path);

/// What a stored record takes of a calibration.yaml written by camimu_calibration_yaml, typed: the
/// IMU stream (name, units), the IMU's Krebs sigmas, each camera (stream, T_cam_imu and its sigmas,
/// time offset, shutter and line delay, intrinsics and their sigmas), gravity, the thermal model
/// and the fixed blocks in `report`, and the canonical model on the stream's input values as the
/// file gives it. The report's other fields keep their defaults.
struct CamImuCalibrationFile {
  CamImuReport report;
  CanonicalImuModel canonical_input;
};
/// `root`: the file as JSON (yaml_to_json). Errors: kCorrupt naming `origin` and the key.
[[nodiscard]] Result<CamImuCalibrationFile> parse_camimu_calibration(const nlohmann::json& root,
                                                                     const std::string& origin);

}  // namespace imucal::app
