// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU session's options: defaults and checks, without the renderer (OpenCV) that
// simulate_camimu_session (sim/camimu.cpp, in libimucal_render.so) needs.

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <string>

#include "sim/camera_render_options.hpp"
#include "sim/camimu.hpp"

namespace imucal::sim {
namespace {

double deg(double d) { return d * std::numbers::pi / 180.0; }

Status check_camera_placement(const Eigen::Isometry3d& T_cam_imu, double timeshift_cam_imu_s) {
  if (!T_cam_imu.matrix().allFinite() ||
      !(T_cam_imu.linear().transpose() * T_cam_imu.linear()).isApprox(Eigen::Matrix3d::Identity(), 1e-9) ||
      T_cam_imu.linear().determinant() < 0.0) {
    return make_error(Errc::kInvalidArgument,
                      "T_cam_imu must be a rigid transform (rotation and translation)");
  }
  if (T_cam_imu.translation().norm() > 1.0) {
    return make_error(Errc::kInvalidArgument, "T_cam_imu translation must be in metres and below 1 m");
  }
  if (!(std::abs(timeshift_cam_imu_s) <= 0.5)) {
    return make_error(Errc::kInvalidArgument, "timeshift_cam_imu must be in seconds, within +-0.5 s");
  }
  return {};
}

}  // namespace

sim::CheckerboardMotionOptions CamImuSimOptions::default_motion() {
  sim::CheckerboardMotionOptions m;
  m.duration_s = 60.0;
  return m;
}

CameraModel CamImuSimOptions::default_sim_camera() {
  // A global-shutter WVGA module (MT9V034 class) binned 2x2 to 376x240, with a wide lens:
  // about 86 x 62 deg field of view and moderate barrel distortion.
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics << 200.3, 199.8, 189.1, 117.3;
  c.distortion_coeffs << -0.2865, 0.0731, 2.1e-4, -3.4e-4;
  c.width = 376;
  c.height = 240;
  return c;
}

Eigen::Isometry3d CamImuSimOptions::default_T_cam_imu() {
  // The IMU sits on the camera board rotated by 180 deg about the optical axis (camera x = -body
  // x, camera y = -body y), with an assembly tilt of a degree or two, 3.9 cm from the optical
  // centre.
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(deg(180.0), Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(deg(1.3), Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(deg(-0.8), Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(deg(1.7), Eigen::Vector3d::UnitZ()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.0312, -0.0184, -0.0136);  // IMU origin in the camera frame, m
  return T;
}

TargetDescription CamImuSimOptions::default_sim_target() {
  // 7 x 6 inner corners (as Kalibr's example board), 5 cm squares: with the default camera and
  // motion the whole grid is in view in about 98 % of the frames.
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 7;
  t.rows = 6;
  t.col_spacing_m = 0.05;
  t.row_spacing_m = 0.05;
  return t;
}

CamImuSimCamera CamImuSimOptions::default_stereo_camera(const CameraModel& cam0,
                                                        const Eigen::Isometry3d& T_cam0_imu,
                                                        double timeshift_cam0_imu_s, double offset_s) {
  CamImuSimCamera c;
  c.camera = cam0;
  c.camera.intrinsics << cam0.intrinsics[0] * 1.021, cam0.intrinsics[1] * 1.018, cam0.intrinsics[2] - 3.7,
      cam0.intrinsics[3] + 2.2;
  if (distortion_coeff_count(cam0.distortion_model) == 4) {
    c.camera.distortion_coeffs << cam0.distortion_coeffs[0] * 0.95, cam0.distortion_coeffs[1] * 1.1, -1.4e-4,
        2.6e-4;
  } else {
    c.camera.distortion_coeffs[0] *= 0.97;  // fov's w; none has no coefficient
  }
  c.camera.projection_params *= 0.98;
  // p_cam1 = T_cam1_cam0 p_cam0: cam1 sits at +0.11 m along cam0's x axis.
  Eigen::Isometry3d T_cam1_cam0 = Eigen::Isometry3d::Identity();
  T_cam1_cam0.linear() = (Eigen::AngleAxisd(deg(0.6), Eigen::Vector3d::UnitX()) *
                          Eigen::AngleAxisd(deg(-1.1), Eigen::Vector3d::UnitY()) *
                          Eigen::AngleAxisd(deg(0.4), Eigen::Vector3d::UnitZ()))
                             .toRotationMatrix();
  T_cam1_cam0.translation() = -(T_cam1_cam0.linear() * Eigen::Vector3d(0.11, 0.0012, -0.0021));
  c.T_cam_imu = T_cam1_cam0 * T_cam0_imu;
  // A frame of cam1 stamped t shows the scene of IMU time t + shift1; the same scene as cam0's
  // frame stamped t - offset: shift1 = shift0 - offset.
  c.timeshift_cam_imu_s = timeshift_cam0_imu_s - offset_s;
  return c;
}

Status CamImuSimOptions::validate() const {
  IMUCAL_TRY(motion.validate());
  if (imu) IMUCAL_TRY(imu->validate());
  if (!(imu_rate_hz >= 4.0 && imu_rate_hz <= 8000.0)) {
    return make_error(Errc::kInvalidArgument, "IMU rate must be within 4..8000 Hz (MPU-6000 output rates)");
  }
  if (!(camera_rate_hz >= 0.5 && camera_rate_hz <= 200.0)) {
    return make_error(Errc::kInvalidArgument, "camera rate must be within 0.5..200 Hz");
  }
  const double period_ns = 1e9 / camera_rate_hz;
  if (exposure_ns <= 0 || static_cast<double>(exposure_ns) > period_ns) {
    return make_error(Errc::kInvalidArgument,
                      "camera exposure must be positive and no longer than the frame period (" +
                          std::to_string(static_cast<std::int64_t>(period_ns)) + " ns); it is given in ns");
  }
  IMUCAL_TRY(validate_camera(camera));
  IMUCAL_TRY(target.validate());
  // The renderer draws tag36h11 (libapriltag's family, 587 codes), checked here without loading it.
  constexpr int kTag36h11Codes = 587;
  if (target.type == TargetDescription::Type::kAprilgrid &&
      target.tag_cols * target.tag_rows > kTag36h11Codes) {
    return make_error(Errc::kInvalidArgument,
                      "an AprilGrid of tag36h11 has at most 587 tags (tagCols x tagRows)");
  }
  IMUCAL_TRY(check_camera_placement(T_cam_imu, timeshift_cam_imu_s));
  if (more_cameras.size() > 7)
    return make_error(Errc::kInvalidArgument, "at most 8 cameras can be simulated");
  for (const CamImuSimCamera& c : more_cameras) {
    IMUCAL_TRY(validate_camera(c.camera));
    IMUCAL_TRY(check_camera_placement(c.T_cam_imu, c.timeshift_cam_imu_s));
  }
  if (image_encoding != "png" && image_encoding != "webp") {
    return make_error(Errc::kInvalidArgument, "image encoding '" + image_encoding +
                                                  "' is not supported (use png or webp, both lossless)");
  }
  sim::CameraRenderOptions render;
  render.noise_sigma_dn = noise_sigma_dn;
  render.supersampling = supersampling;
  render.optics_blur_sigma_px = optics_blur_sigma_px;
  return render.validate();
}

CameraModel sim_camera_for(int width, int height) {
  CameraModel c = CamImuSimOptions::default_sim_camera();
  if (width == c.width && height == c.height) return c;
  const double scale = static_cast<double>(width) / c.width;
  c.intrinsics << c.intrinsics[0] * scale, c.intrinsics[1] * scale, (width - 1) / 2.0, (height - 1) / 2.0;
  c.width = width;
  c.height = height;
  return c;
}

CameraModel sim_camera_for(int width, int height, CameraModelKind model) {
  using P = ProjectionModel;
  using D = DistortionModel;
  CameraModel c = sim_camera_for(width, height);
  if (model == c.kind()) return c;
  const double scale = static_cast<double>(width) / CamImuSimOptions::default_sim_camera().width;
  c.projection = model.projection;
  c.distortion_model = model.distortion;
  c.projection_params.setZero();
  c.distortion_coeffs.setZero();
  double f = 150.0;  // at 376 px across
  if (model == CameraModelKind{P::kPinhole, D::kEquidistant}) {
    c.distortion_coeffs << 0.02, -0.01, 0.004, -0.001;
  } else if (model == CameraModelKind{P::kPinhole, D::kFov}) {
    f = 190.0;
    c.distortion_coeffs[0] = 0.9;
  } else if (model.projection == P::kOmni) {
    f = 270.0;
    c.projection_params[0] = 0.8;
    if (model.distortion == D::kRadtan) c.distortion_coeffs << -0.04, 0.008, 1e-4, -1e-4;
  } else if (model.projection == P::kEucm) {
    f = 110.0;
    c.projection_params << 0.6, 1.1;
  } else if (model.projection == P::kDs) {
    f = 110.0;
    c.projection_params << -0.15, 0.6;
  }
  c.intrinsics << f * scale, f * scale * 0.998, (width - 1) / 2.0 + 0.7, (height - 1) / 2.0 - 0.4;
  return c;
}

}  // namespace imucal::sim
