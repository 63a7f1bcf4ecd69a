// SPDX-License-Identifier: BSD-3-Clause
#include "sim/imu_error_model.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace imucal::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr std::uint64_t kSaltParams = 21;
constexpr std::uint64_t kSaltNoise = 22;
constexpr std::uint64_t kSaltTemperature = 23;

bool unit_lower_triangular(const Eigen::Matrix3d& m) {
  return m(0, 0) == 1.0 && m(1, 1) == 1.0 && m(2, 2) == 1.0 && m(0, 1) == 0.0 && m(0, 2) == 0.0 &&
         m(1, 2) == 0.0 && m.allFinite();
}

/// Rounds to the nearest count and clamps to int16; returns true when clamped.
bool quantise(const Eigen::Vector3d& si, double si_per_count, Eigen::Vector3d* counts) {
  bool saturated = false;
  for (int i = 0; i < 3; ++i) {
    double c = std::nearbyint(si[i] / si_per_count);
    if (!(c <= 32767.0)) {  // also catches NaN
      c = 32767.0;
      saturated = true;
    } else if (c < -32768.0) {
      c = -32768.0;
      saturated = true;
    }
    (*counts)[i] = c;
  }
  return saturated;
}

}  // namespace

Result<double> accel_lsb_per_g(int full_scale_g) {
  switch (full_scale_g) {
    case 2:
      return 16384.0;
    case 4:
      return 8192.0;
    case 8:
      return 4096.0;
    case 16:
      return 2048.0;
    default:
      return make_error(
          Errc::kInvalidArgument,
          "accelerometer full-scale range must be 2, 4, 8 or 16 g, got " + std::to_string(full_scale_g));
  }
}

Result<double> gyro_lsb_per_dps(int full_scale_dps) {
  switch (full_scale_dps) {
    case 250:
      return 131.0;
    case 500:
      return 65.5;
    case 1000:
      return 32.8;
    case 2000:
      return 16.4;
    default:
      return make_error(Errc::kInvalidArgument,
                        "gyroscope full-scale range must be 250, 500, 1000 or 2000 deg/s, got " +
                            std::to_string(full_scale_dps));
  }
}

Status ImuModelParams::validate() const {
  if (!unit_lower_triangular(accel_misalignment) || !unit_lower_triangular(gyro_misalignment)) {
    return make_error(
        Errc::kInvalidArgument,
        "misalignment matrices M_a and M_g must be unit lower-triangular (Krebs ch. 3): ones on "
        "the diagonal, zeros above it");
  }
  if (!(accel_scale.minCoeff() > 0.5 && accel_scale.maxCoeff() < 2.0 && gyro_scale.minCoeff() > 0.5 &&
        gyro_scale.maxCoeff() < 2.0)) {
    return make_error(Errc::kInvalidArgument, "scale factors must be within (0.5, 2)");
  }
  if (std::abs(q_body_gyro.norm() - 1.0) > 1e-6) {
    return make_error(Errc::kInvalidArgument, "q_body_gyro must be a unit quaternion");
  }
  if (!accel_bias.allFinite() || !gyro_bias.allFinite() || !g_sensitivity.allFinite() ||
      !accel_bias_temp_coeff.allFinite() || !gyro_bias_temp_coeff.allFinite() ||
      !accel_bias_temp_coeff2.allFinite() || !gyro_bias_temp_coeff2.allFinite() ||
      !accel_bias_temp_coeff3.allFinite() || !gyro_bias_temp_coeff3.allFinite()) {
    return make_error(Errc::kInvalidArgument, "biases, B_g and temperature coefficients must be finite");
  }
  if (!(accel_scale_temp_coeff.cwiseAbs().maxCoeff() < 0.01) ||
      !(gyro_scale_temp_coeff.cwiseAbs().maxCoeff() < 0.01)) {
    return make_error(Errc::kInvalidArgument,
                      "scale temperature coefficients must be finite and below 0.01 per K (1 %/K) in size");
  }
  if (accel_bias.cwiseAbs().maxCoeff() > 3.0) {
    return make_error(
        Errc::kInvalidArgument,
        "accelerometer bias above 3 m/s^2 (the MPU-6000 tolerance is +-80 mg = 0.78 m/s^2): give "
        "it in m/s^2, not mg or counts");
  }
  if (gyro_bias.cwiseAbs().maxCoeff() > 0.7) {
    return make_error(
        Errc::kInvalidArgument,
        "gyroscope bias above 0.7 rad/s (the MPU-6000 tolerance is +-20 deg/s = 0.35 rad/s): give "
        "it in rad/s, not deg/s or counts");
  }
  if (!(accel_noise_density >= 0.0 && gyro_noise_density >= 0.0 && accel_bias_random_walk >= 0.0 &&
        gyro_bias_random_walk >= 0.0)) {
    return make_error(Errc::kInvalidArgument, "noise densities and random walks must be >= 0");
  }
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9)) {
    return make_error(Errc::kInvalidArgument,
                      "gravity must be given in m/s^2 (9.7..9.9 on the earth's surface), got " +
                          std::to_string(gravity_mps2));
  }
  if (!(temp_time_constant_s > 0.0) || !std::isfinite(temp_start_c) || !std::isfinite(temp_final_c) ||
      temp_start_c < -40.0 || temp_start_c > 85.0 || temp_final_c < -40.0 || temp_final_c > 85.0) {
    return make_error(
        Errc::kInvalidArgument,
        "die temperatures must be within the MPU-6000 range -40..85 deg C and the time constant > 0");
  }
  if (!(temp_ramp_s > 0.0) || !(temp_step_time_s >= 0.0) || !std::isfinite(temp_ramp_s) ||
      !std::isfinite(temp_step_time_s)) {
    return make_error(Errc::kInvalidArgument,
                      "the temperature ramp must last > 0 s and the step time must be >= 0 s");
  }
  IMUCAL_TRY(accel_lsb_per_g(accel_full_scale_g));
  IMUCAL_TRY(gyro_lsb_per_dps(gyro_full_scale_dps));
  return {};
}

