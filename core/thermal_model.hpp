// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The thermal model as it is applied and stored (docs/thermal.md): per gyro and accelerometer
// axis, the change of the bias with die temperature about a reference temperature,
//
//   b(T) = b(T_ref) + sum_{j=1..p} c_j (T - T_ref)^j,   T clamped to the valid range,
//
// in the units the model corrects (SI, or raw counts for a model on a raw stream's input units).
// `calibrate thermal` fits it (calib/thermal_calibration.hpp); `calibrate static --thermal` and
// `calibrate camimu --thermal` subtract it from the samples before fitting, so that their biases
// are those at T_ref; the calibration record stores it (core/calibration_record.hpp).

#include <Eigen/Core>
#include <array>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace imucal {

/// One axis: the change terms c_1..c_p (p = 0: no change with temperature) and their 1-sigma
/// (NaN: not determined). `determined` false: the axis has no model (the reason says why) and
/// nothing is subtracted.
struct ThermalAxisModel {
  bool determined = false;
  std::string reason;
  Eigen::VectorXd coeffs;  // c_1..c_p, unit per K^j
  Eigen::VectorXd sigma;   // same size

  /// sum_j c_j dt^j (0 when not determined).
  double change(double dt) const;
};

/// Scale against temperature, per axis: k, the relative change of the sensor's sensitivity
/// (output per input, the datasheet's "sensitivity change vs. temperature") per K about the
/// reference temperature; the model's scale (SI per count, the factor the correction multiplies
/// by) is then scale(T) = scale(T_ref) / (1 + k (T - T_ref)) (kThermalScaleForm). Fitted to static
/// calibrations at two or more die temperatures (`calibrate thermal --scale-from`). NaN: not
/// determined.
struct ThermalScaleModel {
  Eigen::Vector3d gyro_k = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d gyro_sigma = gyro_k;
  Eigen::Vector3d accel_k = gyro_k;
  Eigen::Vector3d accel_sigma = gyro_k;
  std::vector<double> temperatures_c;  // of the static calibrations it was fitted to
};

struct ThermalModel {
  double reference_c = 0.0;
  double min_c = 0.0;  // the range the model is valid over; temperatures are clamped to it
  double max_c = 0.0;
  std::array<ThermalAxisModel, 3> gyro;
  std::array<ThermalAxisModel, 3> accel;
  /// Scale against temperature: the fit, or "not determined: ..." (the reason) without one.
  std::string scale = "not determined: a still recording in one attitude does not determine it";
  std::optional<ThermalScaleModel> scale_model;

  double clamp(double temperature_c) const;
  /// b(T) - b(T_ref) per axis, T clamped.
  Eigen::Vector3d gyro_change(double temperature_c) const;
  Eigen::Vector3d accel_change(double temperature_c) const;
  /// The same model in other units: every coefficient and sigma of axis i multiplied by
  /// gyro_factor(i) or accel_factor(i) (SI -> raw counts: 1 / the nominal scale).
  ThermalModel scaled(const Eigen::Vector3d& gyro_factor, const Eigen::Vector3d& accel_factor) const;
};

/// The form the record states (short: the record must fit small EEPROMs). In words: per axis,
/// T the die temperature in deg C clamped to the valid range, the coefficients in the model's
/// input units per K^j; a sample is corrected to T_ref by subtracting b(T) - b(T_ref).
inline constexpr const char* kThermalForm = "b(T) = b(T_ref) + sum_j c_j (T - T_ref)^j";
/// The scale's form (ThermalScaleModel).
inline constexpr const char* kThermalScaleForm = "scale(T) = scale(T_ref) / (1 + k (T - T_ref))";

}  // namespace imucal
