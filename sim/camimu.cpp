// SPDX-License-Identifier: BSD-3-Clause
#include "sim/camimu.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>
#include <set>
#include <vector>

#include "core/yaml_json.hpp"
#include "drivers/camera/fake/virtual_camera.hpp"
#include "sim/camera_render.hpp"
#include "sim/camera_scene.hpp"
#include "sim/motion_random.hpp"
#include "sim/session.hpp"
#include "sim/truth.hpp"

namespace imucal::sim {
namespace {

/// The frames of the session: frame k (k = 0, 1, ...) is stamped t_cam = (k0 + k) * period on
/// the camera's clock and shows the scene of IMU time t_cam + timeshift, integrated over the
/// exposure centred there. Only frames whose whole exposure lies inside the trajectory exist.
struct FramePlan {
  std::int64_t k0 = 0, k1 = -1;
  TimeNs period_ns = 0;
};

/// One camera of the session: cam0 from the options' own fields, then more_cameras.
struct SimCam {
  CameraModel camera;
  Eigen::Isometry3d T_cam_imu = Eigen::Isometry3d::Identity();
  double timeshift_cam_imu_s = 0.0;
};

std::vector<SimCam> cameras_of(const CamImuSimOptions& options) {
  std::vector<SimCam> out{{options.camera, options.T_cam_imu, options.timeshift_cam_imu_s}};
  for (const auto& c : options.more_cameras) out.push_back({c.camera, c.T_cam_imu, c.timeshift_cam_imu_s});
  return out;
}

Result<FramePlan> plan_frames(const CamImuSimOptions& options, const SimCam& cam,
                              const sim::CheckerboardMotion& traj) {
  FramePlan plan;
  const TimeNs shift_ns = s_to_ns(cam.timeshift_cam_imu_s);
  const TimeNs half_exposure_ns = options.exposure_ns / 2;
  plan.period_ns = static_cast<TimeNs>(std::llround(1e9 / options.camera_rate_hz));
  const double period = static_cast<double>(plan.period_ns);
  // A rolling shutter's rows are exposed from row_time(first row) to row_time(last row) after
  // the stamp's row: every row's exposure lies inside the trajectory.
  const Shutter& sh = cam.camera.shutter;
  const int h = cam.camera.height;
  const double rt0 = std::min(sh.row_time(0, h), sh.row_time(h - 1, h));
  const double rt1 = std::max(sh.row_time(0, h), sh.row_time(h - 1, h));
  const TimeNs t_begin = traj.start_ns() + half_exposure_ns - shift_ns - s_to_ns(rt0);  // earliest t_cam
  const TimeNs t_end = traj.end_ns() - (options.exposure_ns - half_exposure_ns) - shift_ns - s_to_ns(rt1);
  plan.k0 = static_cast<std::int64_t>(std::ceil(static_cast<double>(t_begin) / period));
  plan.k1 = static_cast<std::int64_t>(std::floor(static_cast<double>(t_end) / period));
  if (plan.k1 < plan.k0) {
    return make_error(Errc::kInvalidArgument, "camimu: the motion is too short for a single frame");
  }
  return plan;
}

SimCameraScene scene_of(const CamImuSimOptions& options, const SimCam& cam, std::size_t index,
                        TimeNs host_offset_ns) {
  SimCameraScene scene;
  scene.camera = cam.camera;
  scene.target = options.target;
  scene.T_cam_imu = cam.T_cam_imu;
  scene.timeshift_cam_imu_s = cam.timeshift_cam_imu_s;
  scene.exposure_ns = options.exposure_ns;
  scene.render.noise_sigma_dn = options.noise_sigma_dn;
  scene.render.supersampling = options.supersampling;
  scene.render.optics_blur_sigma_px = options.optics_blur_sigma_px;
  scene.motion_blur = options.motion_blur;
  // Each camera's noise of its own.
  scene.seed = options.seed + 7919 * index;
  scene.host_offset_ns = host_offset_ns;
  return scene;
}

SimSessionCamera session_camera(const CamImuSimOptions& options, const SimCam& sc, std::size_t c,
                                const FramePlan& plan, const sim::CheckerboardMotion& traj,
                                std::shared_ptr<SceneFrameSource>* source_out, const ProgressFn& progress,
                                acq::CameraAcquisitionStats* stats);

/// The IMU session's options with the virtual cameras attached (plans[c], sources[c] and
/// stats[c] for camera c, the vectors sized to the cameras).
SimImuSessionOptions session_options(const CamImuSimOptions& options, const std::vector<FramePlan>& plans,
                                     const sim::CheckerboardMotion& traj,
                                     std::vector<std::shared_ptr<SceneFrameSource>>* sources,
                                     const ProgressFn& progress,
                                     std::vector<acq::CameraAcquisitionStats>* stats) {
  SimImuSessionOptions o;
  o.kind = "camimu";
  o.script = "checkerboard";
  o.seed = options.seed;
  o.imu_rate_hz = options.imu_rate_hz;
  o.path = options.imu_path;
  o.imu = options.imu ? *options.imu : sim::ImuModelParams::draw(options.seed);
  o.params_from_file = options.imu_params_from_file;
  o.overwrite = options.overwrite;
  o.rig_camera_json = nlohmann::json{
      {"device", "sim"},
      {"model", "target renderer (simulated)"},
      {"width", options.camera.width},
      {"height", options.camera.height},
      {"rate_hz", options.camera_rate_hz},
      {"exposure_ns", options.exposure_ns},
      {"encoding", options.image_encoding},
      {"timestamp_source",
       "mid-exposure"}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  o.metadata.emplace_back("target", target_to_yaml(options.target));
  const std::vector<SimCam> cams = cameras_of(options);
  for (std::size_t c = 0; c < cams.size(); ++c) {
    o.cameras.push_back(session_camera(options, cams[c], c, plans[c], traj, &(*sources)[c],
                                       c == 0 ? progress : ProgressFn{}, &(*stats)[c]));
  }
  return o;
}

/// Camera c of the session: its virtual camera rendering the board along `traj`.
SimSessionCamera session_camera(const CamImuSimOptions& options, const SimCam& sc, std::size_t c,
                                const FramePlan& plan, const sim::CheckerboardMotion& traj,
                                std::shared_ptr<SceneFrameSource>* source_out, const ProgressFn& progress,
                                acq::CameraAcquisitionStats* stats) {
  SimSessionCamera cam;
  cam.info.name = "cam" + std::to_string(c);
  cam.info.backend = "sim";
  cam.info.device = "sim";
  cam.stream.encoding = options.image_encoding;
  cam.stream.png_level = 9;
  cam.stats_out = stats;
  const std::int64_t frames = plan.k1 - plan.k0 + 1;
  cam.make = [&options, sc, c, plan, frames, &traj, source_out, progress](
                 std::function<TimeNs()> clock,
                 TimeNs offset) -> Result<std::unique_ptr<drivers::camera::Camera>> {
    auto source = SceneFrameSource::create(scene_of(options, sc, c, offset), traj);
    if (!source.ok()) return source.error();
    *source_out = std::move(*source);
    auto render = SceneFrameSource::as_renderer(*source_out);
    drivers::camera::fake::VirtualCameraOptions vo;
    vo.width = sc.camera.width;
    vo.height = sc.camera.height;
    vo.rate_hz = options.camera_rate_hz;
    vo.exposure_ns = options.exposure_ns;
    vo.first_frame_ns = plan.k0 * plan.period_ns + offset;
    vo.frame_limit = static_cast<std::uint32_t>(frames);
    vo.clock = std::move(clock);
    auto camera = drivers::camera::fake::VirtualCamera::create(
        vo, [render, frames, progress](TimeNs t_mid, std::uint32_t k, std::span<std::uint8_t> px) {
          if (progress && k % 20 == 0) progress(static_cast<double>(k + 1) / static_cast<double>(frames));
          return render(t_mid, k, px);
        });
    if (!camera.ok()) return camera.error();
    return std::unique_ptr<drivers::camera::Camera>(std::move(*camera));
  };
  return cam;
}

/// The truth file: the IMU truth plus the camera in Kalibr camchain naming.
YAML::Node camimu_truth_yaml(const CamImuSimOptions& options, const sim::SimTruth& truth,
                             const Eigen::Isometry3d& T_world_board, const CamImuSimSummary& sum) {
  YAML::Node doc = sim::truth_to_yaml(truth);
  YAML::Node camera(YAML::NodeType::Map);
  camera["convention"] =
      "T_cam_imu maps IMU (body) points into the camera frame; t_imu = t_cam + timeshift_cam_imu; "
      "T_cn_cnm1 maps camera n-1's points into camera n's frame";
  const std::vector<SimCam> cams = cameras_of(options);
  for (std::size_t c = 0; c < cams.size(); ++c) {
    YAML::Node cam(YAML::NodeType::Map);
    cam["T_cam_imu"] = yaml_matrix_rows(cams[c].T_cam_imu.matrix());
    if (c > 0)
      cam["T_cn_cnm1"] = yaml_matrix_rows((cams[c].T_cam_imu * cams[c - 1].T_cam_imu.inverse()).matrix());
    camera_to_yaml(cams[c].camera, cam);
    cam["timeshift_cam_imu"] = cams[c].timeshift_cam_imu_s;
    // t_cam0 = t_cam + timeshift_cam_cam0 for the same scene.
    cam["timeshift_cam_cam0"] = cams[c].timeshift_cam_imu_s - cams[0].timeshift_cam_imu_s;
    cam["rate_hz"] = options.camera_rate_hz;
    cam["exposure_ns"] = options.exposure_ns;
    cam["timestamp"] = "mid-exposure";
    camera["cam" + std::to_string(c)] = cam;
  }
  camera["target"] = YAML::Load(target_to_yaml(options.target));
  camera["T_world_target"] = yaml_matrix_rows(T_world_board.matrix());
  YAML::Node render(YAML::NodeType::Map);
  render["noise_sigma_dn"] = options.noise_sigma_dn;
  render["supersampling"] = options.supersampling;
  render["optics_blur_sigma_px"] = options.optics_blur_sigma_px;
  render["motion_blur"] = options.motion_blur;
  render["encoding"] = options.image_encoding;
  camera["render"] = render;
  YAML::Node frames(YAML::NodeType::Map);
  frames["count"] = sum.frames;
  frames["all_corners_visible"] = sum.frames_all_corners_visible;
  frames["no_corner_visible"] = sum.frames_no_corner_visible;
  camera["frames"] = frames;
  doc["camera"] = camera;
  return doc;
}

}  // namespace

Status simulate_camimu_session(const CamImuSimOptions& options, const std::string& log_path,
                               const std::string& truth_path, const ProgressFn& progress,
                               CamImuSimSummary* summary) {
  IMUCAL_TRY(options.validate());
  IMUCAL_TRY(refuse_existing_outputs({log_path, truth_path}, options.overwrite));
  auto motion = sim::CheckerboardMotion::create(options.motion, options.seed);
  if (!motion.ok()) return motion.error();
  const sim::CheckerboardMotion& traj = **motion;

  const std::vector<SimCam> cams = cameras_of(options);
  std::vector<FramePlan> plans;
  for (const SimCam& c : cams) {
    auto plan = plan_frames(options, c, traj);
    if (!plan.ok()) return plan.error();
    plans.push_back(*plan);
  }
  std::vector<acq::CameraAcquisitionStats> camera_stats(cams.size());
  std::vector<std::shared_ptr<SceneFrameSource>> sources(cams.size());
  auto imu_truth = write_sim_imu_session(
      session_options(options, plans, traj, &sources, progress, &camera_stats), traj, log_path, "");
  if (!imu_truth.ok()) return imu_truth.error();
  CamImuSimSummary sum;
  sum.imu_samples = imu_truth->recording.samples;
  for (std::size_t c = 0; c < cams.size(); ++c) {
    const auto& source = sources[c];
    if (!source) return make_error(Errc::kInternal, "camimu: a camera was never built");
    const auto frames = static_cast<std::int64_t>(source->stats().frames);
    sum.frames += frames;
    sum.frames_all_corners_visible += source->stats().frames_all_points_visible;
    sum.frames_no_corner_visible += source->stats().frames_no_point_visible;
    sum.image_bytes += static_cast<std::int64_t>(camera_stats[c].stream.encoded_bytes);
    if (camera_stats[c].stream.written != static_cast<std::uint64_t>(frames)) {
      return make_error(Errc::kInternal, "camimu: " + std::to_string(frames) + " frames rendered but " +
                                             std::to_string(camera_stats[c].stream.written) + " written");
    }
  }
  const Eigen::Isometry3d T_world_board = sources[0]->T_world_target();

  const sim::SimTruth& truth = *imu_truth;
  sum.duration_s = truth.trajectory.duration_s;
  sum.mean_accel_mps2 = truth.trajectory.mean_accel_mps2;
  sum.mean_rate_radps = truth.trajectory.mean_rate_radps;
  if (!truth_path.empty()) {
    IMUCAL_TRY(sim::write_truth_yaml(truth_path, camimu_truth_yaml(options, truth, T_world_board, sum),
                                     options.overwrite));
  }
  if (progress) progress(1.0);
  if (summary) *summary = sum;
  return {};
}

}  // namespace imucal::sim
