// SPDX-License-Identifier: BSD-3-Clause
#include "app/session/session_runner.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>

#include "acquisition/camera_stream.hpp"
#include "app/calibration_check.hpp"
#include "app/report/report.hpp"
#include "app/results/camera_results.hpp"
#include "app/results/camimu_results.hpp"
#include "app/results/output.hpp"
#include "app/results/static_results.hpp"
#include "app/results/thermal_results.hpp"
#include "app/rig/stored_calibration.hpp"
#include "app/solvers.hpp"
#include "calib/target_detection.hpp"
#include "core/text_format.hpp"
#include "core/version.hpp"
#include "log/session_log.hpp"
#include "log/target_detections.hpp"

namespace imucal::app::session {

using nlohmann::json;

namespace {

/// <rig>-YYYYmmddTHHMMSSZ, with -2, -3, ... when it exists already.
Result<std::string> make_session_dir(const std::string& state_dir, const std::string& rig) {
  const std::string stamp = utc_now("%Y%m%dT%H%M%SZ");
  const std::filesystem::path base = std::filesystem::path(state_dir) / "sessions";
  std::error_code ec;
  std::filesystem::create_directories(base, ec);
  if (ec) {
    return make_error(Errc::kIo, "cannot create " + base.string() + ": " + ec.message() +
                                     " (check --state-dir and that the service may write there)");
  }
  for (int n = 1; n < 1000; ++n) {
    std::string name = rig + "-" + stamp + (n > 1 ? "-" + std::to_string(n) : "");
    const auto dir = base / name;
    if (std::filesystem::create_directory(dir, ec)) return dir.string();
    if (ec) return make_error(Errc::kIo, "cannot create " + dir.string() + ": " + ec.message());
  }
  return make_error(Errc::kAlreadyExists,
                    "too many sessions named " + rig + "-" + stamp + " in " + base.string());
}

}  // namespace

static SolveOutcome run_solve_timed(const SolveJob& job, const RigConfig& config, const ImuStreamInfo& info,
                                    const std::string& dir,
                                    const std::function<void(double, const std::string&)>& progress,
                                    const MotionLogSource& motion_log);

SolveOutcome run_solve(const SolveJob& job, const RigConfig& config, const ImuStreamInfo& info,
                       const std::string& dir,
                       const std::function<void(double, const std::string&)>& progress,
                       const MotionLogSource& motion_log) {
  const auto t0 = std::chrono::steady_clock::now();
  SolveOutcome out = run_solve_timed(job, config, info, dir, progress, motion_log);
  out.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

/// The cameras of a rig with several: one joint solve of every camera's intrinsics, their poses
/// relative to each other and their time offsets (calibrate_camera_chain), written as
/// camera-NAME.yaml per camera and the chain as cameras-chain.yaml; each camera enters the
/// camera-IMU request with T_cn_cnm1 and its covariance, which that solve takes as a prior. The
/// halves of the recording are calibrated apart as `calibrate camera` does (app/camera_self_check.hpp):
/// where they spread beyond their sigmas, the sigmas (and the covariances passed on) are scaled;
/// the check goes to `check` for the review.
static Status solve_camera_chain(const RigConfig& config, const std::string& dir, const std::string& log,
                                 const MotionLogSource& source,
                                 const std::function<void(double, const std::string&)>& progress,
                                 CamImuRequest* q, std::vector<std::string>* files, SplitCheck* check) {
  if (progress) progress(0.2, "Camera intrinsics and the camera chain");
  CameraChainRequest cq;
  cq.base.log_path = log;
  cq.base.target = *config.target;
  cq.base.target_source = q->target_source;
  cq.base.threads = 2;
  cq.base.store_detections = source.store_detections;
  bool any_rolling = false;
  for (const CameraConfig& c : config.cameras) {
    cq.cameras.push_back(c.name);
    cq.models.push_back(CameraModelKind{ProjectionModel::kPinhole, DistortionModel::kRadtan});
    cq.shutters.push_back(c.shutter);
    any_rolling = any_rolling || c.shutter.rolling();
  }
  // Global cameras as configured: the global model only; a rolling one declared: the evidence.
  cq.chain.shutter.mode =
      any_rolling ? calib::ShutterSolveOptions::Mode::kAuto : calib::ShutterSolveOptions::Mode::kGlobal;
  // One solver thread: with two the order in which Ceres sums the cost varies from run to run,
  // which moves the point where a solve stops by a step and then which corners are rejected, so
  // that a replay of the session would not give the same chain (measured: 2 threads 14 s, 1 thread
  // 21 s on the demo's 60 s; the detection keeps both cores). The same for the single-camera
  // solves that start each camera.
  cq.chain.threads = 1;
  cq.base.intrinsics.threads = 1;
  // Measured over the demo's 10 seeds (docs/camera-calibration.md, "Self-check"): without it 8 of
  // the chain's 210 figures were beyond 3.5 sigmas, with it 2.
  cq.base.self_check_parts = 2;
  auto chain = calibrate_camera_chain(cq);
  if (!chain.ok()) return chain.error().context("camera chain");
  *check = chain->self_check;
  for (std::size_t c = 0; c < chain->cameras.size(); ++c) {
    const CameraCalibrationReport& cam = chain->cameras[c];
    files->push_back(dir + "/camera-" + config.cameras[c].name + ".yaml");
    IMUCAL_TRY(write_text_file(files->back(), camera_result_yaml(cam)));
    CamchainCamera intrinsics;
    intrinsics.name = "cam" + std::to_string(c);
    intrinsics.source = files->back() + " cam0";
    intrinsics.camera = cam.intrinsics.camera;
    intrinsics.camera_stream = cam.stream.name;
    intrinsics.rostopic = "/" + cam.stream.name + "/image_raw";
    set_intrinsics_covariance(cam.intrinsics, &intrinsics);
    if (c > 0) {
      intrinsics.T_cn_cnm1 = chain->chain.cameras[c].T_cn_cnm1;
      intrinsics.T_cn_cnm1_covariance = chain->chain.cameras[c].T_cn_cnm1_covariance;
      intrinsics.follows_in_file = true;
    }
    q->cameras.push_back(std::move(intrinsics));
  }
  files->push_back(dir + "/cameras-chain.yaml");
  return write_text_file(files->back(), camera_chain_yaml(*chain, cq.chain.min_shared_views));
}

/// The camera-IMU part of a final solve: each camera's intrinsics from the motion log's frames,
/// then the camera-IMU calibration with the static result (out.imu, written to `static_yaml`)
/// as the IMU's prior. Returns the result files (camera-<name>.yaml, camimu/...), the canonical
/// one last.
static Result<std::vector<std::string>> solve_camimu(
    const RigConfig& config, const std::string& dir, const std::string& static_yaml,
    const ImuStreamInfo& info, const MotionLogSource& source, const std::optional<ThermalFile>& thermal,
    SolveOutcome& out, const std::function<void(double, const std::string&)>& progress) {
  const std::string log = source.path.empty() ? dir + "/" + kMotionLogFile : source.path;
  if (!config.target) return make_error(Errc::kInvalidArgument, "the configuration names no target");
  std::vector<std::string> files;
  CamImuRequest q;
  q.log_path = log;
  q.target = *config.target;
  q.target_source = "the rig configuration";
  q.store_detections = source.store_detections;
  q.thermal = thermal;  // the session's model: the camimu samples corrected as the static ones
  if (config.cameras.size() >= 2) {
    IMUCAL_TRY(solve_camera_chain(config, dir, log, source, progress, &q, &files, &out.chain_self_check));
  }
  for (std::size_t i = 0; i < config.cameras.size() && config.cameras.size() < 2; ++i) {
    const std::string& name = config.cameras[i].name;
    if (progress)
      progress(0.2 + 0.2 * static_cast<double>(i) / static_cast<double>(config.cameras.size()),
               "Camera intrinsics of " + name);
    CameraCalibrationRequest cq;
    cq.log_path = log;
    cq.camera = name;
    cq.target = *config.target;
    cq.target_source = q.target_source;
    cq.threads = 2;
    cq.store_detections = source.store_detections;
    // A rolling shutter the configuration declares: its line delay held when given, else
    // estimated on the trajectory (docs/config.md); a global one as always.
    const Shutter& shutter = config.cameras[i].shutter;
    cq.known_shutter = shutter;
    cq.known_stamp_row = shutter.rolling();  // the configuration's rolling camera names its row
    if (shutter.rolling()) {
      cq.shutter.mode = calib::ShutterSolveOptions::Mode::kRolling;
      if (shutter.line_delay_s > 0.0) cq.shutter.line_delay_s = shutter.line_delay_s;
    }
    auto cam = calibrate_camera(cq);
    if (!cam.ok()) return cam.error().context(name + " intrinsics");
    const std::string path = dir + "/camera-" + name + ".yaml";
    IMUCAL_TRY(write_text_file(path, camera_result_yaml(*cam)));
    files.push_back(path);
    CamchainCamera intrinsics;
    intrinsics.name = "cam" + std::to_string(q.cameras.size());
    intrinsics.source = path + " cam0";
    intrinsics.camera = cam->intrinsics.camera;
    intrinsics.camera_stream = cam->stream.name;
    intrinsics.rostopic = "/" + cam->stream.name + "/image_raw";
    set_intrinsics_covariance(cam->intrinsics, &intrinsics);
    q.cameras.push_back(std::move(intrinsics));
  }
  // The static result as the IMU's prior, as solved (its file names it in the report).
  NamedCalibration prior;
  prior.name = std::filesystem::path(static_yaml).filename().string();
  prior.format = "imucal";
  prior.path = static_yaml;
  prior.model = out.imu->canonical;
  prior.input_units = info.units;
  prior.spread = NamedCalibration::Spread{out.imu->model.accel, out.imu->model.gyro, out.imu->accel_sigma,
                                          out.imu->gyro_sigma};
  q.imu_intrinsics = std::move(prior);
  q.gravity_source = "standard gravity";
  q.threads = 2;
  q.options.threads = 2;
  // Global cameras only: the global model, as always. With a rolling shutter declared each camera
  // enters with the shutter its intrinsics were solved with, and the evidence decides again with
  // the IMU (kAuto: the line delays freed together); a single camera's configured line delay is held.
  const bool any_rolling = std::any_of(config.cameras.begin(), config.cameras.end(),
                                       [](const CameraConfig& c) { return c.shutter.rolling(); });
  q.options.shutter.mode =
      any_rolling ? calib::ShutterSolveOptions::Mode::kAuto : calib::ShutterSolveOptions::Mode::kGlobal;
  if (config.cameras.size() == 1 && config.cameras[0].shutter.rolling() &&
      config.cameras[0].shutter.line_delay_s > 0.0)
    q.options.shutter.line_delay_s = config.cameras[0].shutter.line_delay_s;
  q.solve_progress = [&progress](const calib::CamImuIteration& it) {
    if (progress) progress(0.5, "Camera-IMU " + it.stage + ": iteration " + std::to_string(it.iteration));
  };
  if (progress) progress(0.45, "Camera-IMU calibration");
  auto report = calibrate_camimu(q);
  if (!report.ok()) return report.error().context("camera-IMU calibration");
  const std::string out_dir = dir + "/camimu";
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) return make_error(Errc::kIo, "cannot create " + out_dir + ": " + ec.message());
  const std::pair<const char*, std::string> texts[] = {
      {kCamchainImucamFile, camimu_camchain_yaml(*report)},
      {kCamImuImuFile, camimu_imu_input_yaml(*report)},
      {kCamImuImuResultFile, camimu_imu_yaml(*report)},
      {kCamImuJsonFile, camimu_result_json(*report)},
      {kCamImuCalibrationFile, camimu_calibration_yaml(*report)}};
  for (const auto& [name, text] : texts) {
    files.push_back(out_dir + "/" + name);
    IMUCAL_TRY(write_text_file(files.back(), text));
  }
  out.camimu = std::move(*report);
  return files;
}

/// The thermal model of a session's thermal recording (SolveJob::thermal_samples, SI means),
/// into out.thermal; a fit that cannot be made (the rig moved, too small a span) is a result not
/// determined, with the reason, and the session goes on without the correction. When determined
/// it is written to <dir>/thermal.yaml (the `calibrate thermal` format) and returned as that file.
static Result<std::optional<ThermalFile>> solve_thermal(const SolveJob& job, const RigConfig& config,
                                                        const ImuStreamInfo& info, const std::string& dir,
                                                        SolveOutcome& out) {
  calib::ThermalOptions options;  // the means are in SI units and deg C already
  options.min_span_c = config.session.thermal_min_span_c;
  // Bins of 20 s from 800 s of recording on; a shorter recording (the operator ended it) gets
  // shorter bins, down to 2 s, so that it still has 40.
  const auto& means = *job.thermal_samples;
  const double duration_s = ns_to_s(means.back().t_ns - means.front().t_ns);
  options.bin_s = std::clamp(duration_s / 40.0, 2.0, 20.0);
  auto fit = calib::calibrate_thermal(means, options);
  if (!fit.ok()) {
    calib::ThermalResult failed;
    failed.reason = fit.error().message;
    out.thermal = std::move(failed);
    return std::optional<ThermalFile>();
  }
  out.thermal = std::move(*fit);
  if (!out.thermal->determined) return std::optional<ThermalFile>();
  ThermalFile file;
  file.path = dir + "/thermal.yaml";
  file.log = dir + "/session.imulog";
  file.stream = info.name;
  file.input_units = imu_units_name(info.units);
  file.result = *out.thermal;
  file.model = calib::thermal_model(file.result);
  IMUCAL_TRY(write_text_file(file.path, thermal_result_yaml(*out.thermal, info, file.log)));
  out.result_files.push_back(file.path);
  return std::optional<ThermalFile>(std::move(file));
}

static SolveOutcome run_solve_timed(const SolveJob& job, const RigConfig& config, const ImuStreamInfo& info,
                                    const std::string& dir,
                                    const std::function<void(double, const std::string&)>& progress,
                                    const MotionLogSource& motion_log) {
  SolveOutcome out;
  std::optional<ThermalFile> thermal;
  std::optional<AppliedThermal> applied;  // the model on the stream's input units and what it left
  std::vector<ImuSample> corrected;       // a copy of the samples at the model's T_ref
  if (job.final && job.thermal_samples && !job.thermal_samples->empty()) {
    if (progress)
      progress(0.0, "Thermal model from " + std::to_string(job.thermal_samples->size()) + " means of 0.1 s");
    auto fitted = solve_thermal(job, config, info, dir, out);
    if (!fitted.ok()) {
      out.error = "writing the thermal model: " + fitted.error().message;
      return out;
    }
    thermal = std::move(*fitted);
    if (out.thermal->determined && !job.samples->empty()) {
      corrected = *job.samples;
      auto a = apply_thermal(*out.thermal, corrected, info, "thermal.yaml");
      if (!a.ok()) {
        out.error =
            "correcting the samples to the thermal model's reference temperature: " + a.error().message;
        return out;
      }
      applied = std::move(*a);
    }
  }
  if (job.samples->empty()) {  // a thermal recording alone
    if (!out.thermal)
      out.error = "nothing to solve: the session has no poses and its thermal recording gave no model";
    return out;
  }
  const std::vector<ImuSample>& samples = applied ? corrected : *job.samples;
  if (progress) progress(0.0, "Static calibration of " + std::to_string(samples.size()) + " samples");
  auto result = app::calibrate_static(samples, job.static_options);
  if (!result.ok()) {
    out.error = result.error().message;
    return out;
  }
  out.imu = std::move(*result);
  if (applied) {
    out.imu->thermal = applied->model;
    for (const std::string& w : applied->warnings) out.imu->warnings.push_back("thermal: " + w);
  }
  if (!job.final) return out;
  if (progress) progress(job.camimu ? 0.15 : 0.9, "Writing the static results");
  const std::string yaml_path = dir + "/imu-static.yaml", json_path = dir + "/imu-static.json";
  const std::map<std::string, std::string> meta = {{"software_version", kVersion}};
  Status s = write_text_file(yaml_path, static_result_yaml(*out.imu, info));
  if (s.ok()) s = write_text_file(json_path, static_result_json(*out.imu, info, "standard gravity", meta));
  if (!s.ok()) {
    out.error = "writing the results: " + s.error().message;
    return out;
  }
  out.result_files.push_back(yaml_path);
  out.result_files.push_back(json_path);
  // The record to store, from the typed results (the files above are for people and tools).
  CalibrationRecord record = calibration_record_from_static(*out.imu, info, yaml_path);
  if (job.camimu) {
    auto files = solve_camimu(config, dir, yaml_path, info, motion_log, thermal, out, progress);
    if (!files.ok()) {
      out.error = files.error().message;
      return out;
    }
    out.result_files.insert(out.result_files.end(), files->begin(), files->end());
    auto merged = merge_calibration_records(std::move(record),
                                            calibration_record_from_camimu(*out.camimu, files->back()));
    if (!merged.ok()) {
      out.error = "building the record: " + merged.error().message;
      return out;
    }
    record = std::move(*merged);
  }
  out.record = std::move(record);
  return out;
}

SessionRunner::SessionRunner(const RigConfig& config, const ImuStreamInfo& info, RunnerOptions options)
    : config_(config), info_(info), options_(std::move(options)), engine_(config, info, *this) {
  worker_ = std::thread([this] { worker_loop(); });
}

SessionRunner::~SessionRunner() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
  close_motion_log();
  close_log();
}

