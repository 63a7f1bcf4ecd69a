// SPDX-License-Identifier: BSD-3-Clause
// Camera-IMU calibration of a log (app/camimu_calibration.hpp): the streams, the detections
// through detect_target_in_stream (shared with the camera calibration), the estimator. Compiled
// into the camera module libimucal_camera.so.

#include "app/camimu_calibration.hpp"

#include <cmath>
#include <cstdio>

#include "app/camera_calibration.hpp"
#include "app/camera_self_check.hpp"
#include "app/camimu_self_check.hpp"
#include "app/results/thermal_results.hpp"
#include "app/streams.hpp"
#include "log/session_log.hpp"

namespace imucal::app {
namespace {

/// The held intrinsics' sigmas in Kalibr's order, from the covariance's diagonal (its layout:
/// fu fv pu pv, projection (2), distortion (4)); NaN where it gives none.
void set_intrinsics_sigmas(const CamchainCamera& cam, CamImuCameraReport* cr) {
  Eigen::Matrix<double, 10, 1> s = Eigen::Matrix<double, 10, 1>::Constant(kNotDetermined);
  if (cam.intrinsics_covariance.rows() == 10 && cam.intrinsics_covariance.cols() == 10)
    s = cam.intrinsics_covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  cr->intrinsics_sigma = kalibr_intrinsics(cam.camera.projection, s.head<4>(), s.segment<2>(4));
  cr->distortion_coeffs_sigma = kalibr_distortion(cam.camera.distortion_model, s.tail<4>());
}

/// The cameras of every camchain file, renumbered cam0..camN in the order given.
/// The target in one camera's frames, as the estimator's input and the report's figures.
Result<calib::CamImuCameraInput> detect_camera(const CamImuRequest& q, const log::SessionLogReader& reader,
                                               int index, const CamchainCamera& cam, int stream_id,
                                               CamImuReport* report) {
  const CameraStreamInfo& stream = reader.camera_streams().at(stream_id);
  if (stream.width > 0 && stream.height > 0 &&
      (stream.width != cam.camera.width || stream.height != cam.camera.height)) {
    return make_error(Errc::kInvalidArgument,
                      cam.source + " is a " + std::to_string(cam.camera.width) + " x " +
                          std::to_string(cam.camera.height) + " camera, but camera stream '" + stream.name +
                          "' holds " + std::to_string(stream.width) + " x " + std::to_string(stream.height) +
                          " frames: give the intrinsics of this camera");
  }
  StreamDetectionRequest dq;
  dq.log_path = q.log_path;
  dq.target = q.target;
  dq.detection = q.detection;
  dq.threads = q.threads;
  dq.reuse_detections = q.reuse_detections;
  dq.store_detections = q.store_detections;
  dq.cache_dir = q.cache_dir;
  dq.allow_damaged = q.allow_damaged;
  if (q.detection_progress) dq.progress = [&q, index](double f) { q.detection_progress(index, f); };
  auto found = detect_target_in_stream(reader, stream_id, dq);
  if (!found.ok()) return found.error().context(cam.name + " (" + cam.source + ")");
  report->warnings.insert(report->warnings.end(), found->warnings.begin(), found->warnings.end());

  CamImuCameraReport cr;
  cr.name = cam.name;
  cr.source = cam.source;
  cr.rostopic = cam.rostopic.empty() ? camera_rostopic(stream) : cam.rostopic;
  cr.cam_overlaps = cam.cam_overlaps;
  cr.stream = stream;
  cr.stream_id = stream_id;
  cr.frames = found->frames;
  cr.frames_with_target = found->frames_with_target;
  cr.detection_key = found->key;
  cr.detections_reused_from = found->reused_from;
  cr.detections_stored_in = found->stored_in;
  cr.detection_wall_s = found->wall_s;
  set_intrinsics_sigmas(cam, &cr);
  report->cameras.push_back(cr);

  calib::CamImuCameraInput in;
  in.name = cam.name;
  in.stream = stream.name;
  in.camera = cam.camera;
  const auto [note, warning] =
      stamp_row_from_stream(stream, cam.stamp_row_given, cam.name, &in.camera.shutter);
  if (!note.empty()) report->notes.push_back(note);
  if (!warning.empty()) report->warnings.push_back(warning);
  in.intrinsics_covariance = cam.intrinsics_covariance;
  in.intrinsics_covariance_source = cam.intrinsics_covariance_source;
  for (auto& o : found->observations) {
    if (!o.empty()) in.observations.push_back(std::move(o));
  }
  return in;
}

/// The IMU noise, the priors and the fixed blocks on top of the request's options.
Status prepare_options(const CamImuRequest& q, CamImuReport* report) {
  report->options = q.options;
  if (q.imu_noise) {
    report->options.noise = *q.imu_noise;
    report->noise_source = q.imu_noise_source;
  } else {
    report->options.noise = calib::CamImuNoise{};
    report->noise_source = "defaults (MPU-6000 datasheet)";
    report->notes.push_back(
        "no IMU noise given: the MPU-6000 datasheet figures weight the IMU residuals (measure yours with "
        "imucal allan and pass --imu)");
  }
  auto prior = imu_prior(q.imu_intrinsics, q.gsens, report->imu_stream);
  if (!prior.ok()) return prior.error();
  if (prior->init) report->options.imu_init = prior->init;
  report->options.fixed = merge_fixed(q.options.fixed, prior->fixed);
  report->notes.insert(report->notes.end(), prior->notes.begin(), prior->notes.end());
  if (q.imu_intrinsics) report->imu_intrinsics_source = q.imu_intrinsics->path;
  if (q.gsens) report->gsens_source = q.gsens->path;
  if (report->options.threads == 0) report->options.threads = q.threads;
  // Camera-camera extrinsics from a camera chain, where the chain gives their covariance.
  for (std::size_t i = 1; i < q.cameras.size(); ++i) {
    const CamchainCamera& cam = q.cameras[i];
    if (!cam.follows_in_file || !cam.T_cn_cnm1) continue;
    if (!cam.T_cn_cnm1_covariance) {
      report->notes.push_back(cam.source + ": its T_cn_cnm1 comes without a covariance, so it is not used; " +
                              cam.name +
                              " is placed through the IMU alone (imucal calibrate camera with both "
                              "cameras gives the chain with its covariance)");
      continue;
    }
    calib::CamImuChainPrior prior;
    prior.camera = static_cast<int>(i);
    prior.T_cn_cnm1 = *cam.T_cn_cnm1;
    prior.covariance = *cam.T_cn_cnm1_covariance;
    prior.source = cam.source;
    report->options.chain_priors.push_back(prior);
    report->notes.push_back(cam.name + "'s pose relative to " + q.cameras[i - 1].name +
                            " enters from the camera chain in " + cam.source +
                            " as a prior with its covariance");
  }
  return {};
}

/// Where the parts disagree on a camera's extrinsics and time offset beyond chance (their
/// chi-square's probability below 5 %), that camera's sigmas are scaled by sqrt(chi-square / dof):
/// the spread of the parts is then what the sigmas promise (docs/camimu-calibration.md,
/// "Uncertainty and quality").
void scale_by_self_check(CamImuCalibrationResult* r, std::vector<std::string>* notes) {
  for (CamImuCameraResult& c : r->cameras) {
    const double k = split_scale(&r->self_check, c.name + " ", c.name, notes);
    // The parts were compared without the held intrinsics' share (they share the intrinsics):
    // only the rest is scaled.
    const auto scale = [k](Eigen::Vector3d* s, const Eigen::Vector3d& held) {
      for (int a = 0; a < 3; ++a) {
        const double h2 = std::isfinite(held(a)) ? held(a) * held(a) : 0.0;
        (*s)(a) = std::sqrt(k * k * std::max((*s)(a) * (*s)(a)-h2, 0.0) + h2);
      }
    };
    scale(&c.rotation_sigma_rad, c.rotation_sigma_from_intrinsics_rad);
    scale(&c.translation_sigma_m, c.translation_sigma_from_intrinsics_m);
    c.timeshift_sigma_s *= k;
    c.line_delay_sigma_s *= k;
  }
}

/// With a static calibration held (--imu-intrinsics, the service's static result), the body
/// frame is the one its accelerometer axes define, and its error is every camera's rotation
/// error too: its covariance (held_axes_covariance) is added to each camera's rotation sigma.
void add_held_axes(const CamImuRequest& q, CamImuReport* report) {
  if (!q.imu_intrinsics || !report->options.fixed.C_bg) return;
  if (!q.imu_intrinsics->spread) {
    report->notes.push_back(
        q.imu_intrinsics->path +
        " gives no sigmas of its scales and misalignments: the cameras' rotation sigmas leave "
        "out the uncertainty of the IMU axes it holds");
    return;
  }
  const Eigen::Matrix3d body = held_axes_covariance(*q.imu_intrinsics->spread);
  for (CamImuCameraResult& c : report->result.cameras) {
    const Eigen::Matrix3d R = c.T_cam_imu.linear();
    const Eigen::Matrix3d cam = R * body * R.transpose();
    for (int a = 0; a < 3; ++a)
      c.rotation_sigma_rad(a) = std::sqrt(c.rotation_sigma_rad(a) * c.rotation_sigma_rad(a) + cam(a, a));
  }
  char text[400];
  std::snprintf(
      text, sizeof text,
      "the cameras' rotation sigmas include the uncertainty of the IMU axes that %s holds (its scales' "
      "and misalignments' sigmas: %.4f, %.4f, %.4f deg about the body axes)",
      q.imu_intrinsics->path.c_str(), std::sqrt(body(0, 0)) * 180.0 / M_PI,
      std::sqrt(body(1, 1)) * 180.0 / M_PI, std::sqrt(body(2, 2)) * 180.0 / M_PI);
  report->notes.emplace_back(text);
}

}  // namespace

Result<CamImuReport> calibrate_camimu_log(const CamImuRequest& q) {
  IMUCAL_TRY(q.target.validate());
  CamImuReport report;
  report.log_path = q.shown_log();
  report.target = q.target;
  report.target_source = q.target_source;
  report.gravity_source = q.gravity_source;
  if (q.cameras.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no camera given: the camera-IMU calibration needs each camera's intrinsics (the YAML "
                      "of imucal calibrate camera, or a Kalibr camchain)")
        .with_remedy("camera");
  }
  const std::vector<CamchainCamera>* cams = &q.cameras;

