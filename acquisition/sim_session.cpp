#include "acquisition/sim_session.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>

#include "acquisition/session_log.hpp"
#include "drivers/sim/motion.hpp"

namespace imucal::acq {
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
  return imu.validate();
}

ImuStreamInfo sim_imu_stream_info(const sim::ImuModelParams& imu, double rate_hz) {
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kRaw;
  info.rate_hz = rate_hz;
  info.accel.scale = Eigen::Vector3d::Constant(imu.accel_mps2_per_count());
  info.gyro.scale = Eigen::Vector3d::Constant(imu.gyro_radps_per_count());
  info.temperature_scale = 1.0 / sim::kMpu6000TempLsbPerDegC;
  info.temperature_offset = sim::kMpu6000TempOffsetDegC;
  info.accel_full_scale_g = imu.accel_full_scale_g;
  info.gyro_full_scale_dps = imu.gyro_full_scale_dps;
  info.dlpf_hz = 0;
  info.device = "sim";
  return info;
}

Result<sim::SimTruth> write_sim_imu_session(const SimImuSessionOptions& options,
                                            const sim::Trajectory& trajectory, const std::string& log_path,
                                            const std::string& truth_path,
                                            const std::function<void(double)>& progress) {
  IMUCAL_TRY(options.validate());
  std::error_code ec;
  if (!options.overwrite) {
    for (const std::string& p : {log_path, truth_path}) {
      if (!p.empty() && std::filesystem::exists(p, ec)) {
        return make_error(Errc::kInvalidArgument, p + " exists; pass --force to replace it");
      }
    }
  }

  SessionLogWriterOptions wopt;
  wopt.overwrite = options.overwrite;
  wopt.commit_interval_ns = 5 * kNsPerSecond;  // simulated: commit every 5 s of sample time
  auto writer_r = SessionLogWriter::create(log_path, wopt);
  if (!writer_r.ok()) return writer_r.error();
  auto& writer = *writer_r;

  const ImuStreamInfo info = sim_imu_stream_info(options.imu, options.imu_rate_hz);
  nlohmann::json rig = {{"imu",
                         {{"device", info.device},
                          {"model", "MPU-6000 (simulated)"},
                          {"rate_hz", options.imu_rate_hz},
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
      {"gyro_bias_random_walk", options.imu.gyro_bias_random_walk}};
  nlohmann::json drops = nlohmann::json::array();
  for (const SampleDrop& d : options.drops)
    drops.push_back({{"start_s", d.start_s}, {"duration_s", d.duration_s}});
  simj["dropped_spans"] = drops;
  IMUCAL_TRY(writer->set_metadata("rig_config", rig.dump()));
  IMUCAL_TRY(writer->set_metadata("sim", simj.dump()));
  IMUCAL_TRY(writer->set_metadata("device", "sim"));
  auto stream = writer->add_imu_stream(info);
  if (!stream.ok()) return stream.error();

  // Segment events, with a pose counter for holds and faces.
  std::vector<Event> events;
  int pose = 0;
  for (const sim::Segment& seg : trajectory.segments()) {
    const SegmentEvents ev = events_for(seg.kind);
    if (ev.begin.empty()) continue;
    nlohmann::json msg = {{"segment", seg.kind}, {"t0_ns", seg.t0_ns}, {"t1_ns", seg.t1_ns}};
    if (ev.begin == "pose_begin") {
      msg["pose"] = pose;
      if (seg.kind == "face" && pose < static_cast<int>(sim::six_face_names().size())) {
        msg["face"] = sim::six_face_names()[static_cast<std::size_t>(pose)];
      }
      ++pose;
    }
    events.push_back({seg.t0_ns, ev.begin, msg.dump()});
    events.push_back({seg.t1_ns, ev.end, msg.dump()});
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  for (const Event& e : events) IMUCAL_TRY(writer->append_event(e));

  sim::SimTruth truth;
  truth.kind = options.kind;
  truth.seed = options.seed;
  truth.params_from_file = options.params_from_file;
  truth.imu = options.imu;
  truth.trajectory.script = options.script;
  truth.trajectory.poses = options.poses;
  truth.trajectory.segments = trajectory.segments();
  truth.trajectory.duration_s = ns_to_s(trajectory.end_ns() - trajectory.start_ns());
  sim::RecordingSummary& rec = truth.recording;
  rec.imu_rate_hz = options.imu_rate_hz;

  const double period_s = 1.0 / options.imu_rate_hz;
  const std::int64_t n =
      static_cast<std::int64_t>(std::floor(truth.trajectory.duration_s * options.imu_rate_hz)) + 1;
  sim::ImuSimulator imu(options.imu, options.seed, trajectory.start_ns());
  std::vector<ImuSample> batch;
  constexpr std::size_t kBatch = 2000;
  batch.reserve(kBatch);
  bool gap_pending = false;
  double sum_a = 0.0, sum_w = 0.0;
  Eigen::Vector3d sum_ba = Eigen::Vector3d::Zero(), sum_bg = Eigen::Vector3d::Zero();
  for (std::int64_t k = 0; k < n; ++k) {
    const TimeNs t_ns = trajectory.start_ns() + s_to_ns(static_cast<double>(k) * period_s);
    const sim::RigState st = trajectory.at(t_ns);
    sim::ImuSimDetail d;
    ImuSample s = imu.sample(t_ns, st, period_s, &d);
    const double a = st.a_world.norm(), w = st.omega_body.norm();
    sum_a += a;
    sum_w += w;
    truth.trajectory.max_accel_mps2 = std::max(truth.trajectory.max_accel_mps2, a);
    truth.trajectory.max_rate_radps = std::max(truth.trajectory.max_rate_radps, w);
    sum_ba += d.accel_bias;
    sum_bg += d.gyro_bias;
    if (k == 0) rec.temperature_start_c = d.temperature_c;
    rec.temperature_end_c = d.temperature_c;
    rec.accel_bias_end = d.accel_bias;
    rec.gyro_bias_end = d.gyro_bias;

    const double t_rel_s = ns_to_s(t_ns - trajectory.start_ns());
    const bool dropped = std::any_of(options.drops.begin(), options.drops.end(), [&](const SampleDrop& dr) {
      return t_rel_s >= dr.start_s && t_rel_s < dr.start_s + dr.duration_s;
    });
    if (dropped) {
      ++rec.dropped_samples;
      gap_pending = true;
      continue;
    }
    if (gap_pending) s.flags |= kImuFlagGapBefore;
    gap_pending = false;
    if (s.flags & kImuFlagAccelSaturated) ++rec.accel_saturated;
    if (s.flags & kImuFlagGyroSaturated) ++rec.gyro_saturated;
    ++rec.samples;
    batch.push_back(s);
    if (batch.size() == kBatch) {
      IMUCAL_TRY(writer->append_imu(*stream, batch));
      batch.clear();
      if (progress) progress(static_cast<double>(k + 1) / static_cast<double>(n));
    }
  }
  if (!batch.empty()) IMUCAL_TRY(writer->append_imu(*stream, batch));
  const double count = static_cast<double>(n);
  truth.trajectory.mean_accel_mps2 = sum_a / count;
  truth.trajectory.mean_rate_radps = sum_w / count;
  rec.accel_bias_mean = sum_ba / count;
  rec.gyro_bias_mean = sum_bg / count;

  IMUCAL_TRY(writer->close());
  if (!truth_path.empty()) {
    auto st = sim::write_truth_yaml(truth_path, sim::truth_to_yaml(truth), options.overwrite);
    if (!st.ok()) return st.error();
  }
  if (progress) progress(1.0);
  return truth;
}

}  // namespace imucal::acq
