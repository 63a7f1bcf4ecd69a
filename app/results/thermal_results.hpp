// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The thermal calibration's result file (`calibrate thermal -o THERMAL.yaml`, docs/thermal.md):
// written here, read back by `calibrate static --thermal`, `calibrate camimu --thermal` and the
// report; and the correction of a stream's samples to the model's reference temperature.

#include <optional>
#include <string>
#include <vector>

#include "calib/thermal_calibration.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/thermal_model.hpp"

namespace imucal::app {

inline constexpr const char* kThermalFormat = "imucal.thermal";

/// The thermal model as YAML: the model per axis (c_0..c_p, sigmas, covariance, AIC, noise), the
/// range, the warnings and the bin means it was fitted to (for the report's figure).
std::string thermal_result_yaml(const calib::ThermalResult& result, const ImuStreamInfo& info,
                                const std::string& log_path);

/// A thermal result file read back.
struct ThermalFile {
  std::string path;
  std::string log;          // the recording it was fitted from
  std::string stream;       // its IMU stream
  std::string input_units;  // "raw" or "si" (the model itself is in SI)
  calib::ThermalResult result;
  ThermalModel model;  // SI: rad/s and m/s^2 per K^j
};

/// Reads a file thermal_result_yaml wrote. kCorrupt, naming the file and the key, for anything
/// else.
[[nodiscard]] Result<ThermalFile> read_thermal_file(const std::string& path);

/// The SI model on a stream's input units: for a raw stream every coefficient divided by the
/// nominal conversion's scale of its axis (counts per K^j); unchanged for an SI stream.
ThermalModel thermal_model_on_input_units(const ThermalModel& si_model, const ImuStreamInfo& info,
                                          const AxisConversion& accel, const AxisConversion& gyro);

/// What the correction did.
struct ThermalCorrection {
  std::size_t corrected = 0;
  std::size_t clamped = 0;                      // outside the model's range: corrected at its nearest end
  std::size_t without_temperature = 0;          // left as they are
  double min_c = 0.0, max_c = 0.0;              // the temperatures met
  double model_min_c = 0.0, model_max_c = 0.0;  // the model's valid range
  double mean_c = 0.0;  // mean of the temperatures the samples were corrected at (clamped)
  /// A warning for the result when some samples were clamped or had no temperature; empty if not.
  std::string warning() const;
};

/// Subtracts b(T) - b(T_ref) from every sample with a die temperature (the stream's temperature
/// scale and offset give deg C), `model` being on the stream's input units. The samples are the
/// caller's copy: a log is never changed. kInsufficientData when no sample has a temperature.
[[nodiscard]] Result<ThermalCorrection> correct_to_reference_temperature(std::vector<ImuSample>& samples,
                                                                         const ImuStreamInfo& info,
                                                                         const ThermalModel& model);

/// What the correction adds to the biases' uncertainty: the model's own 1-sigma of the change
/// f(T) - f(T_ref) at `temperature_c` (clamped to its range), per axis, as a warning for results
/// whose bias sigmas do not carry it ("... gyro x y z deg/s, accel x y z mg; add it in
/// quadrature"). Empty when the result is not determined.
std::string thermal_uncertainty_warning(const calib::ThermalResult& result, double temperature_c);

/// A thermal model applied to a stream's samples.
struct AppliedThermal {
  std::string path;    // where the model came from
  ThermalModel model;  // on the stream's input units: what the result and the record state
  ThermalCorrection correction;
  std::vector<std::string> warnings;
};

/// Corrects `samples` (the caller's copy of `info`'s stream) to the reference temperature of a
/// fitted model (SI, as calibrate_thermal gives it). A raw stream's model is converted with the
/// log's nominal conversion, as `calibrate thermal` converted it. The warnings (samples clamped or
/// without a temperature, the model's own uncertainty at their temperature) end with
/// " (source)". The session applies its own fit through this; apply_thermal_file a file's.
[[nodiscard]] Result<AppliedThermal> apply_thermal(const calib::ThermalResult& result,
                                                   std::vector<ImuSample>& samples, const ImuStreamInfo& info,
                                                   const std::string& source);

/// Corrects `samples` (the caller's copy of `info`'s stream) to the reference temperature of a
/// thermal file (read_thermal_file, or the session's own fit as one). A raw stream's model is
/// converted with the log's nominal conversion, as `calibrate thermal` converted it; a model of
/// another stream is applied with a warning. Errors name the file and say what to do.
[[nodiscard]] Result<AppliedThermal> apply_thermal_file(const ThermalFile& file,
                                                        std::vector<ImuSample>& samples,
                                                        const ImuStreamInfo& info);

/// One point of scale against temperature: the static calibration (calibrate_static with the
/// log's nominal conversion as the initial guess) of a recording of static poses, and the mean
/// die temperature of its samples. The log is read as it is (damaged logs refused); errors name
/// it and say what to do. `warnings` gets a note when the die moved by more than 2 deg C over it.
[[nodiscard]] Result<calib::ThermalScalePoint> scale_point_from_log(const std::string& path,
                                                                    const std::string& stream,
                                                                    std::vector<std::string>& warnings);

}  // namespace imucal::app