const char* temperature_profile_name(TemperatureProfile profile) {
  switch (profile) {
    case TemperatureProfile::kSoak:
      return "soak";
    case TemperatureProfile::kStep:
      return "step";
    case TemperatureProfile::kWarmUp:
      break;
  }
  return "warmup";
}

Result<TemperatureProfile> parse_temperature_profile(const std::string& name) {
  for (TemperatureProfile p :
       {TemperatureProfile::kWarmUp, TemperatureProfile::kSoak, TemperatureProfile::kStep}) {
    if (name == temperature_profile_name(p)) return p;
  }
  return make_error(Errc::kInvalidArgument,
                    "temperature profile must be warmup, soak or step, got '" + name + "'");
}

void ImuModelParams::draw_temperature_coefficients(std::uint64_t seed, int order) {
  Rng rng(Rng::substream(seed, kSaltTemperature));
  const double mg = 1e-3 * kStandardGravity;
  accel_bias_temp_coeff2.setZero();
  accel_bias_temp_coeff3.setZero();
  gyro_bias_temp_coeff2.setZero();
  gyro_bias_temp_coeff3.setZero();
  for (int i = 0; i < 3; ++i) {
    accel_bias_temp_coeff[i] = rng.signed_magnitude(0.3, 1.5) * mg;
    gyro_bias_temp_coeff[i] = rng.signed_magnitude(0.005, 0.03) * kDeg;
    if (order >= 2) {
      accel_bias_temp_coeff2[i] = rng.signed_magnitude(0.005, 0.02) * mg;
      gyro_bias_temp_coeff2[i] = rng.signed_magnitude(2e-4, 6e-4) * kDeg;
    }
    if (order >= 3) {
      accel_bias_temp_coeff3[i] = rng.signed_magnitude(1e-4, 4e-4) * mg;
      gyro_bias_temp_coeff3[i] = rng.signed_magnitude(5e-6, 1.5e-5) * kDeg;
    }
  }
}

