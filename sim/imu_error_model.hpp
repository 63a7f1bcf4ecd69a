// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The simulated MPU-6000: the extended IMU error model of Krebs (2012, ch. 3), with noise and
// bias values after its appendix A and the MPU-6000 datasheet, quantised to the chip's int16
// output at the configured full-scale range. The exact output equations are written down in
// docs/simulator.md; in short, with the body frame B = the accelerometer orthogonal frame (AOF:
// x along the accelerometer's x sensing axis, y in its x-y sensing plane) and
// f_B = C_wb^T (a_w - g_w) the specific force in B:
//
//   a_raw = S_a M_a f_B + b_a(t) + n_a                                 (m/s^2)
//   w_raw = S_g M_g C_bg^T w_B + B_g f_B + b_g(t) + n_g                (rad/s)
//   counts = clamp(round(raw / nominal_lsb), -32768, 32767)
//
// where M is unit lower-triangular, S diagonal, C_bg rotates gyroscope-frame vectors into B,
// b(t) = turn-on bias + random walk + c1 dT + c2 dT^2 + c3 dT^3 with dT = T(t) - T(0), per axis
// (the die temperature T follows the configured temperature profile).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "sim/motion_random.hpp"
#include "sim/trajectory.hpp"

namespace imucal::sim {

/// MPU-6000 temperature sensor: T_degC = raw / 340 + 36.53 (register map, TEMP_OUT).
inline constexpr double kMpu6000TempLsbPerDegC = 340.0;
inline constexpr double kMpu6000TempOffsetDegC = 36.53;
/// Earth rotation rate, rad/s.
inline constexpr double kEarthRateRadps = 7.292115e-5;

/// Nominal sensitivity for a full-scale setting: 2/4/8/16 g -> 16384/8192/4096/2048 LSB/g;
/// 250/500/1000/2000 deg/s -> 131/65.5/32.8/16.4 LSB/(deg/s). Other values are an error.
[[nodiscard]] Result<double> accel_lsb_per_g(int full_scale_g);
[[nodiscard]] Result<double> gyro_lsb_per_dps(int full_scale_dps);

/// How the die temperature moves over a recording (ImuModelParams::temperature_c).
enum class TemperatureProfile {
  kWarmUp,  // first-order warm-up from temp_start_c towards temp_final_c (a cold start)
  kSoak,    // linear ramp from temp_start_c to temp_final_c over temp_ramp_s, then held (heat soak)
  kStep,    // held at temp_start_c until temp_step_time_s, then a first-order approach to temp_final_c
};

/// "warmup", "soak", "step".
const char* temperature_profile_name(TemperatureProfile profile);
[[nodiscard]] Result<TemperatureProfile> parse_temperature_profile(const std::string& name);

/// All parameters of the simulated IMU. SI units throughout; the defaults are an ideal sensor
/// (unit scale, no misalignment, no bias) with the datasheet noise, so that tests can switch
/// single effects on. draw() makes a realistic, seeded instance.
struct ImuModelParams {
  // Accelerometer: a_raw = S_a M_a f_B + b_a.
  Eigen::Vector3d accel_scale = Eigen::Vector3d::Ones();             // diagonal of S_a
  Eigen::Matrix3d accel_misalignment = Eigen::Matrix3d::Identity();  // M_a, unit lower-triangular
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();              // turn-on bias, m/s^2

  // Gyroscope: w_raw = S_g M_g C_bg^T w_B + B_g f_B + b_g.
  Eigen::Vector3d gyro_scale = Eigen::Vector3d::Ones();             // diagonal of S_g
  Eigen::Matrix3d gyro_misalignment = Eigen::Matrix3d::Identity();  // M_g, unit lower-triangular
  Eigen::Quaterniond q_body_gyro = Eigen::Quaterniond::Identity();  // C_bg: gyro frame -> body
  Eigen::Matrix3d g_sensitivity = Eigen::Matrix3d::Zero();          // B_g, (rad/s)/(m/s^2)
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();              // turn-on bias, rad/s

  // White noise densities (Kalibr convention: discrete sigma = density / sqrt(dt)).
  double accel_noise_density = 3.92e-3;  // (m/s^2)/sqrt(Hz), MPU-6000 datasheet 400 ug/sqrt(Hz)
  double gyro_noise_density = 8.73e-5;   // (rad/s)/sqrt(Hz), datasheet 0.005 (deg/s)/sqrt(Hz)
  // Bias random walks (discrete step sigma = density * sqrt(dt)); see docs/simulator.md for why
  // these differ from the figures printed in Krebs's table A.1.
  double accel_bias_random_walk = 1.0e-4;  // (m/s^3)/sqrt(Hz)
  double gyro_bias_random_walk = 2.0e-5;   // (rad/s^2)/sqrt(Hz)

  // Environment.
  double gravity_mps2 = kStandardGravity;  // local |g|; the world's gravity is (0, 0, -g)
  bool earth_rotation = false;             // add the earth rate to the true body rate
  double latitude_deg = 47.37;             // for the earth rate; world x east, y north, z up

