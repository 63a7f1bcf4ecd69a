// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A small synthetic multi-position recording for the static calibration tests (Tedaldi 2013,
// section 4.1 in spirit): a still start, then smooth rotations between random attitudes with
// holds, pure rotation about the IMU origin so the specific force is gravity only. Sensor model
// eqs. 4.1, 4.2: raw = (T K)^-1 ideal - b + noise, optionally in counts with an offset.

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "core/imu.hpp"
#include "core/imu_model.hpp"

namespace imucal::test {

struct SynthConfig {
  unsigned seed = 1;
  double rate_hz = 100.0;
  double still_s = 50.0;
  int poses = 40;
  double hold_min_s = 1.5, hold_max_s = 3.0;
  double move_min_s = 1.5, move_max_s = 3.0;
  double gravity = 9.80665;
  double accel_noise = 3.92e-3 * std::sqrt(100.0);  // per-sample sigma, m/s^2
  double gyro_noise = 8.73e-5 * std::sqrt(100.0);   // per-sample sigma, rad/s
  bool raw_counts = false;                          // output counts: si = lsb * (raw - offset)
  double accel_lsb = 9.80665 / 8192.0, gyro_lsb = M_PI / 180.0 / 65.5;
  double accel_offset = 32768.0, gyro_offset = 32768.0;
  TedaldiImuModel truth;  // maps sensor values (after count conversion) to ideal
  /// Gyro g-sensitivity, canonical G (rad/s per m/s^2): the gyro senses w + G f.
  Eigen::Matrix3d gsens = Eigen::Matrix3d::Zero();
  /// Accelerometer noise during the still start, as a multiple of accel_noise (an accelerometer
  /// that settles after power-up).
  double accel_noise_start = 1.0;
  double gyro_noise_start = 1.0;  // the same for the gyro (a rig held by hand)
};

inline TedaldiImuModel random_truth(unsigned seed) {
  std::mt19937 rng(seed * 7919u + 13u);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  TedaldiImuModel m;
  m.accel.T = accel_misalignment(Eigen::Vector3d(u(rng), u(rng), u(rng)) * 0.01);
  m.accel.scale = Eigen::Vector3d::Ones() + 0.02 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  m.accel.bias = 0.3 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  Eigen::Matrix<double, 6, 1> g;
  for (int i = 0; i < 6; ++i) g[i] = 0.015 * u(rng);
  m.gyro.T = gyro_misalignment(g);
  m.gyro.scale = Eigen::Vector3d::Ones() + 0.03 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  m.gyro.bias = 0.02 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  return m;
}

struct SynthRecording {
  std::vector<ImuSample> samples;
  std::vector<std::pair<double, double>> holds_s;  // [t0, t1] of the still start and every hold
};

inline SynthRecording make_static_recording(const SynthConfig& cfg) {
  std::mt19937 rng(cfg.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double dt = 1.0 / cfg.rate_hz;
  const Eigen::Matrix3d inv_a = cfg.truth.accel.TK().inverse();
  const Eigen::Matrix3d inv_g = cfg.truth.gyro.TK().inverse();
  SynthRecording rec;
  double t = 0.0;
  long index = 0;
  Eigen::Quaterniond q(Eigen::Vector4d(gauss(rng), gauss(rng), gauss(rng), gauss(rng)).normalized());
  auto emit = [&](const Eigen::Quaterniond& q_wb, const Eigen::Vector3d& w_body) {
    const Eigen::Vector3d f = q_wb.conjugate() * Eigen::Vector3d(0, 0, cfg.gravity);
    ImuSample s;
    s.t_ns = index * static_cast<TimeNs>(std::llround(dt * 1e9));
    Eigen::Vector3d a = inv_a * f - cfg.truth.accel.bias;
    Eigen::Vector3d w = inv_g * (w_body + cfg.gsens * f) - cfg.truth.gyro.bias;
    const bool in_still_start = static_cast<double>(index) * dt < cfg.still_s;
    const double accel_noise = cfg.accel_noise * (in_still_start ? cfg.accel_noise_start : 1.0);
    const double gyro_noise = cfg.gyro_noise * (in_still_start ? cfg.gyro_noise_start : 1.0);
    for (int i = 0; i < 3; ++i) {
      a[i] += accel_noise * gauss(rng);
      w[i] += gyro_noise * gauss(rng);
    }
    if (cfg.raw_counts) {
      for (int i = 0; i < 3; ++i) {
        a[i] = std::round(a[i] / cfg.accel_lsb + cfg.accel_offset);
        w[i] = std::round(w[i] / cfg.gyro_lsb + cfg.gyro_offset);
      }
    }
    s.accel = a;
    s.gyro = w;
    rec.samples.push_back(s);
    ++index;
    t += dt;
  };
  auto hold = [&](double duration) {
    const double t0 = t;
    const long n = std::lround(duration / dt);
    for (long i = 0; i < n; ++i) emit(q, Eigen::Vector3d::Zero());
    rec.holds_s.emplace_back(t0, t - dt);
  };
  hold(cfg.still_s);
  for (int p = 0; p < cfg.poses; ++p) {
    // Turn by 40-120 deg about a random axis with a smooth (1 - cos) rate profile.
    const Eigen::Vector3d axis = Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
    const double angle = (40.0 + 80.0 * uni(rng)) * M_PI / 180.0;
    const double dur = cfg.move_min_s + (cfg.move_max_s - cfg.move_min_s) * uni(rng);
    const long n = std::lround(dur / dt);
    const Eigen::Quaterniond q0 = q;
    for (long i = 0; i < n; ++i) {
      const double s = static_cast<double>(i) / static_cast<double>(n);
      const double frac = s - std::sin(2 * M_PI * s) / (2 * M_PI);
      const double rate = angle / (static_cast<double>(n) * dt) * (1 - std::cos(2 * M_PI * s));
      const Eigen::Quaterniond qi = q0 * Eigen::Quaterniond(Eigen::AngleAxisd(angle * frac, axis));
      emit(qi, rate * axis);
    }
    q = q0 * Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis));
    hold(cfg.hold_min_s + (cfg.hold_max_s - cfg.hold_min_s) * uni(rng));
  }
  return rec;
}

inline AxisConversion counts_conversion(double lsb, double offset) {
  AxisConversion c;
  c.scale = Eigen::Vector3d::Constant(lsb);
  c.offset = Eigen::Vector3d::Constant(offset);
  return c;
}

}  // namespace imucal::test
