// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Bias against die temperature from a still recording over a temperature range (a warm-up from
// cold, a heat soak, holds at several temperatures), per gyro and accelerometer axis; the model,
// the order criterion and the limits are written down in docs/thermal.md.
//
// The samples are averaged in time bins. Each axis's bin means are
//
//   y_k = sum_j c_j (T_k - T_ref)^j + w_k + r(t_k),   j = 0..p,
//
// with w_k the white noise of a bin mean and r(t) a random walk (the part of the slowly varying
// bias that is not temperature). The bins are correlated through r; the polynomial is fitted by
// generalised least squares under that covariance, whose two variances are estimated with the
// coefficients by maximum likelihood. The order p (0..3) is the one of least -2 ln L + (p + 3)
// (a term kept when it lowers -2 ln L by more than 1; docs/thermal.md says why). On a still rig
// the accelerometer also sees gravity's projection, constant while the rig does not move: c_0
// holds it, and only the change with temperature (c_1..c_p) is a temperature model. No solver
// library: Eigen's Cholesky and QR decompositions.

#include <Eigen/Core>
#include <array>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/thermal_model.hpp"

namespace imucal::calib {

struct ThermalOptions {
  /// Raw -> SI conversion of the samples (identity for an SI stream) and of the temperature
  /// (deg C = temperature_scale * raw + temperature_offset).
  AxisConversion accel;
  AxisConversion gyro;
  double temperature_scale = 1.0;
  double temperature_offset = 0.0;
  /// Below this span of die temperature (max - min over the bins, deg C) the model is not
  /// determined.
  double min_span_c = 3.0;
  /// Bin length, s. A recording that would give more than max_bins bins gets longer ones.
  double bin_s = 20.0;
  int max_bins = 200;
  /// Highest polynomial order tried (0..3).
  int max_order = 3;
  /// The reference temperature; default the middle of the range covered.
  std::optional<double> reference_c;
  /// Motion check: means over windows of this length may not step by more than these from one
  /// window to the next (a still rig's bias moves by orders of magnitude less in a second).
  double motion_window_s = 1.0;
  double max_gyro_step_radps = 0.01;
  double max_accel_step_mps2 = 0.1;

  /// Checks ranges; the error names the field.
  [[nodiscard]] Status validate() const;
};

/// The fit of one axis. Units: the axis's SI unit (rad/s or m/s^2) per K^j for c_j.
struct ThermalAxisFit {
  bool determined = false;
  std::string reason;  // why not, when not determined
  int order = 0;
  /// c_0..c_order about the reference temperature. c_0 is the value at the reference (for the
  /// accelerometer it includes gravity's projection and is not a bias).
  Eigen::VectorXd coeffs;
  Eigen::MatrixXd covariance;  // of coeffs
  /// AIC = -2 ln L + 2 (order + 3) of every order tried (NaN where it could not be fitted).
  std::array<double, 4> aic{};
  /// RMS of the bin means about the fitted curve.
  double residual_rms = 0.0;
  /// RMS over the range of the 1-sigma uncertainty of the fitted change f(T) - f(T_ref).
  double model_sigma_rms = 0.0;
  /// max - min over the range of the fitted change: what is left uncompensated without the model.
  double uncompensated_drift = 0.0;
  /// The noise model fitted with the curve: white noise density (unit*sqrt(s)) and bias random
  /// walk (unit/sqrt(s)); 0 where the likelihood prefers none.
  double white_noise_density = 0.0;
  double random_walk = 0.0;

  /// f(T) - f(T_ref): the temperature part at T (deg C), with T_ref the result's reference.
  double change(double temperature_c, double reference_c) const;
  /// The 1-sigma uncertainty of change().
  double change_sigma(double temperature_c, double reference_c) const;
};

/// One time bin's means (SI), as fitted.
struct ThermalBinMean {
  double t_s = 0.0;  // mean time since the first sample
  double temperature_c = 0.0;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
  std::size_t samples = 0;
};

/// The scale factors of one static calibration (calibrate_static) at one die temperature.
struct ThermalScalePoint {
  std::string source;               // the recording
  double temperature_c = 0.0;       // mean die temperature of its samples
  double temperature_span_c = 0.0;  // max - min over its samples
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero(), gyro_sigma = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel = Eigen::Vector3d::Zero(), accel_sigma = Eigen::Vector3d::Zero();
};

/// Scale against temperature from static calibrations at several die temperatures.
struct ThermalScaleFit {
  bool determined = false;
  std::string reason;  // why not, when not determined
  std::vector<ThermalScalePoint> points;
  ThermalScaleModel model;  // k and its sigma per axis (NaN where an input sigma was not determined)
  /// chi^2 / (points - 2) of the weighted fit per axis (NaN with two points: a line through two
  /// points leaves nothing to judge it by). Above 1 the sigmas are inflated by its root.
  Eigen::Vector3d gyro_chi2_dof = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d accel_chi2_dof = gyro_chi2_dof;
};

/// s_i(T) = a_i + b_i (T - reference_c) per axis (s the model's scale, SI per count) by least
/// squares weighted with the points' scale sigmas; the sensitivity is 1 / s, so its relative
/// change per K at the reference is k_i = -b_i / a_i, its sigma propagated from the covariance of
/// (a_i, b_i). Not determined with fewer than two points or a temperature span below min_span_c.
ThermalScaleFit fit_scale_against_temperature(std::vector<ThermalScalePoint> points, double reference_c,
                                              double min_span_c);

struct ThermalResult {
  bool determined = false;
  std::string reason;  // why not, when not determined
  double reference_c = 0.0;
  double temp_min_c = 0.0;  // range covered by the bins
  double temp_max_c = 0.0;
  double duration_s = 0.0;
  std::size_t samples = 0;  // samples used
  int bins = 0;
  double bin_s = 0.0;
  /// The temperature only rose (or only fell) over the recording: time and temperature are then
  /// tied, and a random walk and a temperature curve are told apart only by their shapes.
  bool temperature_monotonic = true;
  std::array<ThermalAxisFit, 3> gyro;   // rad/s
  std::array<ThermalAxisFit, 3> accel;  // m/s^2
  std::vector<ThermalBinMean> bin_means;
  std::vector<std::string> warnings;
  /// Scale against temperature: not determined by a still recording in one attitude; fitted
  /// when static pose recordings at other temperatures are given (fit_scale_against_temperature).
  ThermalScaleFit scale{false, "a still recording in one attitude does not determine it", {}, {}, {}, {}};
};

/// Fits the thermal model. Errors: no sample with a temperature, or the rig moved
/// (kInsufficientData, with what to do). A span below options.min_span_c is a result with
/// determined = false and the reason.
[[nodiscard]] Result<ThermalResult> calibrate_thermal(std::span<const ImuSample> samples,
                                                      const ThermalOptions& options);

/// The model to apply and store (SI): c_1..c_p of each determined axis with their sigmas.
ThermalModel thermal_model(const ThermalResult& result);

/// Polynomial of order p in (T - reference) by least squares on the given points, no weights and
/// no uncertainty: c_0..c_p (used to compare with PX4's thermal calibration).
Eigen::VectorXd fit_polynomial_plain(std::span<const double> temperature_c, std::span<const double> values,
                                     double reference_c, int order);

}  // namespace imucal::calib