  std::string imu_stream = q.imu_stream;
  if (imu_stream.empty() && !q.imu_rostopic.empty()) {
    // The --imu file's topic chooses among a bag's IMU streams, as Kalibr's does.
    if (auto log = log::SessionLogReader::open(q.log_path); log.ok()) {
      imu_stream = imu_stream_of_topic((*log)->imu_streams(), q.imu_rostopic);
    }
  }
  auto loaded =
      load_imu_stream(q.log_path, imu_stream, q.allow_damaged ? DamagePolicy::kAllow : DamagePolicy::kRefuse);
  if (!loaded.ok()) return loaded.error();
  if (loaded->damaged())
    report.warnings.push_back(loaded->damage_warning() + ": calibrated from its readable part only");
  const auto& reader = *loaded->reader;
  report.imu_stream = loaded->info;
  report.imu_rostopic = q.imu_rostopic.empty() ? imu_rostopic(loaded->info) : q.imu_rostopic;
  report.imu_update_rate = q.imu_update_rate > 0.0 ? q.imu_update_rate : loaded->info.rate_hz;
  if (auto it = reader.metadata().find("software_version"); it != reader.metadata().end())
    report.log_software_version = it->second;
  IMUCAL_TRY(prepare_options(q, &report));

  auto ids = match_camera_streams(*cams, reader.camera_streams());
  if (!ids.ok()) return ids.error().with_remedy("camera");
  std::vector<calib::CamImuCameraInput> inputs;
  for (std::size_t i = 0; i < cams->size(); ++i) {
    auto in = detect_camera(q, reader, static_cast<int>(i), (*cams)[i], (*ids)[i], &report);
    if (!in.ok()) return in.error();
    inputs.push_back(std::move(*in));
  }

