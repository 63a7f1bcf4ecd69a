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

#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "sim/camera_render.hpp"
#include "sim/motion_random.hpp"
#include "sim/session.hpp"
#include "sim/truth.hpp"

namespace imucal::sim {
namespace {

/// A rendered 8-bit gray image, losslessly encoded as the log stores frames (log/frame_codec.hpp:
/// WebP lossless, or PNG at the highest compression).
Result<std::vector<std::uint8_t>> encode_frame(const cv::Mat& gray, const std::string& encoding) {
  log::Image image = log::Image::zeros(gray.cols, gray.rows, 1, 8);
  for (int r = 0; r < gray.rows; ++r) {
    std::memcpy(image.data.data() + static_cast<std::size_t>(r) * image.row_bytes(),
                gray.ptr<std::uint8_t>(r), image.row_bytes());
  }
  return encoding == "png" ? log::encode_png(image, 9) : log::encode_webp_lossless(image);
}

constexpr std::uint64_t kNoiseSubstream = 0xCA3E7A;  // camera noise stream, independent of the IMU's

YAML::Node matrix_yaml(const Eigen::Matrix4d& m) {
  YAML::Node rows(YAML::NodeType::Sequence);
  for (int r = 0; r < 4; ++r) {
    YAML::Node row(YAML::NodeType::Sequence);
    for (int c = 0; c < 4; ++c) row.push_back(m(r, c));
    row.SetStyle(YAML::EmitterStyle::Flow);
    rows.push_back(row);
  }
  return rows;
}

Eigen::Isometry3d pose_of(const sim::RigState& s) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = s.q_world_body.toRotationMatrix();
  T.translation() = s.p_world_body;
  return T;
}

void remove_log_files(const std::string& path) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(path + suffix, ec);
}

/// Copies metadata, the IMU stream and the events of the IMU-only log into `writer`.
Status copy_imu_part(const log::SessionLogReader& reader, log::SessionLogWriter& writer,
                     const nlohmann::json& camera_rig, std::int64_t* samples) {
  static const std::set<std::string> kWriterKeys = {"schema_version", "software_version", "created_utc",
                                                    "complete"};
  for (const auto& [key, value] : reader.metadata()) {
    if (kWriterKeys.count(key) != 0) continue;
    if (key == "rig_config") {
      nlohmann::json rig = nlohmann::json::parse(value, nullptr, false);
      if (rig.is_discarded() || !rig.is_object()) rig = nlohmann::json::object();
      rig["camera"] = camera_rig;
      IMUCAL_TRY(writer.set_metadata(key, rig.dump()));
    } else {
      IMUCAL_TRY(writer.set_metadata(key, value));
    }
  }
  if (reader.metadata().count("rig_config") == 0) {
    IMUCAL_TRY(writer.set_metadata("rig_config", nlohmann::json{{"camera", camera_rig}}.dump()));
  }
  for (const auto& [id, info] : reader.imu_streams()) {
    auto out_id = writer.add_imu_stream(info);
    if (!out_id.ok()) return out_id.error();
    std::vector<ImuSample> batch;
    batch.reserve(4096);
    Status status;
    auto visited = reader.for_each_imu(id, log::kTimeMin, log::kTimeMax, [&](const ImuSample& s) {
      batch.push_back(s);
      ++*samples;
      if (batch.size() == 4096) {
        status = writer.append_imu(*out_id, batch);
        batch.clear();
        return status.ok();
      }
      return true;
    });
    IMUCAL_TRY(status);
    IMUCAL_TRY(visited);
    if (!batch.empty()) IMUCAL_TRY(writer.append_imu(*out_id, batch));
  }
  auto events = reader.events();
  if (!events.ok()) return events.error();
  for (const log::Event& e : *events) IMUCAL_TRY(writer.append_event(e));
  return {};
}

}  // namespace

