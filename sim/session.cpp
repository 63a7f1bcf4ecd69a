// SPDX-License-Identifier: BSD-3-Clause
#include "sim/session.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>

#include "acquisition/recorder.hpp"
#include "drivers/mpu6000/output_settings.hpp"
#include "log/dataset_io.hpp"
#include "log/session_log.hpp"
#include "sim/motion.hpp"
#include "sim/rig.hpp"

namespace imucal::sim {
namespace {

/// The event a segment produces at its start and end (empty kinds produce none).
struct SegmentEvents {
  std::string begin, end;
};

SegmentEvents events_for(const std::string& kind) {
  if (kind == "still") return {"still_begin", "still_end"};
  if (kind == "hold" || kind == "face") return {"pose_begin", "pose_end"};
  return {};
}

}  // namespace

Status SimImuSessionOptions::validate() const {
  if (!(imu_rate_hz >= 4.0 && imu_rate_hz <= 8000.0)) {
    return make_error(
        Errc::kInvalidArgument,
        "IMU rate must be within 4..8000 Hz (MPU-6000 output rates), got " + std::to_string(imu_rate_hz));
  }
  for (const SampleDrop& d : drops) {
    if (!(d.start_s >= 0.0 && d.duration_s > 0.0)) {
      return make_error(Errc::kInvalidArgument, "dropped spans need start >= 0 s and a positive duration");
    }
  }
  IMUCAL_TRY(imu.validate());
  if (!(std::abs(path.clock_ppm) <= 80'000.0)) {
    return make_error(Errc::kInvalidArgument, "the chip clock error must be within +-80000 ppm");
  }
  auto settings = sim_driver_settings(*this);
  if (!settings.ok()) return settings.error();
  return {};
}

Result<drivers::mpu6000::Settings> sim_driver_settings(const SimImuSessionOptions& options) {
  drivers::mpu6000::OutputRequest req;
  req.bus = options.path.bus;
  req.rate_hz = options.imu_rate_hz;
  req.accel_full_scale_g = options.imu.accel_full_scale_g;
  req.gyro_full_scale_dps = options.imu.gyro_full_scale_dps;
  return drivers::mpu6000::settings_for(req);
}

Status refuse_existing_outputs(std::initializer_list<std::string> paths, bool overwrite) {
  std::error_code ec;
  for (const std::string& p : paths) {
    if (p.empty()) continue;
    // A device, FIFO, socket or folder is never replaced, overwrite or not.
    IMUCAL_TRY(log::check_replaceable(p));
    if (!overwrite && std::filesystem::exists(p, ec))
      return make_error(Errc::kAlreadyExists, p + " already exists");
  }
  return {};
}

namespace {

/// The rig description and the simulation parameters, as log metadata.
Status write_session_metadata(log::SessionLogWriter& writer, const SimImuSessionOptions& options,
                              const ImuStreamInfo& info, const std::string& truth_path) {
  const char* bus_name = options.path.bus == drivers::mpu6000::BusKind::kSpi ? "spi" : "i2c";
  nlohmann::json rig_json = {{"imu",
                              {{"device", info.device},
                               {"model", "MPU-6000 (simulated: register emulator)"},
                               {"bus", bus_name},
                               {"rate_hz", options.imu_rate_hz},
                               {"dlpf_hz", info.dlpf_hz},
                               {"accel_full_scale_g", info.accel_full_scale_g},
                               {"gyro_full_scale_dps", info.gyro_full_scale_dps}}}};
  nlohmann::json simj = {
      {"kind", options.kind},
      {"script", options.script},
      {"seed", options.seed},
      {"params_from_file", options.params_from_file},
      {"truth_file",
       truth_path.empty() ? std::string() : std::filesystem::path(truth_path).filename().string()},
      {"gravity_mps2", options.imu.gravity_mps2},
      {"earth_rotation", options.imu.earth_rotation},
      {"accel_noise_density", options.imu.accel_noise_density},
      {"gyro_noise_density", options.imu.gyro_noise_density},
      {"accel_bias_random_walk", options.imu.accel_bias_random_walk},
      {"gyro_bias_random_walk", options.imu.gyro_bias_random_walk},
      {"path", "emulator+driver+acquisition"},
      {"clock_ppm", options.path.clock_ppm},
      {"edge_latency_ns", options.path.data_ready.latency_ns},
      {"edge_jitter_ns", options.path.data_ready.sigma_ns}};
  nlohmann::json drops = nlohmann::json::array();
  for (const SampleDrop& d : options.drops)
    drops.push_back({{"start_s", d.start_s}, {"duration_s", d.duration_s}});
  simj["host_stalls"] = drops;
  if (!options.rig_camera_json.empty()) rig_json["camera"] = nlohmann::json::parse(options.rig_camera_json);
  IMUCAL_TRY(writer.set_metadata("rig_config",
                                 rig_json.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
  IMUCAL_TRY(writer.set_metadata("sim", simj.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
  for (const auto& [key, value] : options.metadata) IMUCAL_TRY(writer.set_metadata(key, value));
  return writer.set_metadata("device", "sim");
}

/// Segment events, with a pose counter for holds and faces, in time order.
Status write_segment_events(log::SessionLogWriter& writer, const sim::Trajectory& trajectory) {
  std::vector<log::Event> events;
  int pose = 0;
  for (const sim::Segment& seg : trajectory.segments()) {
    const SegmentEvents ev = events_for(seg.kind);
    if (ev.begin.empty()) continue;
    nlohmann::json msg = {{"segment", seg.kind}, {"t0_ns", seg.t0_ns}, {"t1_ns", seg.t1_ns}};
    if (ev.begin == "pose_begin") {
      msg["pose"] = pose;
      if (!seg.label.empty()) msg["face"] = seg.label;
      ++pose;
    }
    events.push_back(
        {seg.t0_ns, ev.begin, msg.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)});
    events.push_back({seg.t1_ns, ev.end, msg.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)});
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const log::Event& a, const log::Event& b) { return a.t_ns < b.t_ns; });
  for (const log::Event& e : events) IMUCAL_TRY(writer.append_event(e));
  return {};
}

/// Runs the rig until the trajectory's end and writes the samples inside it (trajectory clock:
/// host time minus `offset`), stalling the host over the options' drops. Counts into `rec`.
Status record_trajectory(SimImuRig& rig, const SimImuSessionOptions& options,
                         const sim::Trajectory& trajectory, TimeNs offset, TimeNs setup_ns,
                         log::SessionLogWriter& writer, int stream, sim::RecordingSummary& rec,
                         const std::function<void()>& after_step, const ProgressFn& progress) {
  const TimeNs t_start = trajectory.start_ns(), t_end = trajectory.end_ns();
  const TimeNs duration_ns = std::max<TimeNs>(1, t_end - t_start);
  std::vector<ImuSample> out, batch;
  constexpr std::size_t kBatch = 2000;
  batch.reserve(kBatch);
  bool done = false;
  double last_progress = 0.0;
  while (!done) {
    const TimeNs now = rig.clock().now_ns() - offset;
    for (const SampleDrop& d : options.drops) {
      const TimeNs s0 = t_start + s_to_ns(d.start_s), s1 = s0 + s_to_ns(d.duration_s);
      if (now >= s0 && now < s1) rig.stall_until(s1 + offset);
    }
    if (rig.clock().now_ns() - offset > t_end + setup_ns) break;  // the chip stopped delivering
    if (auto st = rig.acquisition().step(out); !st.ok()) return st.error().context("simulated acquisition");
    after_step();
    for (ImuSample& s : out) {
      s.t_ns -= offset;
      if (s.t_ns < t_start) continue;
      if (s.t_ns > t_end) {
        done = true;
        break;
      }
      if (s.flags & kImuFlagAccelSaturated) ++rec.accel_saturated;
      if (s.flags & kImuFlagGyroSaturated) ++rec.gyro_saturated;
      ++rec.samples;
      batch.push_back(s);
    }
    if (batch.size() >= kBatch) {
      IMUCAL_TRY(writer.append_imu(stream, batch));
      batch.clear();
    }
    const double f =
        static_cast<double>(rig.clock().now_ns() - offset - t_start) / static_cast<double>(duration_ns);
    if (progress && f - last_progress >= 0.01) {
      last_progress = f;
      progress(std::clamp(f, 0.0, 1.0));
    }
  }
  if (!batch.empty()) IMUCAL_TRY(writer.append_imu(stream, batch));
  return {};
}

/// The session's cameras, recorded through the camera path (acquisition/camera_acquisition.hpp).
class SimCameras {
 public:
  Status open(const SimImuSessionOptions& options, SimImuRig& rig, TimeNs offset,
              log::SessionLogWriter& writer) {
    for (const SimSessionCamera& sc : options.cameras) {
      auto camera = sc.make([&rig] { return rig.clock().now_ns(); }, offset);
      if (!camera.ok()) return camera.error().context("simulated camera " + sc.info.name);
      acq::CameraStreamOptions so = sc.stream;
      so.block_when_full = true;  // simulated time waits for the encoder, as a real-time rig need not
      so.time_offset_ns = offset;
      auto stream = acq::CameraStream::create((*camera)->format(), (*camera)->timestamp_meaning(), so);
      if (!stream.ok()) return stream.error().context("camera " + sc.info.name);
      CameraStreamInfo info = sc.info;
      const auto format = (*camera)->format();
      info.width = format.width;
      info.height = format.height;
      info.rate_hz = format.rate_hz;
      info.timestamp_source = (*stream)->timestamp_source();
      auto id = writer.add_camera_stream(info);
      if (!id.ok()) return id.error();
      IMUCAL_TRY((*stream)->start_log(writer, *id));
      IMUCAL_TRY((*camera)->start());
      cameras_.push_back(std::move(*camera));
      stats_out_.push_back(sc.stats_out);
      acquisitions_.push_back(std::make_unique<acq::CameraAcquisition>(
          *cameras_.back(), info.name, std::move(*stream),
          [&writer](log::Event e) { (void)writer.append_event(e); }, 2 * kNsPerSecond));
    }
    return {};
  }

  void service(TimeNs host_now_ns) {
    for (auto& a : acquisitions_) a->service(host_now_ns);
  }

  /// Stops the cameras and writes what their encoders hold; the first error, and the counters
  /// as "camera.<name>" metadata.
  Status close(log::SessionLogWriter& writer) {
    Status first;
    for (auto& c : cameras_) (void)c->stop();
    for (std::size_t i = 0; i < acquisitions_.size(); ++i) {
      auto& a = acquisitions_[i];
      auto st = a->stream().stop();
      if (!st.ok() && first.ok()) first = st;
      (void)writer.set_metadata("camera." + a->name(), acq::camera_metadata_json(a->stats()));
      if (stats_out_[i] != nullptr) *stats_out_[i] = a->stats();
    }
    acquisitions_.clear();
    cameras_.clear();
    return first;
  }

  bool empty() const { return cameras_.empty(); }

 private:
  std::vector<std::unique_ptr<drivers::camera::Camera>> cameras_;
  std::vector<std::unique_ptr<acq::CameraAcquisition>> acquisitions_;
  std::vector<acq::CameraAcquisitionStats*> stats_out_;
};

/// What the sensing elements saw, into the truth.
void add_sensor_truth(const TrajectorySensorStats& ss, sim::SimTruth& truth) {
  sim::RecordingSummary& rec = truth.recording;
  const double count = static_cast<double>(std::max<std::int64_t>(1, ss.samples));
  truth.trajectory.mean_accel_mps2 = ss.sum_accel_mps2 / count;
  truth.trajectory.mean_rate_radps = ss.sum_rate_radps / count;
  truth.trajectory.max_accel_mps2 = ss.max_accel_mps2;
  truth.trajectory.max_rate_radps = ss.max_rate_radps;
  rec.accel_bias_mean = ss.sum_accel_bias / count;
  rec.gyro_bias_mean = ss.sum_gyro_bias / count;
  rec.accel_bias_end = ss.accel_bias_end;
  rec.gyro_bias_end = ss.gyro_bias_end;
  rec.temperature_start_c = ss.temperature_start_c;
  rec.temperature_end_c = ss.temperature_end_c;
  rec.dropped_samples = std::max<std::int64_t>(0, ss.samples - rec.samples);
}

/// Timing, driver and mounting metadata, as a recording on a rig writes them.
Status write_acquisition_metadata(log::SessionLogWriter& writer, SimImuRig& rig, const sim::SimTruth& truth) {
  acq::RecordSummary summary;
  summary.samples = static_cast<std::uint64_t>(truth.recording.samples);
  summary.timing = rig.acquisition().timestamper().stats();
  summary.acquisition = rig.acquisition().stats();
  summary.period_error_ppm = rig.acquisition().timestamper().period_error_ppm();
  summary.duration_s = truth.trajectory.duration_s;
  summary.rate_hz =
      summary.duration_s > 0 ? static_cast<double>(truth.recording.samples) / summary.duration_s : 0.0;
  IMUCAL_TRY(writer.set_metadata(
      "imu.timing", acq::timing_metadata_json(summary, rig.acquisition().timestamper().options())));
  IMUCAL_TRY(writer.set_metadata("imu.driver", acq::driver_metadata_json(rig.driver())));
  return writer.set_metadata("imu.mounting", acq::mounting_metadata_json(rig.acquisition().mounting()));
}

}  // namespace

Result<sim::SimTruth> write_sim_imu_session(const SimImuSessionOptions& options,
                                            const sim::Trajectory& trajectory, const std::string& log_path,
                                            const std::string& truth_path, const ProgressFn& progress) {
  IMUCAL_TRY(options.validate());
  IMUCAL_TRY(refuse_existing_outputs({log_path, truth_path}, options.overwrite));
  auto settings = sim_driver_settings(options);
  if (!settings.ok()) return settings.error();

  log::SessionLogWriterOptions wopt;
  wopt.overwrite = options.overwrite;
  // Faster than real time: commit every 5 s of sample time (and every 5 s of wall time).
  wopt.commit_interval_ns = 5 * kNsPerSecond;
  wopt.commit_data_interval_ns = 5 * kNsPerSecond;
  auto writer_r = log::SessionLogWriter::create(log_path, wopt);
  if (!writer_r.ok()) return writer_r.error();
  auto& raw_writer = *writer_r;
  // The camera streams' encoder threads share the log with this thread.
  auto writer = log::synchronized_writer(*raw_writer);

  ImuStreamInfo info = drivers::mpu6000::make_stream_info(*settings, "sim");
  info.name = "imu0";
  IMUCAL_TRY(write_session_metadata(*writer, options, info, truth_path));
  auto stream = writer->add_imu_stream(info);
  if (!stream.ok()) return stream.error();
  IMUCAL_TRY(write_segment_events(*writer, trajectory));

  sim::SimTruth truth;
  truth.kind = options.kind;
  truth.seed = options.seed;
  truth.params_from_file = options.params_from_file;
  truth.imu = options.imu;
  truth.trajectory.script = options.script;
  truth.trajectory.poses = options.poses;
  truth.trajectory.segments = trajectory.segments();
  truth.trajectory.duration_s = ns_to_s(trajectory.end_ns() - trajectory.start_ns());
  truth.recording.imu_rate_hz = options.imu_rate_hz;

  // The emulated chip powers up kSetupNs of host time before the trajectory starts, so that the
  // driver has reset and configured it and the timestamper has locked on to its clock when the
  // first sample of the trajectory arrives. Samples are written on the trajectory's clock:
  // host time minus a constant offset (an exact integer shift of the reconstructed stamps).
  constexpr TimeNs kSetupNs = kNsPerSecond;
  SimRigOptions ro;
  ro.settings = *settings;
  ro.clock_ppm = options.path.clock_ppm;
  ro.data_ready = options.path.data_ready;
  ro.data_ready.seed ^= options.seed;
  const TimeNs offset = ro.start_ns + kSetupNs - trajectory.start_ns();
  auto sensor = std::make_shared<TrajectorySensor>(options.imu, options.seed, trajectory, offset,
                                                   chip_sample_period_s(*settings, ro.clock_ppm));
  auto rig_r = SimImuRig::create(TrajectorySensor::source(sensor), ro);
  if (!rig_r.ok()) return rig_r.error();
  SimImuRig& rig = **rig_r;
  SimCameras cameras;
  Status recorded = cameras.open(options, rig, offset, *writer);
  if (recorded.ok()) {
    recorded = record_trajectory(
        rig, options, trajectory, offset, kSetupNs, *writer, *stream, truth.recording,
        [&] { cameras.service(rig.clock().now_ns()); }, progress);
  }
  if (recorded.ok() && !cameras.empty()) {
    // Frames whose exposure ends after the last sample: let the host clock run on a little.
    rig.clock().sleep_until(rig.clock().now_ns() + kNsPerSecond);
    cameras.service(rig.clock().now_ns());
  }
  const Status cameras_closed = cameras.close(*writer);
  IMUCAL_TRY(recorded);
  IMUCAL_TRY(cameras_closed);
  add_sensor_truth(sensor->stats(), truth);
  IMUCAL_TRY(write_acquisition_metadata(*writer, rig, truth));
  IMUCAL_TRY(writer->close());
  if (!truth_path.empty()) {
    auto st = sim::write_truth_yaml(truth_path, sim::truth_to_yaml(truth), options.overwrite);
    if (!st.ok()) return st.error();
  }
  if (progress) progress(1.0);
  return truth;
}

}  // namespace imucal::sim