ImuModelParams ImuModelParams::draw(std::uint64_t seed) {
  Rng rng(Rng::substream(seed, kSaltParams));
  ImuModelParams p;
  for (int i = 0; i < 3; ++i) p.accel_scale[i] = 1.0 + rng.signed_magnitude(0.01, 0.03);
  for (int i = 0; i < 3; ++i) p.gyro_scale[i] = 1.0 + rng.signed_magnitude(0.01, 0.03);
  auto misalignment = [&]() {
    Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
    m(1, 0) = std::sin(rng.signed_magnitude(0.5 * kDeg, 2.0 * kDeg));  // M_yz
    m(2, 0) = std::sin(rng.signed_magnitude(0.5 * kDeg, 2.0 * kDeg));  // M_zy
    m(2, 1) = std::sin(rng.signed_magnitude(0.5 * kDeg, 2.0 * kDeg));  // M_zx
    return m;
  };
  p.accel_misalignment = misalignment();
  p.gyro_misalignment = misalignment();
  const Eigen::Vector3d rot(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
  p.q_body_gyro = Eigen::Quaterniond(Eigen::AngleAxisd(rot.norm() * kDeg, rot.normalized()));
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) p.g_sensitivity(r, c) = 1.8e-4 * rng.normal();
  const double mg = 1e-3 * kStandardGravity;
  p.accel_bias =
      Eigen::Vector3d(rng.uniform(-50, 50) * mg, rng.uniform(-50, 50) * mg, rng.uniform(-80, 80) * mg);
  for (int i = 0; i < 3; ++i) p.gyro_bias[i] = rng.uniform(-5.0, 5.0) * kDeg;
  return p;
}

Eigen::Matrix3d ImuModelParams::accel_matrix() const { return accel_scale.asDiagonal() * accel_misalignment; }

Eigen::Matrix3d ImuModelParams::gyro_matrix() const {
  return gyro_scale.asDiagonal() * gyro_misalignment * q_body_gyro.toRotationMatrix().transpose();
}

double ImuModelParams::accel_mps2_per_count() const {
  auto lsb = accel_lsb_per_g(accel_full_scale_g);
  return lsb.ok() ? kStandardGravity / *lsb : 0.0;
}

double ImuModelParams::gyro_radps_per_count() const {
  auto lsb = gyro_lsb_per_dps(gyro_full_scale_dps);
  return lsb.ok() ? kDeg / *lsb : 0.0;
}

double ImuModelParams::temperature_c(double t_s) const {
  switch (temp_profile) {
    case TemperatureProfile::kSoak:
      return temp_start_c + (temp_final_c - temp_start_c) * std::clamp(t_s / temp_ramp_s, 0.0, 1.0);
    case TemperatureProfile::kStep:
      if (t_s <= temp_step_time_s) return temp_start_c;
      return temp_final_c +
             (temp_start_c - temp_final_c) * std::exp(-(t_s - temp_step_time_s) / temp_time_constant_s);
    case TemperatureProfile::kWarmUp:
      break;
  }
  return temp_final_c + (temp_start_c - temp_final_c) * std::exp(-t_s / temp_time_constant_s);
}

namespace {

Eigen::Vector3d cubic(double dT, const Eigen::Vector3d& c1, const Eigen::Vector3d& c2,
                      const Eigen::Vector3d& c3) {
  // Horner, so that zero higher terms give exactly c1 * dT.
  return dT * (c1 + dT * (c2 + dT * c3));
}

}  // namespace

Eigen::Vector3d ImuModelParams::accel_bias_temp(double temperature) const {
  return cubic(temperature - temp_ref_c(), accel_bias_temp_coeff, accel_bias_temp_coeff2,
               accel_bias_temp_coeff3);
}

Eigen::Vector3d ImuModelParams::gyro_bias_temp(double temperature) const {
  return cubic(temperature - temp_ref_c(), gyro_bias_temp_coeff, gyro_bias_temp_coeff2,
               gyro_bias_temp_coeff3);
}

Eigen::Vector4d ImuModelParams::accel_bias_temp_poly(int axis) const {
  return {0.0, accel_bias_temp_coeff[axis], accel_bias_temp_coeff2[axis], accel_bias_temp_coeff3[axis]};
}

Eigen::Vector4d ImuModelParams::gyro_bias_temp_poly(int axis) const {
  return {0.0, gyro_bias_temp_coeff[axis], gyro_bias_temp_coeff2[axis], gyro_bias_temp_coeff3[axis]};
}

Eigen::Vector3d specific_force_body(const RigState& state, double gravity_mps2) {
  const Eigen::Vector3d g_world(0.0, 0.0, -gravity_mps2);
  return state.q_world_body.conjugate() * (state.a_world - g_world);
}