void SessionRunner::worker_loop() {
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [this] { return stop_ || !jobs_.empty(); });
      if (jobs_.empty()) return;  // stopping with nothing left
      job = std::move(jobs_.front());
      jobs_.pop_front();
      running_job_ = true;
    }
    job();
    {
      std::lock_guard lock(mutex_);
      running_job_ = false;
    }
    cv_.notify_all();
  }
}

void SessionRunner::run_on_worker(std::function<void()> work) {
  if (!options_.post) {
    work();
    return;
  }
  {
    std::lock_guard lock(mutex_);
    jobs_.push_back(std::move(work));
  }
  cv_.notify_all();
}

void SessionRunner::drain() {
  std::unique_lock lock(mutex_);
  cv_.wait(lock, [this] { return jobs_.empty() && !running_job_; });
}

bool SessionRunner::busy() {
  std::lock_guard lock(mutex_);
  return running_job_ || !jobs_.empty();
}

Status SessionRunner::start(const std::vector<std::string>& steps) {
  // A start that would be refused makes no session folder (status would point at an empty one).
  if (auto plan = engine_.plan(steps); !plan.ok()) return plan.error();
  // The solver modules now, not at the solve: an upgrade during the session cannot swap them.
  if (Status s = load_session_modules(!config_.cameras.empty()); !s.ok())
    return s.error().context("loading the solver modules for the session");
  close_log();
  motion_step_start_ns_ = -1;
  if (!options_.session_dir.empty()) {
    dir_ = options_.session_dir;
  } else {
    auto dir = make_session_dir(options_.state_dir, config_.name);
    if (!dir.ok()) return dir.error();
    dir_ = *dir;
  }
  if (options_.write_log) {
    auto writer = log::SessionLogWriter::create(log_path());
    if (!writer.ok()) return writer.error().context("creating the session log");
    log_ = std::move(*writer);
    for (const auto& [k, v] : options_.metadata) IMUCAL_TRY(log_->set_metadata(k, v));
    IMUCAL_TRY(log_->set_metadata(
        "session", json{{"steps", steps}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
    auto id = log_->add_imu_stream(info_);
    if (!id.ok()) return id.error().context("declaring the IMU stream");
    stream_id_ = *id;
  }
  recording_ = true;
  if (auto s = engine_.start(steps); !s.ok()) {
    close_log();
    return s;
  }
  return {};
}

void SessionRunner::on_samples(std::span<const ImuSample> samples) {
  for (const auto& s : samples) {
    if (recording_ && log_ && engine_.running()) {
      if (auto st = log_->append_imu(stream_id_, s); !st.ok()) {
        // The log is the session's record: without it nothing that follows could be replayed.
        recording_ = false;
        engine_.fault("log", st.error().message);
      }
    }
    engine_.on_sample(s);
    sync_motion_log();
    if (motion_shared_) {
      if (auto st = motion_shared_->append_imu(motion_imu_id_, s); !st.ok()) motion_log_error(st.error());
    }
  }
}

bool SessionRunner::wants_frames() const {
  return engine_.current_step() == StepId::kMotion && !config_.cameras.empty();
}

void SessionRunner::sync_motion_log() {
  if (!options_.write_log) return;
  const bool want = wants_frames();
  if (want && engine_.step_start_ns() != motion_step_start_ns_) {
    // The step began (or began again after a redo): a new log. After an error, none until then.
    close_motion_log();
    motion_step_start_ns_ = engine_.step_start_ns();
    if (auto s = open_motion_log(); !s.ok()) motion_log_error(s.error());
  } else if (!want && motion_log_) {
    close_motion_log();
  }
}

void SessionRunner::motion_log_error(const Error& error) {
  // Without its log the motion step cannot be solved: the step stops, as for a device fault,
  // and a redo starts the step again with a new log.
  close_motion_log();
  engine_.fault("log", "the motion log " + dir_ + "/" + kMotionLogFile + ": " + error.message);
}

Status SessionRunner::open_motion_log() {
  const std::string path = dir_ + "/" + kMotionLogFile;
  std::error_code ec;
  std::filesystem::remove(path, ec);  // a redo of the step records it again
  auto writer = log::SessionLogWriter::create(path);
  if (!writer.ok()) return writer.error();
  motion_log_ = std::move(*writer);
  for (const auto& [k, v] : options_.metadata) IMUCAL_TRY(motion_log_->set_metadata(k, v));
  if (config_.target) IMUCAL_TRY(motion_log_->set_metadata("target", target_to_yaml(*config_.target)));
  auto id = motion_log_->add_imu_stream(info_);
  if (!id.ok()) return id.error();
  motion_imu_id_ = *id;
  motion_camera_ids_.assign(config_.cameras.size(), -1);
  camera_streams_.clear();
  camera_streams_.resize(config_.cameras.size());
  live_.assign(config_.cameras.size(), {});
  coverage_.assign(config_.cameras.size(), {});
  view_sent_.assign(config_.cameras.size(), {});
  motion_shared_ = log::synchronized_writer(*motion_log_);
  return {};
}

Result<acq::CameraStream*> SessionRunner::camera_stream(std::size_t camera,
                                                        const drivers::camera::Frame& frame,
                                                        drivers::camera::TimestampMeaning meaning) {
  if (camera_streams_[camera]) return camera_streams_[camera].get();
  const CameraConfig& c = config_.cameras[camera];
  acq::CameraStreamOptions so;
  so.block_when_full = options_.frames_wait_for_encoder;
  auto stream =
      acq::CameraStream::create({frame.width, frame.height, frame.pixel_format, c.rate_hz}, meaning, so);
  if (!stream.ok()) return stream.error();
  CameraStreamInfo ci;
  ci.name = c.name;
  ci.width = frame.width;
  ci.height = frame.height;
  ci.rate_hz = c.rate_hz;
  ci.backend = camera_backend_name(c.backend);
  ci.device = c.device;
  ci.timestamp_source = (*stream)->timestamp_source();
  auto id = motion_shared_->add_camera_stream(ci);
  if (!id.ok()) return id.error();
  IMUCAL_TRY((*stream)->start_log(*motion_shared_, *id));
  motion_camera_ids_[camera] = *id;
  camera_streams_[camera] = std::move(*stream);
  return camera_streams_[camera].get();
}

void SessionRunner::close_motion_log() {
  if (!motion_log_) return;
  // Every queued frame is encoded and written before the log closes.
  for (std::size_t i = 0; i < camera_streams_.size(); ++i) {
    if (!camera_streams_[i]) continue;
    const Status stopped = camera_streams_[i]->stop();
    const acq::CameraStreamStats st = camera_streams_[i]->stats();
    const std::string& name = config_.cameras[i].name;
    if (!stopped.ok())
      warn("camera " + name + ": frames not written to the motion log: " + stopped.error().message);
    if (st.queue_dropped > 0 || st.wrong_size > 0)
      warn("camera " + name + ": " + std::to_string(st.queue_dropped) +
           " frames dropped for want of a free buffer (the encoder or the disk too slow), " +
           std::to_string(st.wrong_size) + " of another size than the first; " + std::to_string(st.written) +
           " written");
  }
  camera_streams_.clear();
  motion_shared_.reset();
  const Status closed = motion_log_->close();
  motion_log_.reset();
  if (!closed.ok()) {
    warn("closing the motion log: " + closed.error().message);
    return;
  }
  // Every frame was searched as it came, with the detector `calibrate camera` uses by default:
  // stored under its key, the solve (and `imucal calibrate camera` offline) reuse them.
  if (!detector_ || !config_.target) return;
  for (std::size_t i = 0; i < live_.size() && i < motion_camera_ids_.size(); ++i) {
    if (motion_camera_ids_[i] < 0) continue;  // no frame came
    log::DetectionSet set;
    set.target_key = detection_key(*config_.target, calib::DetectionOptions{});
    set.description = target_to_yaml(*config_.target);
    set.frames = live_[i].frames;
    for (auto& [t, data] : live_[i].found) set.detections.push_back({t, std::move(data)});
    if (auto s = log::write_target_detections(dir_ + "/" + kMotionLogFile, motion_camera_ids_[i], set);
        !s.ok())
      warn("the live detections were not stored in the motion log (the solve searches again): " +
           s.error().message);
  }
  live_.clear();
}

void SessionRunner::on_frame(std::size_t camera, drivers::camera::Frame& frame,
                             drivers::camera::TimestampMeaning meaning) {
  sync_motion_log();
  if (!wants_frames() || camera >= config_.cameras.size() || !motion_log_) {
    frame.release();
    return;
  }
  const std::string& name = config_.cameras[camera].name;
  if (!detector_ && config_.target) {
    auto detector = make_target_detector(*config_.target);
    if (!detector.ok()) {
      frame.release();
      engine_.fault(name, "target detection: " + detector.error().message);
      return;
    }
    detector_ = std::move(*detector);
  }
  auto stream = camera_stream(camera, frame, meaning);
  if (!stream.ok()) {
    frame.release();
    if (stream.error().code == Errc::kUnsupported || stream.error().code == Errc::kInvalidArgument) {
      engine_.fault(name, stream.error().message);
    } else {
      motion_log_error(stream.error());
    }
    return;
  }
  if ((*stream)->log_failed()) {
    frame.release();
    const Status st = (*stream)->stop();
    motion_log_error(st.ok() ? make_error(Errc::kIo, "writing " + name + "'s frames failed") : st.error());
    return;
  }
  bool seen = false;
  TimeNs t_ns = 0;
  const bool recorded = (*stream)->publish(frame, [&](const acq::PublishedFrame& f) {
    t_ns = f.t_ns;
    if (!detector_) return;
    auto obs = detector_->detect(calib::GrayView{f.grey.data(), f.width, f.height, 0});
    seen = obs.ok() && !obs->empty();
    ++live_[camera].frames;
    if (seen) {
      obs->t_ns = f.t_ns;
      obs->width = f.width;
      obs->height = f.height;
      live_[camera].found.emplace_back(f.t_ns, encode_detection(*obs));
    }
    if (camera < coverage_.size()) {
      ViewCoverage& coverage = coverage_[camera];
      if (coverage.width() != f.width || coverage.height() != f.height)
        coverage = ViewCoverage(f.width, f.height);
      if (seen) coverage.add(obs->px, obs->ids, *config_.target);
      send_view(camera, f, seen ? obs->px : std::vector<Eigen::Vector2d>{},
                seen ? obs->ids : std::vector<int>{});
    }
  });
  if (!recorded) return;  // dropped: counted by the stream, reported when the log closes
  // Replay reads what the engine saw from this event (docs/service-session.md).
  if (log_) {
    // At the engine's time, as replay applies inputs (after the sample of that time).
    if (auto s = log_->append_event(
            {engine_.now_ns(), "frame", session_msg::dump(session_msg::FrameEvent{camera, t_ns, seen})});
        !s.ok())
      warn("session log: " + s.error().message);
  }
  engine_.on_frame(camera, t_ns, seen);
}

void SessionRunner::send_view(std::size_t camera, const acq::PublishedFrame& f,
                              const std::vector<Eigen::Vector2d>& px, const std::vector<int>& ids) {
  if (!options_.view_frame || camera >= view_sent_.size()) return;
  if (options_.view_watched && !options_.view_watched()) return;
  const auto now = std::chrono::steady_clock::now();
  const auto interval = std::chrono::duration<double>(1.0 / std::max(options_.view_rate_hz, 1e-3));
  if (view_sent_[camera] != std::chrono::steady_clock::time_point{} && now - view_sent_[camera] < interval)
    return;
  view_sent_[camera] = now;
  ViewFrame v =
      make_view_frame(f.grey.data(), f.width, f.height, options_.view_width, px, ids, *config_.target);
  v.camera = camera;
  v.name = config_.cameras[camera].name;
  v.t_ns = f.t_ns;
  v.coverage = coverage_[camera].figures();
  options_.view_frame(std::move(v));
}

void SessionRunner::fault(const std::string& source, const std::string& text) { engine_.fault(source, text); }

void SessionRunner::emit(const SessionMessage& message) {
  // The motion step's figures gain each camera's coverage, which the runner keeps (the engine
  // sees only whether a frame showed the target).
  if (const auto* live = std::get_if<session_msg::Live>(&message); live && !coverage_.empty()) {
    if (const auto* figures = std::get_if<session_msg::MotionFigures>(&live->figures);
        figures && figures->coverage.empty()) {
      session_msg::Live covered = *live;
      auto& f = std::get<session_msg::MotionFigures>(covered.figures);
      for (const ViewCoverage& c : coverage_) f.coverage.push_back(c.figures());
      emit(covered);
      return;
    }
  }
  const auto* done = std::get_if<session_msg::Done>(&message);
  if (done && !dir_.empty() && !done->session_dir) {
    // The end of a session names its folder (where the logs, results and reports are).
    session_msg::Done named = *done;
    named.session_dir = dir_;
    emit(named);
    return;
  }
  if (log_) {
    if (auto s = log_->append_event({engine_.now_ns(), "session", session_msg::dump(message)}); !s.ok())
      warn("session log: " + s.error().message);
  }
  if (options_.broadcast) options_.broadcast(message);
  if (done) {
    if (log_) (void)log_->flush();
    close_log();
  }
}

PreflightReport SessionRunner::preflight() {
  PreflightReport report;
  if (options_.preflight) report = options_.preflight();
  report.rig = config_.name;
  return report;
}

void SessionRunner::solve(const SolveJob& job) {
  const std::string dir = dir_;
  const ImuStreamInfo info = info_;
  const bool report = options_.report;
  auto complete_record = options_.complete_record;
  const std::string log = log_path();
  run_on_worker([this, job, dir, info, report, complete_record, log] {
    auto progress = [this](double f, const std::string& text) {
      if (options_.post) {
        options_.post([this, f, text] { engine_.solve_progress(f, text); });
      } else {
        engine_.solve_progress(f, text);
      }
    };
    SolveOutcome out =
        run_solve(job, config_, info, dir,
                  job.final ? std::function<void(double, const std::string&)>(progress) : nullptr);
    if (job.final && out.error.empty()) {
      if (complete_record && out.record) {
        if (Status s = complete_record(*out.record); !s.ok())
          out.error = "building the record: " + s.error().message;
      }
      if (report && out.error.empty()) {
        report::ReportOptions ro;
        ro.result_path = dir + "/imu-static.json";
        ro.log_path = options_.write_log ? log : std::string();
        ro.html_path = dir + "/report.html";
        ro.overwrite = true;
        ro.log_in_progress = true;  // the session goes on (review, write) while the report is drawn
        ro.generator = std::string("imucal ") + kVersion;
        if (!out.imu) {
          // A thermal recording alone: no static result to draw.
        } else if (auto r = report::write_report(ro); r.ok()) {
          out.result_files.push_back(ro.html_path);
        } else {
          warn("the session report was not written: " + r.error().message);
        }
        if (out.thermal && out.thermal->determined) {
          ro.result_path = dir + "/thermal.yaml";
          ro.log_path.clear();
          ro.html_path = dir + "/report-thermal.html";
          if (auto r = report::write_report(ro); r.ok()) {
            out.result_files.push_back(ro.html_path);
          } else {
            warn("the thermal report was not written: " + r.error().message);
          }
        }
        if (out.camimu) {
          ro.result_path = dir + "/camimu/result.json";
          ro.log_path = options_.write_log ? dir + "/" + kMotionLogFile : std::string();
          ro.html_path = dir + "/report-camimu.html";
          if (auto r = report::write_report(ro); r.ok()) {
            out.result_files.push_back(ro.html_path);
          } else {
            warn("the camera-IMU report was not written: " + r.error().message);
          }
        }
      }
    }
    auto apply = [this, id = job.id, out = std::move(out)]() mutable {
      engine_.solve_finished(id, std::move(out));
    };
    if (options_.post) {
      options_.post(std::move(apply));
    } else {
      apply();
    }
  });
}

void SessionRunner::write(const CalibrationRecord& record) {
  auto writer = options_.write_storage;
  run_on_worker([this, record, writer] {
    Result<std::string> where =
        writer ? writer(record)
               : Result<std::string>(make_error(Errc::kUnsupported, "this host has no storage to write to"));
    const Status status = where.ok() ? Status{} : Status(where.error());
    const std::string place = where.ok() ? *where : std::string();
    auto apply = [this, status, place] { engine_.write_finished(status, place); };
    if (options_.post) {
      options_.post(apply);
    } else {
      apply();
    }
  });
}

void SessionRunner::warn(const std::string& text) const {
  if (options_.warn) {
    options_.warn(text);
  } else {
    std::fprintf(stderr, "%s\n", text.c_str());
  }
}

Status SessionRunner::recover() { return options_.recover ? options_.recover() : Status{}; }

void SessionRunner::recording_finished() {
  recording_ = false;
  close_motion_log();
  if (log_) (void)log_->flush();
}

void SessionRunner::close_log() {
  if (!log_) return;
  if (auto s = log_->close(); !s.ok()) warn("closing the session log: " + s.error().message);
  log_.reset();
}

}  // namespace imucal::app::session