  // Die temperature: by default a first-order warm-up from temp_start_c towards temp_final_c.
  TemperatureProfile temp_profile = TemperatureProfile::kWarmUp;
  double temp_start_c = 30.0;
  double temp_final_c = 36.0;
  double temp_time_constant_s = 600.0;  // kWarmUp and kStep
  double temp_ramp_s = 600.0;           // kSoak: length of the ramp
  double temp_step_time_s = 0.0;        // kStep: when the surroundings step to temp_final_c
  // Bias against die temperature, per axis: c1 dT + c2 dT^2 + c3 dT^3, dT = T - temp_start_c
  // (temp_ref_c()). The linear terms alone give the model of earlier versions.
  Eigen::Vector3d accel_bias_temp_coeff = Eigen::Vector3d::Zero();   // c1, (m/s^2)/K
  Eigen::Vector3d accel_bias_temp_coeff2 = Eigen::Vector3d::Zero();  // c2, (m/s^2)/K^2
  Eigen::Vector3d accel_bias_temp_coeff3 = Eigen::Vector3d::Zero();  // c3, (m/s^2)/K^3
  Eigen::Vector3d gyro_bias_temp_coeff = Eigen::Vector3d::Zero();    // c1, (rad/s)/K
  Eigen::Vector3d gyro_bias_temp_coeff2 = Eigen::Vector3d::Zero();   // c2, (rad/s)/K^2
  Eigen::Vector3d gyro_bias_temp_coeff3 = Eigen::Vector3d::Zero();   // c3, (rad/s)/K^3
  // Scale factor against die temperature, per output axis: the sensed part (before bias and
  // noise) times 1 + k (T - kScaleTempRefC), k relative per K. Zero: the scale does not move.
  static constexpr double kScaleTempRefC = 25.0;
  Eigen::Vector3d accel_scale_temp_coeff = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_scale_temp_coeff = Eigen::Vector3d::Zero();

  // Device settings.
  int accel_full_scale_g = 4;
  int gyro_full_scale_dps = 500;

  /// Checks shapes and ranges (triangularity of M, positive scales, supported full-scale
  /// ranges, non-negative noise); the message names the field.
  [[nodiscard]] Status validate() const;

  /// A realistic MPU-6000 drawn from `seed`: scale errors 1-3 %, misalignments 0.5-2 deg,
  /// C_bg within +-1 deg per axis, B_g entries ~ N(0, 1.8e-4), turn-on biases uniform within
  /// the datasheet tolerances (accel +-50 mg x/y, +-80 mg z; gyro +-5 deg/s of the +-20 deg/s).
  static ImuModelParams draw(std::uint64_t seed);
  /// Bias temperature coefficients of an MPU-6000 drawn from `seed` (a stream apart from draw()'s)
  /// up to `order` (1..3): per axis c1 within the datasheet's +-0.03 (deg/s)/K and +-1.5 mg/K,
  /// c2 and c3 such that each bends the curve by a comparable amount over a 40 K span.
  void draw_temperature_coefficients(std::uint64_t seed, int order);

  // Derived quantities.
  Eigen::Matrix3d accel_matrix() const;  // S_a M_a
  Eigen::Matrix3d gyro_matrix() const;   // S_g M_g C_bg^T
  /// Nominal raw->SI conversion of one count (what the driver assumes from the range).
  double accel_mps2_per_count() const;
  double gyro_radps_per_count() const;
  /// Die temperature at time t since the start of the recording, deg C.
  double temperature_c(double t_s) const;
  /// The temperature the bias polynomials are taken about: temp_start_c.
  double temp_ref_c() const { return temp_start_c; }
  /// The temperature parts of the biases at die temperature T (zero at temp_ref_c()).
  Eigen::Vector3d accel_bias_temp(double temperature_c) const;
  Eigen::Vector3d gyro_bias_temp(double temperature_c) const;
  /// Polynomial coefficients of one axis's temperature part, c0 (= 0) to c3, about temp_ref_c().
  Eigen::Vector4d accel_bias_temp_poly(int axis) const;
  Eigen::Vector4d gyro_bias_temp_poly(int axis) const;
};

/// The error-free inputs and the unquantised outputs of one simulated sample (for tests and the
/// truth file).
struct ImuSimDetail {
  Eigen::Vector3d specific_force_body = Eigen::Vector3d::Zero();  // f_B, m/s^2
  Eigen::Vector3d rate_body = Eigen::Vector3d::Zero();            // w_B incl. earth rate, rad/s
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();           // b_a(t) in effect
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();            // b_g(t) in effect
  Eigen::Vector3d accel_bias_temp = Eigen::Vector3d::Zero();      // its die-temperature part
  Eigen::Vector3d gyro_bias_temp = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_si = Eigen::Vector3d::Zero();  // a_raw before quantisation
  Eigen::Vector3d gyro_si = Eigen::Vector3d::Zero();   // w_raw before quantisation
  double temperature_c = 0.0;
};

/// Produces MPU-6000 samples from rig states. Deterministic for a given (params, seed) and
/// sequence of calls; sample() must be called with non-decreasing times (the bias random walk
/// advances by the time since the previous call).
class ImuSimulator {
 public:
  ImuSimulator(const ImuModelParams& params, std::uint64_t seed, TimeNs t_start_ns = 0);

  /// One sample in raw counts (int16 values held in doubles, temperature as the TEMP_OUT
  /// count), flags set for saturated triads. `detail`, when given, receives the SI values.
  ImuSample sample(TimeNs t_ns, const RigState& state, double dt_s, ImuSimDetail* detail = nullptr);

  /// The same model without quantisation: a_raw, w_raw in SI (for tests and SI output).
  ImuSimDetail sample_si(TimeNs t_ns, const RigState& state, double dt_s);

  const ImuModelParams& params() const { return p_; }

 private:
  ImuModelParams p_;
  Rng rng_;
  TimeNs t_start_ns_;
  TimeNs t_last_ns_;
  Eigen::Vector3d accel_walk_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_walk_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d accel_matrix_;
  Eigen::Matrix3d gyro_matrix_;
};

/// Ideal specific force and body rate (incl. the earth rate when enabled) for a rig state.
Eigen::Vector3d specific_force_body(const RigState& state, double gravity_mps2);
Eigen::Vector3d rate_body(const RigState& state, const ImuModelParams& params);

}  // namespace imucal::sim