Eigen::Vector3d rate_body(const RigState& state, const ImuModelParams& params) {
  Eigen::Vector3d w = state.omega_body;
  if (params.earth_rotation) {
    const double lat = params.latitude_deg * kDeg;
    const Eigen::Vector3d earth_world(0.0, kEarthRateRadps * std::cos(lat), kEarthRateRadps * std::sin(lat));
    w += state.q_world_body.conjugate() * earth_world;
  }
  return w;
}

ImuSimulator::ImuSimulator(const ImuModelParams& params, std::uint64_t seed, TimeNs t_start_ns)
    : p_(params),
      rng_(Rng::substream(seed, kSaltNoise)),
      t_start_ns_(t_start_ns),
      t_last_ns_(t_start_ns),
      accel_matrix_(params.accel_matrix()),
      gyro_matrix_(params.gyro_matrix()) {}

ImuSimDetail ImuSimulator::sample_si(TimeNs t_ns, const RigState& state, double dt_s) {
  ImuSimDetail d;
  // Bias random walk: advance by the time since the previous sample.
  const double step_s = ns_to_s(t_ns - t_last_ns_);
  if (step_s > 0.0) {
    const double sa = p_.accel_bias_random_walk * std::sqrt(step_s);
    const double sg = p_.gyro_bias_random_walk * std::sqrt(step_s);
    for (int i = 0; i < 3; ++i) accel_walk_[i] += sa * rng_.normal();
    for (int i = 0; i < 3; ++i) gyro_walk_[i] += sg * rng_.normal();
  }
  t_last_ns_ = std::max(t_last_ns_, t_ns);
  d.temperature_c = p_.temperature_c(ns_to_s(t_ns - t_start_ns_));
  d.accel_bias_temp = p_.accel_bias_temp(d.temperature_c);
  d.gyro_bias_temp = p_.gyro_bias_temp(d.temperature_c);
  d.accel_bias = p_.accel_bias + accel_walk_ + d.accel_bias_temp;
  d.gyro_bias = p_.gyro_bias + gyro_walk_ + d.gyro_bias_temp;
  d.specific_force_body = specific_force_body(state, p_.gravity_mps2);
  d.rate_body = rate_body(state, p_);
  // White noise, discrete sigma = density / sqrt(dt).
  const double na = dt_s > 0.0 ? p_.accel_noise_density / std::sqrt(dt_s) : 0.0;
  const double ng = dt_s > 0.0 ? p_.gyro_noise_density / std::sqrt(dt_s) : 0.0;
  Eigen::Vector3d noise_a, noise_g;
  for (int i = 0; i < 3; ++i) noise_a[i] = na * rng_.normal();
  for (int i = 0; i < 3; ++i) noise_g[i] = ng * rng_.normal();
  const double dt_scale = d.temperature_c - ImuModelParams::kScaleTempRefC;
  const Eigen::Vector3d accel_tc = Eigen::Vector3d::Ones() + p_.accel_scale_temp_coeff * dt_scale;
  const Eigen::Vector3d gyro_tc = Eigen::Vector3d::Ones() + p_.gyro_scale_temp_coeff * dt_scale;
  d.accel_si = accel_tc.cwiseProduct(accel_matrix_ * d.specific_force_body) + d.accel_bias + noise_a;
  d.gyro_si = gyro_tc.cwiseProduct(gyro_matrix_ * d.rate_body) + p_.g_sensitivity * d.specific_force_body +
              d.gyro_bias + noise_g;
  return d;
}

ImuSample ImuSimulator::sample(TimeNs t_ns, const RigState& state, double dt_s, ImuSimDetail* detail) {
  const ImuSimDetail d = sample_si(t_ns, state, dt_s);
  ImuSample s;
  s.t_ns = t_ns;
  if (quantise(d.accel_si, p_.accel_mps2_per_count(), &s.accel)) s.flags |= kImuFlagAccelSaturated;
  if (quantise(d.gyro_si, p_.gyro_radps_per_count(), &s.gyro)) s.flags |= kImuFlagGyroSaturated;
  s.temperature = std::nearbyint((d.temperature_c - kMpu6000TempOffsetDegC) * kMpu6000TempLsbPerDegC);
  if (detail != nullptr) *detail = d;
  return s;
}

}  // namespace imucal::sim
