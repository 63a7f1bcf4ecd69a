// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A second generator of synthetic camera-IMU recordings, with a rolling-shutter camera, for testing
// the calibration on data that the project's simulator did not make: it shares no code with sim/,
// draws no images and projects the target corners analytically. The body follows closed-form
// sinusoids, so the IMU readings are exact derivatives of the pose, and each corner is seen at the
// time of the image row it lands on.
//
// World frame = target frame: the checkerboard hangs vertically in the z = 0 plane with its y axis
// down, so g_w = (0, 9.80665, 0); the camera looks at it along +z (the board's z axis points away
// from the camera, as the checkerboard detector has it).
//   p_cam = T_cam_imu * T_wb(t)^-1 * p_w,  accel = R_wb^T (a_w - g_w) + bias + noise,
//   a corner on image row v of the frame stamped t_cam is seen at the IMU time
//   t_cam + timeshift + row_offset(v) line_delay, row_offset(v) = (readout position of row v) -
//   (readout position of the stamped row).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <stdexcept>
#include <vector>

#include "calib/camimu_calibration.hpp"
#include "calib/target_detection.hpp"
#include "core/camera_model.hpp"
#include "core/target.hpp"
#include "core/time.hpp"

namespace imucal::test {

struct RsAnalyticOptions {
  std::uint64_t seed = 1;
  double duration_s = 40.0, imu_rate_hz = 200.0, camera_rate_hz = 20.0;
  double line_delay_s = 30e-6;  // 0 = global shutter (the camera's shutter kind then global)
  Shutter::Readout readout = Shutter::Readout::kTopToBottom;
  Shutter::StampRow stamp_row = Shutter::StampRow::kFirst;
  double timeshift_s = 0.006;
  double corner_sigma_px = 0.2;
  bool imu_noise = true;      // white noise and the constant biases; false: exact readings, zero biases
  double motion_scale = 1.0;  // multiplies every sinusoid's amplitude (rotation and translation)
};

struct RsAnalyticRig {
  std::vector<calib::CamImuSample> imu;
  calib::CamImuCameraInput camera;  // "cam0"; camera.camera: the true intrinsics and shutter
  TargetDescription target;
  Eigen::Isometry3d T_cam_imu;  // truth
  double timeshift_s = 0, line_delay_s = 0;
  Eigen::Vector3d gyro_bias, accel_bias;  // truth
  double frames_all_corners_fraction = 0;
};

namespace rs_analytic {

inline constexpr double kGravity = 9.80665;
/// Gravity in the world (target) frame: the board hangs vertically with its y axis down.
inline Eigen::Vector3d gravity_w() { return Eigen::Vector3d(0.0, kGravity, 0.0); }

// The default rig. The camera looks at the board's centre from kViewDistance along +z; the IMU's
// axes are x forward (the optical axis), y left and z up, turned by a few degrees.
inline constexpr double kViewDistance = 0.7;          // m
inline constexpr double kAccelNoiseDensity = 0.0039;  // m/s^2/sqrt(Hz)
inline constexpr double kGyroNoiseDensity = 8.73e-5;  // rad/s/sqrt(Hz)
inline Eigen::Vector3d default_gyro_bias() { return Eigen::Vector3d(0.01, -0.005, 0.008); }
inline Eigen::Vector3d default_accel_bias() { return Eigen::Vector3d(0.05, -0.03, 0.04); }

inline TargetDescription default_target() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 7;
  t.rows = 6;
  t.col_spacing_m = 0.05;
  t.row_spacing_m = 0.05;
  return t;
}

/// 752 x 480 pinhole-radtan (EuRoC-like); rolling with `line_delay_s` > 0, global with 0.
inline CameraModel default_camera(double line_delay_s, Shutter::Readout readout,
                                  Shutter::StampRow stamp_row) {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics = Eigen::Vector4d(458.7, 458.7, 367.2, 248.4);
  c.distortion_coeffs = Eigen::Vector4d(-0.28, 0.07, 2e-4, 2e-5);
  c.width = 752;
  c.height = 480;
  if (line_delay_s > 0.0) {
    c.shutter.kind = Shutter::Kind::kRolling;
    c.shutter.line_delay_s = line_delay_s;
    c.shutter.readout = readout;
    c.shutter.stamp_row = stamp_row;
  }
  return c;
}

/// The true extrinsics: the axis permutation (IMU x, y, z = camera z, -x, -y) turned by a rotation
/// vector of (0.04, -0.03, 0.05) rad (4.1 degrees), and the camera centre a few centimetres from the
/// IMU.
inline Eigen::Isometry3d default_T_cam_imu() {
  Eigen::Matrix3d permutation;
  permutation << 0, -1, 0,  //
      0, 0, -1,             //
      1, 0, 0;
  const Eigen::Vector3d turn(0.04, -0.03, 0.05);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(turn.norm(), turn.normalized()).toRotationMatrix() * permutation;
  T.translation() = Eigen::Vector3d(0.04, -0.025, 0.015);
  return T;
}

/// The camera's orientation in the world with the body at rest: looking along the board's +z with
/// the image x and y along the board's x and y.
inline Eigen::Matrix3d default_R_wc0() { return Eigen::Matrix3d::Identity(); }

inline Eigen::Matrix3d rot_x(double c) {
  return Eigen::AngleAxisd(c, Eigen::Vector3d::UnitX()).toRotationMatrix();
}
inline Eigen::Matrix3d rot_y(double b) {
  return Eigen::AngleAxisd(b, Eigen::Vector3d::UnitY()).toRotationMatrix();
}
inline Eigen::Matrix3d rot_z(double a) {
  return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

/// amp sin(omega t + phase) with its first two derivatives.
struct Wave {
  double amp = 0.0, omega = 0.0, phase = 0.0;
  double value(double t) const { return amp * std::sin(omega * t + phase); }
  double rate(double t) const { return amp * omega * std::cos(omega * t + phase); }
  double accel(double t) const { return -amp * omega * omega * std::sin(omega * t + phase); }
};

/// A vector-valued wave: amp sin(omega t + phase).
struct Wave3 {
  Eigen::Vector3d amp = Eigen::Vector3d::Zero();
  double omega = 0.0, phase = 0.0;
};

/// The body's pose: R_wb(t) = R_base Rz(a(t)) Ry(b(t)) Rx(c(t)), p_wb(t) = p0 + sum of Wave3.
struct Trajectory {
  Eigen::Matrix3d R_base = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p0 = Eigen::Vector3d::Zero();
  std::array<std::vector<Wave>, 3> angle;  // a (about z), b (about y), c (about x)
  std::vector<Wave3> position;

  static double sum_value(const std::vector<Wave>& w, double t) {
    double s = 0.0;
    for (const Wave& x : w) s += x.value(t);
    return s;
  }
  static double sum_rate(const std::vector<Wave>& w, double t) {
    double s = 0.0;
    for (const Wave& x : w) s += x.rate(t);
    return s;
  }

  Eigen::Matrix3d R_wb(double t) const {
    return R_base * rot_z(sum_value(angle[0], t)) * rot_y(sum_value(angle[1], t)) *
           rot_x(sum_value(angle[2], t));
  }
  Eigen::Vector3d p_wb(double t) const {
    Eigen::Vector3d p = p0;
    for (const Wave3& w : position) p += w.amp * std::sin(w.omega * t + w.phase);
    return p;
  }
  /// The body's angular velocity in the body frame. For R = Rz(a) Ry(b) Rx(c),
  /// R^T dR/dt = [Rx^T Ry^T (0, 0, a') + Rx^T (0, b', 0) + (c', 0, 0)]x; R_base drops out.
  Eigen::Vector3d omega_b(double t) const {
    const double b = sum_value(angle[1], t);
    const double c = sum_value(angle[2], t);
    const Eigen::Matrix3d Rx_t = rot_x(c).transpose();
    return Rx_t * rot_y(b).transpose() * Eigen::Vector3d(0.0, 0.0, sum_rate(angle[0], t)) +
           Rx_t * Eigen::Vector3d(0.0, sum_rate(angle[1], t), 0.0) +
           Eigen::Vector3d(sum_rate(angle[2], t), 0.0, 0.0);
  }
  /// The body's acceleration in the world frame.
  Eigen::Vector3d accel_w(double t) const {
    Eigen::Vector3d a = Eigen::Vector3d::Zero();
    for (const Wave3& w : position) a -= w.amp * (w.omega * w.omega) * std::sin(w.omega * t + w.phase);
    return a;
  }
  /// What an ideal accelerometer reads: the specific force in the body frame.
  Eigen::Vector3d specific_force_b(double t) const {
    return R_wb(t).transpose() * (accel_w(t) - gravity_w());
  }
  Eigen::Isometry3d T_wb(double t) const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = R_wb(t);
    T.translation() = p_wb(t);
    return T;
  }
};

/// The trajectory for a seed: the camera swings about the board's centre (each pan and tilt wave
/// comes with the translation that keeps the optical axis near the centre, to first order), rolls
/// about its optical axis, and moves on its own by a few centimetres along every world axis.
/// Depends only on the seed, the motion scale, the target and the extrinsics.
inline Trajectory make_trajectory(std::uint64_t seed, double motion_scale, const TargetDescription& target,
                                  const Eigen::Isometry3d& T_cam_imu) {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32), 0x7261u};
  std::mt19937_64 rng(seq);
  auto uniform = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  constexpr double kTwoPi = 2.0 * std::numbers::pi;

  const Eigen::Matrix3d R_wc0 = default_R_wc0();
  const Eigen::Matrix3d& R_ci = T_cam_imu.linear();
  const Eigen::Vector3d centre(0.5 * (target.cols - 1) * target.col_spacing_m,
                               0.5 * (target.rows - 1) * target.row_spacing_m, 0.0);
  const Eigen::Vector3d p_wc0 = centre - kViewDistance * (R_wc0 * Eigen::Vector3d::UnitZ());

  Trajectory traj;
  traj.R_base = R_wc0 * R_ci;
  // The camera centre is p_wb - R_wb R_ci^T t_ci, so the body at rest sits at p_wc0 + R_wc0 t_ci.
  traj.p0 = p_wc0 + R_wc0 * T_cam_imu.translation();

  // Per Euler angle: count, amplitude range (rad), frequency range (Hz). The body's z and y axes
  // are close to the camera's -y and -x (pan and tilt), its x axis to the optical axis (roll).
  struct AngleSpec {
    int count;
    double amp_lo, amp_hi, f_lo, f_hi;
  };
  const std::array<AngleSpec, 3> specs = {{{2, 0.2, 0.3, 0.2, 0.9},     // a: pan
                                           {2, 0.15, 0.25, 0.2, 0.9},   // b: tilt
                                           {3, 0.2, 0.45, 0.2, 1.5}}};  // c: roll
  for (int k = 0; k < 3; ++k) {
    for (int i = 0; i < specs[k].count; ++i) {
      Wave w;
      w.amp = motion_scale * uniform(specs[k].amp_lo, specs[k].amp_hi);
      w.omega = kTwoPi * uniform(specs[k].f_lo, specs[k].f_hi);
      w.phase = uniform(0.0, kTwoPi);
      traj.angle[k].push_back(w);
      // A small body rotation theta turns the camera by R_ci theta and its optical axis by
      // R_wc0 (R_ci theta x e_z); moving the camera by -d times that keeps the centre in view.
      Eigen::Vector3d theta = Eigen::Vector3d::Zero();
      theta[2 - k] = w.amp;  // a turns about z, b about y, c about x
      Wave3 orbit;
      orbit.amp = -kViewDistance * (R_wc0 * (R_ci * theta).cross(Eigen::Vector3d::UnitZ()));
      orbit.omega = w.omega;
      orbit.phase = w.phase;
      traj.position.push_back(orbit);
    }
  }
  // Free translation: two waves per world axis, smaller across the view than along it.
  const std::array<std::array<double, 2>, 3> amp_range = {{{0.05, 0.08}, {0.05, 0.08}, {0.05, 0.15}}};
  for (int axis = 0; axis < 3; ++axis) {
    for (int i = 0; i < 2; ++i) {
      Wave3 w;
      w.amp[axis] = motion_scale * uniform(amp_range[axis][0], amp_range[axis][1]);
      w.omega = kTwoPi * uniform(0.2, 1.2);
      w.phase = uniform(0.0, kTwoPi);
      traj.position.push_back(w);
    }
  }
  return traj;
}