  // With a thermal model the solve sees a copy corrected to its reference temperature.
  std::vector<ImuSample> corrected;
  if (q.thermal) {
    corrected = loaded->samples;
    auto applied = apply_thermal_file(*q.thermal, corrected, loaded->info);
    if (!applied.ok()) return applied.error().with_remedy("thermal");
    report.thermal = applied->model;
    report.thermal_source = q.thermal->path;
    report.warnings.insert(report.warnings.end(), applied->warnings.begin(), applied->warnings.end());
  }
  std::size_t saturated = 0;
  const auto samples = camimu_samples(report.thermal ? corrected : loaded->samples, loaded->info, &saturated);
  report.imu_samples = samples.size();
  if (saturated > 0) {
    report.warnings.push_back(std::to_string(saturated) +
                              " saturated IMU samples left out: the motion exceeded the sensor's range");
  }
  auto result = calib::calibrate_camimu(samples, inputs, q.target, report.options, q.solve_progress);
  if (!result.ok()) return result.error().context("camera-IMU calibration of " + q.shown_log());
  report.result = std::move(*result);
  if (q.self_check_parts >= 2) {
    if (q.solve_progress) q.solve_progress({"self-check", q.self_check_parts, 0.0, 0.0});
    report.result.self_check = camimu_self_check(samples, inputs, q.target, report.options, report.result,
                                                 q.self_check_parts, report.options.threads);
    scale_by_self_check(&report.result, &report.notes);
    const SplitCheck& sc = report.result.self_check;
    if (sc.verdict == SplitCheck::Verdict::kDisagree)
      report.result.warnings.push_back("self-check: " + sc.summary + "; " + sc.advice);
    else if (sc.verdict == SplitCheck::Verdict::kNotDetermined)
      report.notes.push_back(sc.summary);
  }
  add_held_axes(q, &report);
  report.warnings.insert(report.warnings.end(), report.result.warnings.begin(), report.result.warnings.end());
  return report;
}

}  // namespace imucal::app
