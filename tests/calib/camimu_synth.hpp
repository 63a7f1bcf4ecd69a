// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A synthetic camera-IMU recording for the estimator's tests and the accuracy study: the
// simulator's checkerboard motion and IMU error model (MPU-6000 noise), and the target corners
// projected with the true camera, T_cam_imu and time offset plus Gaussian corner noise (no
// rendering, so a seed costs milliseconds; the rendered path is covered by the fixture tests).

#include <Eigen/Geometry>
#include <random>
#include <vector>

#include "calib/camimu_calibration.hpp"
#include "sim/camimu.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"

namespace imucal::test {

struct CamImuSynth {
  std::vector<calib::CamImuSample> imu;
  std::vector<calib::CamImuCameraInput> cameras;
  TargetDescription target;
  sim::ImuModelParams truth;
  Eigen::Isometry3d T_cam_imu = Eigen::Isometry3d::Identity();  // of cam0
  double timeshift_s = 0.0;
  std::vector<Eigen::Isometry3d> T_cams_imu;  // every camera
  std::vector<double> timeshifts_s;
  Eigen::Isometry3d T_world_target = Eigen::Isometry3d::Identity();
};

struct CamImuSynthOptions {
  std::uint64_t seed = 1;
  double duration_s = 90.0;
  double imu_rate_hz = 200.0;
  double camera_rate_hz = 20.0;
  double corner_sigma_px = 0.3;
  double timeshift_s = 0.0042;
  bool noise = true;        // IMU white noise and bias random walk
  bool imu_errors = true;   // scale, misalignment, C_bg, g-sensitivity drawn from the seed
  double excitation = 1.0;  // multiplies the motion's mean acceleration and rate (Krebs' targets)
  /// A second camera (cam1) beside the first: 12 cm along the IMU x axis, turned 10 deg about
  /// y, with its own time offset.
  bool second_camera = false;
  double second_timeshift_s = -0.0123;
  /// A pixel offset shared by every corner of a frame (standard deviation per coordinate), as a
  /// detector's bias on a blurred frame: errors the corners' independent noise does not model.
  double frame_shared_px = 0.0;
  /// From this time on (s; negative: never) every camera sits moved by `moved_by_m` (camera
  /// frame): a recording whose halves disagree.
  double moved_at_s = -1.0;
  Eigen::Vector3d moved_by_m = Eigen::Vector3d::Zero();
};

inline CamImuSynth make_camimu_synth(const CamImuSynthOptions& o) {
  using sim::CamImuSimOptions;
  CamImuSynth out;
  sim::CheckerboardMotionOptions mo = CamImuSimOptions::default_motion();
  mo.duration_s = o.duration_s;
  mo.excitation = o.excitation;
  auto motion = sim::CheckerboardMotion::create(mo, o.seed).value();
  out.truth = o.imu_errors ? sim::ImuModelParams::draw(o.seed) : sim::ImuModelParams{};
  if (!o.noise) {
    out.truth.accel_noise_density = 0;
    out.truth.gyro_noise_density = 0;
    out.truth.accel_bias_random_walk = 0;
    out.truth.gyro_bias_random_walk = 0;
  }
  out.truth.accel_bias_temp_coeff.setZero();
  out.truth.gyro_bias_temp_coeff.setZero();
  out.target = CamImuSimOptions::default_sim_target();
  out.T_cam_imu = CamImuSimOptions::default_T_cam_imu();
  out.timeshift_s = o.timeshift_s;
  out.T_world_target = motion->T_world_board(out.target);
  sim::ImuSimulator imu(out.truth, o.seed, 0);
  const double dt = 1.0 / o.imu_rate_hz;
  for (TimeNs t = 0; t < motion->end_ns(); t += static_cast<TimeNs>(dt * 1e9)) {
    const sim::ImuSimDetail d = imu.sample_si(t, motion->at(t), dt);
    out.imu.push_back({t, d.accel_si, d.gyro_si});
  }
  out.T_cams_imu.push_back(out.T_cam_imu);
  out.timeshifts_s.push_back(o.timeshift_s);
  if (o.second_camera) {
    Eigen::Isometry3d T_c1_c0 = Eigen::Isometry3d::Identity();
    T_c1_c0.linear() = Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
    T_c1_c0.translation() = Eigen::Vector3d(-0.12, 0.005, 0.01);
    out.T_cams_imu.push_back(T_c1_c0 * out.T_cam_imu);
    out.timeshifts_s.push_back(o.second_timeshift_s);
  }
  std::mt19937_64 rng(o.seed * 7919 + 1);
  std::normal_distribution<double> noise(0.0, o.corner_sigma_px);
  std::normal_distribution<double> shared_noise(0.0, 1.0);
  const auto points = out.target.points();
  const TimeNs frame_ns = static_cast<TimeNs>(1e9 / o.camera_rate_hz);
  for (std::size_t c = 0; c < out.T_cams_imu.size(); ++c) {
    calib::CamImuCameraInput cam;
    cam.name = "cam" + std::to_string(c);
    cam.camera = CamImuSimOptions::default_sim_camera();
    const TimeNs shift_ns = static_cast<TimeNs>(out.timeshifts_s[c] * 1e9);
    for (TimeNs tc = frame_ns - std::min<TimeNs>(0, shift_ns); tc + shift_ns < motion->end_ns();
         tc += frame_ns) {
      // A frame stamped tc shows the scene of IMU time tc + shift.
      const sim::RigState s = motion->at(tc + shift_ns);
      Eigen::Isometry3d T_world_body = Eigen::Isometry3d::Identity();
      T_world_body.linear() = s.q_world_body.toRotationMatrix();
      T_world_body.translation() = s.p_world_body;
      Eigen::Isometry3d T_cam_imu = out.T_cams_imu[c];
      if (o.moved_at_s >= 0.0 && static_cast<double>(tc) * 1e-9 >= o.moved_at_s)
        T_cam_imu.translation() += o.moved_by_m;
      const Eigen::Isometry3d T_cam_target = T_cam_imu * T_world_body.inverse() * out.T_world_target;
      // Drawn only when asked for, so that the other recordings' noise stays as it was.
      Eigen::Vector2d shared = Eigen::Vector2d::Zero();
      if (o.frame_shared_px > 0.0)
        shared = o.frame_shared_px * Eigen::Vector2d(shared_noise(rng), shared_noise(rng));
      calib::TargetObservation obs;
      obs.t_ns = tc;
      obs.width = cam.camera.width;
      obs.height = cam.camera.height;
      for (std::size_t k = 0; k < points.size(); ++k) {
        const auto pr = cam.camera.project(T_cam_target * points[k]);
        if (!pr.valid()) continue;
        obs.ids.push_back(static_cast<int>(k));
        obs.px.push_back(pr.px + shared + Eigen::Vector2d(noise(rng), noise(rng)));
      }
      if (!obs.ids.empty()) cam.observations.push_back(std::move(obs));
    }
    out.cameras.push_back(std::move(cam));
  }
  return out;
}

}  // namespace imucal::test