/// The readout position of image row v minus that of the stamped row (the definition in the
/// header comment; independent of Shutter::row_offset, which tests compare it with).
inline double row_offset(double v, int height, Shutter::Readout readout, Shutter::StampRow stamp_row) {
  const double last_row = static_cast<double>(height) - 1.0;
  const double position = readout == Shutter::Readout::kTopToBottom ? v : last_row - v;
  double stamped = 0.0;
  if (stamp_row == Shutter::StampRow::kMiddle) stamped = 0.5 * last_row;
  if (stamp_row == Shutter::StampRow::kLast) stamped = last_row;
  return position - stamped;
}

/// A world point in the camera frame at IMU time t.
inline Eigen::Vector3d point_in_camera(const Trajectory& traj, const Eigen::Isometry3d& T_cam_imu,
                                       const Eigen::Vector3d& p_w, double t) {
  return T_cam_imu * (traj.R_wb(t).transpose() * (p_w - traj.p_wb(t)));
}

struct CornerView {
  bool valid = false;      // in front of the camera and on the sensor, at its own time
  bool converged = false;  // the row iteration settled
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
  double t_s = 0.0;  // the IMU time at which the corner is seen
  int iterations = 0;
};

/// Where and when the frame whose stamped row shows the world at IMU time `t_stamp_s` sees the world
/// point p_w: the fixed point of t -> project -> v -> t = t_stamp_s + row_offset(v) line_delay_s,
/// started from the row at t_stamp_s and stopped when the row moves by less than 1e-6 px (at most
/// 20 steps). With line_delay_s = 0 the plain projection at t_stamp_s.
inline CornerView view_corner(const Trajectory& traj, const Eigen::Isometry3d& T_cam_imu,
                              const CameraModel& camera, const Eigen::Vector3d& p_w, double t_stamp_s,
                              double line_delay_s, Shutter::Readout readout, Shutter::StampRow stamp_row) {
  CornerView out;
  out.t_s = t_stamp_s;
  CameraModel::Projection proj = camera.project(point_in_camera(traj, T_cam_imu, p_w, t_stamp_s));
  if (!proj.in_front) return out;
  if (line_delay_s > 0.0) {
    constexpr int kMaxIterations = 20;
    constexpr double kTolerancePx = 1e-6;
    double v = proj.px.y();
    for (int i = 0; i < kMaxIterations; ++i) {
      out.t_s = t_stamp_s + row_offset(v, camera.height, readout, stamp_row) * line_delay_s;
      proj = camera.project(point_in_camera(traj, T_cam_imu, p_w, out.t_s));
      out.iterations = i + 1;
      if (!proj.in_front) return out;
      const double dv = proj.px.y() - v;
      v = proj.px.y();
      if (std::abs(dv) < kTolerancePx) {
        out.converged = true;
        break;
      }
    }
  } else {
    out.converged = true;
  }
  out.px = proj.px;
  out.valid = out.converged && proj.valid();
  return out;
}

