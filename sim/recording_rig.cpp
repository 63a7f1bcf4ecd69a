// SPDX-License-Identifier: BSD-3-Clause
#include "sim/recording_rig.hpp"

#include <algorithm>
#include <nlohmann/json.hpp>

#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"
#include "sim/virtual_cameras.hpp"

namespace imucal::sim {
namespace {

/// The motion script the options name; `board` is set for the checkerboard motion.
Result<std::shared_ptr<const Trajectory>> make_motion(const RecordingRigOptions& o,
                                                      std::shared_ptr<const CheckerboardMotion>* board) {
  if (o.motion == "static") {
    StaticProtocolOptions so;
    auto script = make_static_protocol(so, o.seed);
    if (!script.ok()) return script.error();
    return std::shared_ptr<const Trajectory>(std::move(*script));
  }
  if (o.motion == "checkerboard") {
    CheckerboardMotionOptions mo;
    mo.duration_s = std::max(10.0, o.duration_s + 5.0);
    auto motion = CheckerboardMotion::create(mo, o.seed);
    if (!motion.ok()) return motion.error();
    std::shared_ptr<const CheckerboardMotion> shared = std::move(*motion);
    *board = shared;
    return std::shared_ptr<const Trajectory>(shared);
  }
  if (o.motion != "still") {
    return make_error(Errc::kInvalidArgument,
                      "the motion '" + o.motion + "' is none of still, static, checkerboard");
  }
  StillOptions still;
  still.duration_s = o.duration_s + 30.0;
  auto script = make_still(still, o.seed);
  if (!script.ok()) return script.error();
  return std::shared_ptr<const Trajectory>(std::move(*script));
}

void fill_rig_options(SimRigOptions& r, const RecordingRigOptions& o) {
  r.settings = o.settings;
  r.clock_ppm = o.clock_ppm;
  r.data_ready.sigma_ns = static_cast<TimeNs>(o.jitter_us * 1e3);
  r.data_ready.seed = o.seed;
  r.mounting = o.mounting;
}

}  // namespace

Result<std::unique_ptr<RecordingRig>> RecordingRig::create(const RecordingRigOptions& options) {
  RecordingRigOptions o = options;
  for (const CameraConfig& cc : o.cameras) {
    if (cc.backend != CameraBackend::kSim) {
      return make_error(Errc::kInvalidArgument,
                        std::string("the virtual rig records simulated cameras only; camera ") + cc.name +
                            " has backend " + camera_backend_name(cc.backend));
    }
  }
  if (o.motion.empty()) o.motion = o.cameras.empty() ? "still" : "checkerboard";
  if (!o.cameras.empty() && o.motion != "checkerboard") {
    return make_error(
        Errc::kInvalidArgument,
        "the virtual cameras look at the target during the checkerboard motion; use it, or remove "
        "the cameras from the configuration");
  }
  if (!o.cameras.empty() && !o.target)
    return make_error(Errc::kInvalidArgument,
                      "the virtual cameras need the target (target: in the configuration)");
  if (!o.cameras.empty() && o.camera_content == "render" && o.render == nullptr)
    return make_error(Errc::kInvalidArgument, "the virtual cameras need the renderer to render the target");

  std::unique_ptr<RecordingRig> r(new RecordingRig());
  std::shared_ptr<const CheckerboardMotion> board;
  auto trajectory = make_motion(o, &board);
  if (!trajectory.ok()) return trajectory.error().context("virtual rig");
  r->trajectory_ = std::move(*trajectory);
  const ImuModelParams params = ImuModelParams::draw(o.seed);

  // The chip, at rest from power-on: trajectory time 0 is the emulator's start.
  TimeNs start_ns = 0;
  fake::DataReadyTiming data_ready;
  auto source = [&](TimeNs start) {
    auto sensor = std::make_shared<TrajectorySensor>(params, o.seed, *r->trajectory_, start,
                                                     chip_sample_period_s(o.settings, o.clock_ppm));
    return TrajectorySensor::source(std::move(sensor));
  };
  std::function<TimeNs()> clock;
  if (o.realtime) {
    RealtimeSimRigOptions ro;
    fill_rig_options(ro, o);
    ro.start_ns = monotonic_now_ns();
    start_ns = ro.start_ns;
    data_ready = ro.data_ready;
    auto rig = RealtimeSimRig::create(source(ro.start_ns), ro);
    if (!rig.ok()) return rig.error().context("virtual rig");
    r->realtime_ = std::move(*rig);
  } else {
    SimRigOptions ro;
    fill_rig_options(ro, o);
    start_ns = ro.start_ns;
    data_ready = ro.data_ready;
    auto rig = SimImuRig::create(source(ro.start_ns), ro);
    if (!rig.ok()) return rig.error().context("virtual rig");
    r->rig_ = std::move(*rig);
    SimImuRig* sim = r->rig_.get();
    clock = [sim] { return sim->clock().now_ns(); };
  }

  // The cameras: frames from a second after power-up, on the rig's clock (real time: empty).
  for (std::size_t i = 0; i < o.cameras.size(); ++i) {
    const CameraConfig& cc = o.cameras[i];
    const SimCameraScene scene = virtual_camera_scene(cc, *o.target, o.seed, i, start_ns);
    drivers::camera::fake::FrameRenderer renderer;
    if (o.camera_content == "render") {
      auto made = o.render(scene, board, board->T_world_board(scene.target));
      if (!made.ok()) return made.error().context("virtual camera " + cc.name);
      renderer = std::move(*made);
    } else {
      renderer = drivers::camera::fake::test_pattern_renderer(cc.width, cc.height, scene.seed);
    }
    VirtualCameraTiming timing;
    timing.first_frame_ns = start_ns + kNsPerSecond;
    timing.clock = clock;
    auto camera = make_virtual_camera(cc, std::move(renderer), timing);
    if (!camera.ok()) return camera.error();
    if (auto st = (*camera)->set_format({cc.width, cc.height, cc.pixel_format, cc.rate_hz}); !st.ok())
      return make_error(Errc::kInvalidArgument, "camera " + cc.name + ": " + st.error().message);
    r->cameras_.push_back(std::move(*camera));
  }

  r->info_ = drivers::mpu6000::make_stream_info(o.settings, "sim");
  r->info_.name = "imu0";
  nlohmann::json meta = {{"seed", o.seed},
                         {"clock_ppm", o.clock_ppm},
                         {"edge_latency_ns", data_ready.latency_ns},
                         {"edge_jitter_ns", data_ready.sigma_ns},
                         {"script", o.motion}};
  if (o.realtime) meta["realtime"] = true;
  if (!o.cameras.empty()) meta["timeshift_cam_imu_s"] = kVirtualTimeshiftCamImuS;
  r->metadata_ = meta.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  return r;
}

RecordingRig::~RecordingRig() { stop(); }

acq::ImuAcquisition& RecordingRig::acquisition() {
  return realtime_ ? realtime_->acquisition() : rig_->acquisition();
}

drivers::mpu6000::Mpu6000& RecordingRig::driver() { return realtime_ ? realtime_->driver() : rig_->driver(); }

void RecordingRig::stop() {
  if (realtime_) realtime_->stop_ticker();
}

}  // namespace imucal::sim
