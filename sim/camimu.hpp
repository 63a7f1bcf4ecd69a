// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The simulated camera-IMU session: the virtual rig moved in front of a checkerboard, its IMU
// recorded at imu_rate_hz and its camera rendered at camera_rate_hz into one session log, with
// the ground truth (IMU errors, camera model, T_cam_imu, timeshift_cam_imu, target) written to a
// truth YAML. See docs/simulator-camera.md.
//
// Conventions (docs/conventions.md):
//   T_cam_imu maps points from the IMU (body, accelerometer) frame into the camera frame.
//   t_imu = t_cam + timeshift_cam_imu: a frame stamped t_cam on the camera's clock shows the
//   scene of IMU time t_cam + timeshift_cam_imu. Frame stamps are mid-exposure.

#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "core/camera_model.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/target.hpp"
#include "core/time.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"
#include "sim/session.hpp"

namespace imucal::sim {

/// A further camera of the simulated session (cam1, cam2, ...), with its own intrinsics, pose on
/// the rig and stamp offset; it renders the same board at the same rate and exposure as cam0.
struct CamImuSimCamera {
  CameraModel camera;
  /// Points in the IMU (body) frame -> this camera's frame.
  Eigen::Isometry3d T_cam_imu = Eigen::Isometry3d::Identity();
  /// t_imu = t_cam + timeshift_cam_imu_s for this camera's stamps.
  double timeshift_cam_imu_s = 0.0;
};

struct CamImuSimOptions {
  std::uint64_t seed = 1;
  /// The motion in front of the board (sim/motion.hpp): 60-90 s is what the
  /// camera-IMU calibration expects (Krebs 2012, section 5.2); the default is 60 s.
  sim::CheckerboardMotionOptions motion = default_motion();
  /// The IMU; empty: drawn from the seed (sim::ImuModelParams::draw), as `imucal sim` does.
  std::optional<sim::ImuModelParams> imu;
  bool imu_params_from_file = false;  // recorded in the truth
  double imu_rate_hz = 200.0;         // MPU-6000 output rate
  SimImuPath imu_path;                // how the emulated chip is read (sim/session.hpp)
  double camera_rate_hz = 20.0;
  TimeNs exposure_ns = 4'000'000;  // frames are stamped at mid-exposure

  /// The camera model and its resolution (default: a 376x240 pinhole-radtan camera).
  CameraModel camera = default_sim_camera();
  /// Points in the IMU (body) frame -> camera frame.
  Eigen::Isometry3d T_cam_imu = default_T_cam_imu();
  /// t_imu = t_cam + timeshift_cam_imu_s.
  double timeshift_cam_imu_s = 0.0042;
  /// The board: inner corners and spacing (Kalibr semantics).
  TargetDescription target = default_sim_target();
  /// Cameras after cam0 (a stereo pair: one; default none).
  std::vector<CamImuSimCamera> more_cameras;

  // Image formation (sim/camera_render.hpp).
  /// Gaussian sensor noise, grey levels. Low by default to keep the fixture small (noise is
  /// what lossless codecs cannot compress; docs/simulator-camera.md has the measurements).
  double noise_sigma_dn = 0.2;
  int supersampling = 2;              // n x n area samples per pixel
  double optics_blur_sigma_px = 0.7;  // lens point-spread function (Gaussian sigma)
  bool motion_blur = true;            // average sub-exposure renders over the exposure time
  /// Lossless image codec for the frames in the log: "png" or "webp".
  std::string image_encoding = "webp";

  /// Replace existing output files.
  bool overwrite = false;

  static sim::CheckerboardMotionOptions default_motion();
  static CameraModel default_sim_camera();
  static Eigen::Isometry3d default_T_cam_imu();
  static TargetDescription default_sim_target();
  /// The stereo partner of the default camera: 11 cm along cam0's x axis (to its right), turned by
  /// about a degree, a little different focal length and principal point, its stamps
  /// `offset_s` later than cam0's for the same scene (0: the pair is synchronized).
  static CamImuSimCamera default_stereo_camera(const CameraModel& cam0, const Eigen::Isometry3d& T_cam0_imu,
                                               double timeshift_cam0_imu_s, double offset_s);

  /// Checks ranges; the message says which field is wrong and what is accepted.
  [[nodiscard]] Status validate() const;
};

/// What a simulated session holds (for the command's summary line).
struct CamImuSimSummary {
  std::int64_t imu_samples = 0;
  std::int64_t frames = 0;                      // of every camera
  std::int64_t frames_all_corners_visible = 0;  // the whole inner-corner grid on the sensor
  std::int64_t frames_no_corner_visible = 0;
  double duration_s = 0.0;
  double mean_accel_mps2 = 0.0;
  double mean_rate_radps = 0.0;
  std::int64_t image_bytes = 0;  // encoded frames, total
};

/// Simulates the session and writes the session log at `log_path` and the ground truth at
/// `truth_path` (YAML: the IMU truth of sim/truth.hpp plus a `camera:` section in
/// Kalibr camchain naming). `progress` (may be empty) receives the completed fraction in
/// [0, 1]; `summary` (may be null) receives what was written.
[[nodiscard]] Status simulate_camimu_session(const CamImuSimOptions& options, const std::string& log_path,
                                             const std::string& truth_path, const ProgressFn& progress = {},
                                             CamImuSimSummary* summary = nullptr);

}  // namespace imucal::sim