/// The generator behind make_rs_analytic_rig, for any checkerboard.
inline RsAnalyticRig make_rig(const RsAnalyticOptions& o, const TargetDescription& target) {
  if (!(o.duration_s > 2.0) || !(o.imu_rate_hz > 0.0) || !(o.camera_rate_hz > 0.0) ||
      !(o.line_delay_s >= 0.0) || !(o.corner_sigma_px >= 0.0) || !(std::abs(o.timeshift_s) < 0.5)) {
    throw std::invalid_argument("make_rs_analytic_rig: options out of range");
  }
  RsAnalyticRig rig;
  rig.target = target;
  rig.T_cam_imu = default_T_cam_imu();
  rig.timeshift_s = o.timeshift_s;
  rig.line_delay_s = o.line_delay_s;
  rig.gyro_bias = o.imu_noise ? default_gyro_bias() : Eigen::Vector3d::Zero();
  rig.accel_bias = o.imu_noise ? default_accel_bias() : Eigen::Vector3d::Zero();
  const Trajectory traj = make_trajectory(o.seed, o.motion_scale, target, rig.T_cam_imu);

  // Separate generators for the IMU and the corner noise, so that switching one leaves the other.
  std::seed_seq imu_seq{static_cast<std::uint32_t>(o.seed), static_cast<std::uint32_t>(o.seed >> 32),
                        0x696du};
  std::seed_seq px_seq{static_cast<std::uint32_t>(o.seed), static_cast<std::uint32_t>(o.seed >> 32), 0x7078u};
  std::mt19937_64 imu_rng(imu_seq);
  std::mt19937_64 px_rng(px_seq);
  std::normal_distribution<double> imu_normal(0.0, 1.0);
  std::normal_distribution<double> px_normal(0.0, 1.0);

  // IMU: t = 0 .. duration, stamped on the IMU clock, which is the trajectory's time.
  const double accel_sigma = kAccelNoiseDensity * std::sqrt(o.imu_rate_hz);
  const double gyro_sigma = kGyroNoiseDensity * std::sqrt(o.imu_rate_hz);
  const auto imu_count = static_cast<std::int64_t>(std::floor(o.duration_s * o.imu_rate_hz + 1e-9)) + 1;
  rig.imu.reserve(static_cast<std::size_t>(imu_count));
  for (std::int64_t i = 0; i < imu_count; ++i) {
    calib::CamImuSample s;
    s.t_ns = s_to_ns(static_cast<double>(i) / o.imu_rate_hz);
    const double t = ns_to_s(s.t_ns);
    s.gyro = traj.omega_b(t) + rig.gyro_bias;
    s.accel = traj.specific_force_b(t) + rig.accel_bias;
    if (o.imu_noise) {
      for (int k = 0; k < 3; ++k) s.accel[k] += accel_sigma * imu_normal(imu_rng);
      for (int k = 0; k < 3; ++k) s.gyro[k] += gyro_sigma * imu_normal(imu_rng);
    }
    rig.imu.push_back(s);
  }

  // Camera: frames stamped t_cam = 1 s .. duration - 1 s on the camera clock.
  rig.camera.name = "cam0";
  rig.camera.stream = "cam0";
  rig.camera.camera = default_camera(o.line_delay_s, o.readout, o.stamp_row);
  const CameraModel& camera = rig.camera.camera;
  const std::vector<Eigen::Vector3d> points = target.points();
  const auto frame_count =
      static_cast<std::int64_t>(std::floor((o.duration_s - 2.0) * o.camera_rate_hz + 1e-9)) + 1;
  std::int64_t frames_all = 0;
  for (std::int64_t k = 0; k < frame_count; ++k) {
    calib::TargetObservation obs;
    obs.t_ns = s_to_ns(1.0 + static_cast<double>(k) / o.camera_rate_hz);
    obs.width = camera.width;
    obs.height = camera.height;
    const double t_stamp = ns_to_s(obs.t_ns) + o.timeshift_s;
    std::size_t seen = 0;
    for (std::size_t id = 0; id < points.size(); ++id) {
      const CornerView view = view_corner(traj, rig.T_cam_imu, camera, points[id], t_stamp, o.line_delay_s,
                                          o.readout, o.stamp_row);
      if (!view.valid) continue;
      ++seen;
      Eigen::Vector2d px = view.px;
      if (o.corner_sigma_px > 0.0) {
        px.x() += o.corner_sigma_px * px_normal(px_rng);
        px.y() += o.corner_sigma_px * px_normal(px_rng);
        // A detector reports no corner off the sensor.
        if (px.x() < -0.5 || px.y() < -0.5 || px.x() >= camera.width - 0.5 || px.y() >= camera.height - 0.5) {
          continue;
        }
      }
      obs.ids.push_back(static_cast<int>(id));
      obs.px.push_back(px);
    }
    // The fraction counts every stamped frame and the corners before the noise.
    if (seen == points.size()) ++frames_all;
    if (obs.ids.size() >= 12) rig.camera.observations.push_back(std::move(obs));
  }
  rig.frames_all_corners_fraction =
      frame_count > 0 ? static_cast<double>(frames_all) / static_cast<double>(frame_count) : 0.0;
  return rig;
}

}  // namespace rs_analytic

/// The recording for `o` with the default board, camera and extrinsics (rs_analytic::default_*).
inline RsAnalyticRig make_rs_analytic_rig(const RsAnalyticOptions& o) {
  return rs_analytic::make_rig(o, rs_analytic::default_target());
}

}  // namespace imucal::test
