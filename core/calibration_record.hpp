// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The calibration as the rig stores it (docs/storage.md): one typed record, and its JSON form in
// one place (calibration_record.cpp). The storage holds that JSON encoded as CBOR; `store read`
// prints it as YAML or JSON. The record is built from the solves' typed results
// (app/stored_calibration.hpp); adding a field touches this type, its two functions below and
// their test (tests/core/test_calibration_record.cpp).
//
// JSON form (version 3 when a camera carries its intrinsics, else 2 when it holds "thermal", else
// version 1, which every version reads):
//   {"format": "imucal.calibration", "version": 1, "created_utc", "software_version", "rig",
//    "imu": {"stream", "input_units", "form", "A_a", "b_a", "A_g", "b_g", "G",   (canonical form)
//            "source": "static"|"camimu",
//            "sigma": {"model", static: "accel"/"gyro" {"misalignment", "scale", "bias"}, "G";
//                      camimu: "S_a", "M_a", "b_a", "S_g", "M_g", "C_bg_rad", "B_g", "b_g"}},
//    "cameras": [{"name", "stream", "T_cam_imu" (4 rows), "rotation_sigma_rad",
//                 "translation_sigma_m", "timeshift_cam_imu_s", "timeshift_sigma_s",
//                 rolling shutter only: "line_delay_s", "line_delay_sigma_s",
//                 version 3: "camera": {"camera_model", "intrinsics", "distortion_model",
//                   "distortion_coeffs", "resolution" (Kalibr's keys and orders),
//                   "intrinsics_sigma", "distortion_coeffs_sigma" (null where not known)}}],
//    "gravity_mps2", "source": {"files": [{"path", "kind", "method", "fixed"}], "notes": [...]},
//    "thermal" (optional): {"form", "reference_c", "valid_range_c": [min, max], "scale",
//                           "gyro"/"accel": 3 x {"order", "coeffs" (c_1..c_order), "sigma"} or
//                           {"order": null, "reason"}}}   (core/thermal_model.hpp, input units)
// A figure that was not determined (NaN) is null.

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/camera_model.hpp"
#include "core/camimu_calibration.hpp"
#include "core/imu_calibration.hpp"
#include "core/imu_model.hpp"
#include "core/result.hpp"
#include "core/thermal_model.hpp"

namespace imucal {

inline constexpr const char* kCalibrationFormat = "imucal.calibration";
inline constexpr int kCalibrationRecordVersion = 3;
/// The oldest version still read (1: no thermal model).
inline constexpr int kOldestCalibrationRecordVersion = 1;
/// The methods' names, as the record's sources and the result files state them.
inline constexpr const char* kStaticMethod = "static multi-position (Tedaldi 2013)";
inline constexpr const char* kCamImuMethod = "continuous-time camera-IMU (Krebs 2012)";
/// The canonical form's equations, as the record states them.
inline constexpr const char* kCanonicalForm = "a = A_a (a_raw - b_a); w = A_g (w_raw - b_g) - G a";
/// Tedaldi's convention (the static method's triads), and Krebs' form (the camera-IMU solve's).
inline constexpr const char* kTedaldiConvention = "corrected = misalignment * diag(scale) * (raw - bias)";
inline constexpr const char* kKrebsForm =
    "a_raw = S_a M_a a + b_a; w_raw = S_g M_g C_bg^T w + B_g C_bg^T a + b_g";

/// The sigmas of the method that estimated the IMU, in that method's own parameters.
struct ImuSigmaRecord {
  /// "tedaldi: ..." or "krebs: ...": which parameters these are; empty: no sigmas stored.
  std::string model;
  /// The static method's (Tedaldi's form, per triad), and of G with the g-sensitivity.
  std::optional<TriadSigma> accel, gyro;
  std::optional<Eigen::Matrix3d> G;
  /// The camera-IMU method's (Krebs's form).
  std::optional<KrebsImuSigma> krebs;
};

struct ImuRecord {
  std::string stream;       // the IMU stream calibrated
  std::string input_units;  // "raw" or "si": what the model corrects
  std::string form = kCanonicalForm;
  CanonicalImuModel model;
  std::string source;  // "static" or "camimu": the method the IMU comes from
  ImuSigmaRecord sigma;
};

/// A camera's intrinsics as the record keeps them: the model (its shutter is the record's
/// line_delay_s), and the standard deviation of each figure in Kalibr's order (NaN: not
/// determined; all NaN when the calibration that gave the intrinsics stated none).
struct CameraIntrinsicsRecord {
  CameraModel camera;
  std::vector<double> intrinsics_sigma;         // as kalibr_intrinsics
  std::vector<double> distortion_coeffs_sigma;  // as kalibr_distortion
};

struct CameraRecord {
  std::string name;    // cam0, ...
  std::string stream;  // the camera stream of the log
  Eigen::Matrix4d T_cam_imu = Eigen::Matrix4d::Identity();
  Eigen::Vector3d rotation_sigma_rad = Eigen::Vector3d::Constant(kNotDetermined);
  Eigen::Vector3d translation_sigma_m = Eigen::Vector3d::Constant(kNotDetermined);
  double timeshift_cam_imu_s = 0.0;
  double timeshift_sigma_s = kNotDetermined;
  /// A rolling shutter's line delay (s per row) as the camera-IMU solve used it, and its sigma
  /// (not determined when held); absent for a global shutter.
  std::optional<double> line_delay_s;
  double line_delay_sigma_s = kNotDetermined;
  /// The intrinsics the extrinsics were found with (version 3 on; absent in older records).
  std::optional<CameraIntrinsicsRecord> intrinsics;
};

/// A result the record was built from.
struct RecordSourceFile {
  std::string path;
  std::string kind;    // "static" or "camimu"
  std::string method;  // the method's name
  /// camimu: the blocks the solve held fixed (empty for a static result).
  std::optional<std::vector<std::string>> fixed;
};

struct CalibrationRecord {
  std::string created_utc;
  std::string software_version;
  std::string rig;  // the rig's name, set from the configuration when written
  ImuRecord imu;
  std::vector<CameraRecord> cameras;
  std::optional<double> gravity_mps2;
  std::vector<RecordSourceFile> files;
  std::vector<std::string> notes;
  /// The bias against die temperature the IMU model was fitted with (its biases are those at the
  /// model's reference temperature), in the IMU's input units; empty: none.
  std::optional<ThermalModel> thermal;
};

/// The record's JSON form (above).
nlohmann::json calibration_record_json(const CalibrationRecord& record);

/// A record from its JSON form (this version or an older one). kCorrupt, with the key, for
/// another format, a newer version, a missing
/// or malformed key, a matrix of the wrong size or a model figure that is not finite.
[[nodiscard]] Result<CalibrationRecord> calibration_record_from_json(const nlohmann::json& json);

/// The "thermal" block alone (the record's form above), as the result files embed it.
nlohmann::json thermal_model_json(const ThermalModel& model);
[[nodiscard]] Result<ThermalModel> thermal_model_from_json(const nlohmann::json& json);

/// True when both hold the same calibration: their IMU and cameras (the creation time, software
/// version, rig name and sources may differ). Undetermined figures compare equal.
bool same_calibration(const CalibrationRecord& a, const CalibrationRecord& b);

}  // namespace imucal