namespace {

constexpr double kImuShare = 0.05;  // of the progress: the IMU part is quick next to rendering

/// The IMU part, through the same code as the other simulated sessions, into the scratch log
/// `imu_part` (removed again on failure).
Result<sim::SimTruth> write_imu_part(const CamImuSimOptions& options, const sim::CheckerboardMotion& traj,
                                     const std::string& imu_part, const ProgressFn& progress) {
  SimImuSessionOptions imu_opt;
  imu_opt.kind = "camimu";
  imu_opt.script = "checkerboard";
  imu_opt.seed = options.seed;
  imu_opt.imu_rate_hz = options.imu_rate_hz;
  imu_opt.path = options.imu_path;
  imu_opt.imu = options.imu ? *options.imu : sim::ImuModelParams::draw(options.seed);
  imu_opt.params_from_file = options.imu_params_from_file;
  imu_opt.overwrite = true;
  remove_log_files(imu_part);
  auto imu_truth = write_sim_imu_session(imu_opt, traj, imu_part, "", [&](double f) {
    if (progress) progress(kImuShare * f);
  });
  if (!imu_truth.ok()) {
    remove_log_files(imu_part);
    return imu_truth.error().context("camimu IMU part");
  }
  return imu_truth;
}

/// Renders the frames and appends them to camera stream `cam_id`. Frame k is stamped
/// t_cam = k * period on the camera's clock and shows the scene of IMU time t_cam + timeshift,
/// integrated over the exposure centred there. Only frames whose whole exposure lies inside the
/// trajectory are recorded.
Status write_frames(const CamImuSimOptions& options, const sim::CheckerboardMotion& traj,
                    const sim::CheckerboardRenderer& renderer, const Eigen::Isometry3d& T_world_board,
                    log::SessionLogWriter& writer, int cam_id, CamImuSimSummary& sum,
                    const ProgressFn& progress) {
  const TimeNs shift_ns = s_to_ns(options.timeshift_cam_imu_s);
  const TimeNs half_exposure_ns = options.exposure_ns / 2;
  const double period_ns = 1e9 / options.camera_rate_hz;
  const TimeNs t_begin = traj.start_ns() + half_exposure_ns - shift_ns;  // earliest t_cam
  const TimeNs t_end = traj.end_ns() - (options.exposure_ns - half_exposure_ns) - shift_ns;
  const std::int64_t k0 = static_cast<std::int64_t>(std::ceil(static_cast<double>(t_begin) / period_ns));
  const std::int64_t k1 = static_cast<std::int64_t>(std::floor(static_cast<double>(t_end) / period_ns));
  if (k1 < k0) {
    return make_error(Errc::kInvalidArgument, "camimu: the motion is too short for a single frame");
  }
  auto T_cam_board_at = [&](TimeNs t_imu_ns) {
    return options.T_cam_imu * pose_of(traj.at(t_imu_ns)).inverse() * T_world_board;
  };
  sim::Rng noise(sim::Rng::substream(options.seed, kNoiseSubstream));
  std::vector<Eigen::Isometry3d> subs;
  for (std::int64_t k = k0; k <= k1; ++k) {
    const TimeNs t_cam = static_cast<TimeNs>(std::llround(static_cast<double>(k) * period_ns));
    const TimeNs t_open = t_cam + shift_ns - half_exposure_ns;  // IMU time the exposure starts
    int n_sub = 1;
    if (options.motion_blur) {
      n_sub =
          renderer.sub_exposures_needed(T_cam_board_at(t_open), T_cam_board_at(t_open + options.exposure_ns));
    }
    subs.clear();
    for (int i = 0; i < n_sub; ++i) {
      const double f = options.motion_blur ? (i + 0.5) / n_sub : 0.5;
      subs.push_back(T_cam_board_at(t_open + static_cast<TimeNs>(std::llround(f * options.exposure_ns))));
    }
    const cv::Mat image = renderer.render(subs, &noise);
    const sim::CornerTruth truth = renderer.project_corners(T_cam_board_at(t_cam + shift_ns));
    if (truth.visible_count == static_cast<int>(truth.px.size())) ++sum.frames_all_corners_visible;
    if (truth.visible_count == 0) ++sum.frames_no_corner_visible;

    CameraFrame frame;
    frame.t_ns = t_cam;
    frame.width = image.cols;
    frame.height = image.rows;
    frame.encoding = options.image_encoding;
    frame.exposure_ns = options.exposure_ns;
    frame.sequence = static_cast<std::uint32_t>(k - k0);
    auto encoded = encode_frame(image, options.image_encoding);
    if (!encoded.ok()) return encoded.error().context("camimu: encoding frame " + std::to_string(k - k0));
    frame.data = std::move(*encoded);
    sum.image_bytes += static_cast<std::int64_t>(frame.data.size());
    IMUCAL_TRY(writer.append_frame(cam_id, frame));
    ++sum.frames;
    if (progress && (k - k0) % 20 == 0) {
      progress(kImuShare +
               (1.0 - kImuShare) * static_cast<double>(k - k0 + 1) / static_cast<double>(k1 - k0 + 1));
    }
  }
  return {};
}

/// The final log: the IMU part copied from `imu_part`, the target and the camera stream.
Status write_camimu_log(const CamImuSimOptions& options, const sim::CheckerboardMotion& traj,
                        const sim::CheckerboardRenderer& renderer, const Eigen::Isometry3d& T_world_board,
                        const std::string& imu_part, const std::string& log_path, CamImuSimSummary& sum,
                        const ProgressFn& progress) {
  nlohmann::json camera_rig = {{"device", "sim"},
                               {"model", "target renderer (simulated)"},
                               {"width", options.camera.width},
                               {"height", options.camera.height},
                               {"rate_hz", options.camera_rate_hz},
                               {"exposure_ns", options.exposure_ns},
                               {"encoding", options.image_encoding},
                               {"timestamp_source", "mid-exposure"}};
  log::SessionLogWriterOptions wopt;
  wopt.overwrite = options.overwrite;
  wopt.commit_interval_ns = 5 * kNsPerSecond;
  auto reader = log::SessionLogReader::open(imu_part);
  if (!reader.ok()) return reader.error().context("camimu IMU part");
  auto writer_r = log::SessionLogWriter::create(log_path, wopt);
  if (!writer_r.ok()) return writer_r.error();
  log::SessionLogWriter& writer = **writer_r;
  IMUCAL_TRY(copy_imu_part(**reader, writer, camera_rig, &sum.imu_samples));
  IMUCAL_TRY(writer.set_metadata("target", target_to_yaml(options.target)));

  CameraStreamInfo cam_info;
  cam_info.name = "cam0";
  cam_info.width = options.camera.width;
  cam_info.height = options.camera.height;
  cam_info.rate_hz = options.camera_rate_hz;
  cam_info.backend = "sim";
  cam_info.device = "sim";
  cam_info.timestamp_source = "mid-exposure";
  auto cam_id = writer.add_camera_stream(cam_info);
  if (!cam_id.ok()) return cam_id.error();
  IMUCAL_TRY(write_frames(options, traj, renderer, T_world_board, writer, *cam_id, sum, progress));
  return writer.close();
}

/// The truth file: the IMU truth plus the camera in Kalibr camchain naming.
YAML::Node camimu_truth_yaml(const CamImuSimOptions& options, const sim::SimTruth& truth,
                             const Eigen::Isometry3d& T_world_board, const CamImuSimSummary& sum) {
  YAML::Node doc = sim::truth_to_yaml(truth);
  YAML::Node cam0(YAML::NodeType::Map);
  cam0["T_cam_imu"] = matrix_yaml(options.T_cam_imu.matrix());
  camera_to_yaml(options.camera, cam0);
  cam0["timeshift_cam_imu"] = options.timeshift_cam_imu_s;
  cam0["rate_hz"] = options.camera_rate_hz;
  cam0["exposure_ns"] = options.exposure_ns;
  cam0["timestamp"] = "mid-exposure";
  YAML::Node camera(YAML::NodeType::Map);
  camera["convention"] =
      "T_cam_imu maps IMU (body) points into the camera frame; t_imu = t_cam + timeshift_cam_imu";
  camera["cam0"] = cam0;
  camera["target"] = YAML::Load(target_to_yaml(options.target));
  camera["T_world_target"] = matrix_yaml(T_world_board.matrix());
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

  sim::CameraRenderOptions render_opt;
  render_opt.noise_sigma_dn = options.noise_sigma_dn;
  render_opt.supersampling = options.supersampling;
  render_opt.optics_blur_sigma_px = options.optics_blur_sigma_px;
  auto renderer_r = sim::CheckerboardRenderer::create(options.camera, options.target, render_opt);
  if (!renderer_r.ok()) return renderer_r.error();
  const sim::CheckerboardRenderer& renderer = **renderer_r;

  // The IMU part goes into a scratch log next to the output first; the final log copies it and
  // adds the camera stream.
  const std::string imu_part = log_path + ".imu-part";
  auto imu_truth = write_imu_part(options, traj, imu_part, progress);
  if (!imu_truth.ok()) return imu_truth.error();
  const Eigen::Isometry3d T_world_board = traj.T_world_board(options.target);
  CamImuSimSummary sum;
  const Status status =
      write_camimu_log(options, traj, renderer, T_world_board, imu_part, log_path, sum, progress);
  remove_log_files(imu_part);
  if (!status.ok()) return status;

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
