// SPDX-License-Identifier: BSD-3-Clause
// imucal record: acquire the rig's MPU-6000 into a session log, on hardware (spidev / i2c-dev,
// data-ready through libgpiod, on the Boost.Asio event loop) or, with --sim, through the same
// driver and acquisition code against the register-level emulator: on simulated time (as fast
// as the host computes), or with --realtime in real time through the event loop a rig runs
// (docs/acquisition.md). On the event loop SIGINT, SIGTERM, SIGHUP and SIGQUIT end the recording
// cleanly; further signals while it closes are ignored.

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>
#include <string>

#include "acquisition/recorder.hpp"
#include "app/module_loader.hpp"
#include "app/results/output_checks.hpp"
#include "app/rig/cameras.hpp"
#include "app/rig/rig.hpp"
#include "core/rig_config.hpp"
#include "daemon/cli/command.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "sim/recording_rig.hpp"
#include "sim/render_module.hpp"

namespace imucal::cli {
namespace {

namespace mpu = drivers::mpu6000;

struct RecordArgs {
  std::string config_path;
  std::string out_path;
  double duration_s = 10.0;
  bool sim = false;
  bool realtime = false;
  bool force = false;
  bool json = false;
  std::uint64_t seed = 1;
  double sim_clock_ppm = sim::kDefaultClockPpm;
  double sim_jitter_us = 30.0;
  std::string sim_motion;  // empty: checkerboard with simulated cameras, else still
  std::string sim_camera = "render";
};

template <class T>
T take(Result<T> r, const std::string& what) {
  if (!r.ok()) fail(r.error(), what);
  return std::move(r).value();
}

/// Driver settings from the rig configuration (already validated by the loader).
mpu::Settings settings_from(const ImuConfig& imu, const std::string& config_path) {
  auto s = app::driver_settings(imu);
  if (!s.ok()) throw CliExit{kExitUsage, "imu settings in " + config_path + ": " + s.error().message};
  return *s;
}

void print_summary(const RecordArgs& a, const acq::RecordSummary& s, const std::string& extra_json) {
  if (a.json) {
    nlohmann::json j;
    j["log"] = a.out_path;
    j["samples"] = s.samples;
    j["duration_s"] = s.duration_s;
    j["rate_hz"] = s.rate_hz;
    j["period_error_ppm"] = s.period_error_ppm;
    j["gaps"] = s.timing.gaps;
    j["samples_lost"] = s.timing.samples_lost;
    j["edges_rejected"] = s.timing.edges_rejected;
    j["log_dropped"] = s.stream.log_dropped;
    j["interrupted"] = s.interrupted;
    if (!extra_json.empty()) j["sim"] = nlohmann::json::parse(extra_json);
    for (const auto& c : s.cameras) {
      j["cameras"].push_back(nlohmann::json::parse(acq::camera_metadata_json(c.stats)));
      j["cameras"].back()["name"] = c.name;
    }
    std::cout << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
    return;
  }
  std::printf(
      "recorded %llu samples over %.3f s (%.3f Hz measured; chip period %+.0f ppm from nominal) to %s\n",
      static_cast<unsigned long long>(s.samples), s.duration_s, s.rate_hz, s.period_error_ppm,
      a.out_path.c_str());
  std::printf("timing: %llu edges rejected, %llu gaps, %llu samples lost; log: %llu dropped\n",
              static_cast<unsigned long long>(s.timing.edges_rejected),
              static_cast<unsigned long long>(s.timing.gaps),
              static_cast<unsigned long long>(s.timing.samples_lost),
              static_cast<unsigned long long>(s.stream.log_dropped));
  for (const auto& c : s.cameras) {
    const auto& st = c.stats;
    std::printf(
        "camera %s: %llu frames written, %llu dropped by the device, %llu dropped for want of a free "
        "buffer (encoder or disk too slow), %llu stalls%s%s\n",
        c.name.c_str(), static_cast<unsigned long long>(st.stream.written),
        static_cast<unsigned long long>(st.stream.device_dropped + st.device.dropped),
        static_cast<unsigned long long>(st.stream.queue_dropped), static_cast<unsigned long long>(st.stalls),
        st.failed ? "; FAILED: " : "", st.failed ? st.failure.c_str() : "");
  }
}

/// Ends a recording stopped by a signal: the log is complete, so this is a success.
void note_interrupted(const RecordArgs& a, const acq::RecordSummary& s) {
  if (!s.interrupted) return;
  std::fprintf(stderr,
               "record: interrupted by %s after %.3f s of samples (%llu); %s is closed and complete\n",
               s.signal == SIGTERM   ? "SIGTERM"
               : s.signal == SIGHUP  ? "SIGHUP"
               : s.signal == SIGQUIT ? "SIGQUIT"
                                     : "SIGINT",
               s.duration_s, static_cast<unsigned long long>(s.samples), a.out_path.c_str());
}

/// `record --sim`: the virtual rig (sim/recording_rig.hpp) and its cameras, on simulated time
/// or, with --realtime, on CLOCK_MONOTONIC through the event loop and the eventfd data-ready line.
void run_record_sim(const RecordArgs& a, const RigConfig& config, const mpu::Settings& settings,
                    const acq::MountingMap& mounting, acq::RecordOptions& ro, Progress& progress) {
  sim::RecordingRigOptions o;
  o.settings = settings;
  o.mounting = mounting;
  o.cameras = config.cameras;
  o.target = config.target;
  o.seed = a.seed;
  o.clock_ppm = a.sim_clock_ppm;
  o.jitter_us = a.sim_jitter_us;
  o.motion = a.sim_motion;
  o.camera_content = a.sim_camera;
  o.duration_s = a.duration_s;
  o.realtime = a.realtime;
  if (!config.cameras.empty() && a.sim_camera == "render") {
    auto module = app::load_module<sim::RenderModuleApi>(sim::kRenderModule, sim::kRenderModuleEntry);
    if (!module.ok()) fail(module.error(), "simulated cameras");
    o.render = (*module)->scene_renderer;
  }
  auto made = sim::RecordingRig::create(o);
  if (!made.ok()) {
    if (made.error().code == Errc::kInvalidArgument)
      throw CliExit{kExitUsage, "--sim with " + a.config_path + ": " + made.error().message};
    fail(made.error(), "simulated rig");
  }
  sim::RecordingRig& rig = **made;
  for (std::size_t i = 0; i < rig.cameras().size(); ++i) {
    acq::RecordCamera rc;
    rc.camera = rig.cameras()[i].get();
    rc.info.name = config.cameras[i].name;
    rc.info.backend = "sim";
    rc.info.device = "sim";
    ro.cameras.push_back(rc);
  }
  ro.stream_info = rig.stream_info();
  ro.metadata.emplace_back("sim", rig.metadata());
  if (a.realtime) {
    ro.loop = acq::RecordLoop::kEventLoop;
    ro.stop_on_signals = true;
  }
  const auto summary = take(acq::record_imu_session(rig.acquisition(), ro), "recording");
  rig.stop();
  progress.finish();
  print_summary(a, summary, rig.metadata());
  if (a.realtime) note_interrupted(a, summary);
}

void run_record(const RecordArgs& a) {
  if (!(a.duration_s > 0.0) || !std::isfinite(a.duration_s)) {
    throw CliExit{kExitUsage, "--duration must be a positive number of seconds"};
  }
  if (auto s = app::check_not_input(a.out_path, {a.config_path}); !s.ok()) fail(s.error());
  const RigConfig config = take(load_rig_config(a.config_path), "reading the rig configuration");
  const bool sim = a.sim || config.imu.bus == ImuBus::kSim;
  if (a.realtime && !sim) throw CliExit{kExitUsage, "--realtime needs --sim (or imu.bus: sim)"};
  const acq::MountingMap mounting = take(app::imu_mounting(config.imu), "imu mounting in " + a.config_path);
  const mpu::Settings settings = settings_from(config.imu, a.config_path);

  acq::RecordOptions ro = app::record_options(config, sim);
  ro.log_path = a.out_path;
  ro.overwrite = a.force;
  ro.duration_s = a.duration_s;
  Progress progress("recording", a.duration_s);
  ro.progress = [&](double f) { progress.update(f * a.duration_s); };

  acq::AcquisitionOptions ao;
  if (sim) {
    run_record_sim(a, config, settings, mounting, ro, progress);
    return;
  }

  // Hardware: a missing node or a silent chip is a device problem here, not a missing input.
  auto rig = app::open_imu_rig(config, ao);
  if (!rig.ok()) throw CliExit{kExitDevice, rig.error().message};
  // Every configured camera is opened and configured before the log exists: a missing camera or a
  // refused format stops here, with nothing written.
  auto cameras = app::open_rig_cameras(config);
  if (!cameras.ok()) {
    const Errc code = cameras.error().code;
    throw CliExit{code == Errc::kNotFound || code == Errc::kDevice ? kExitDevice : kExitUsage,
                  cameras.error().message};
  }
  ro.cameras = cameras->record;
  ro.stream_info = (*rig)->stream_info();
  ro.loop = acq::RecordLoop::kEventLoop;
  ro.stop_on_signals = true;
  const auto summary = take(acq::record_imu_session((*rig)->source(), ro), "recording");
  progress.finish();
  print_summary(a, summary, "");
  note_interrupted(a, summary);
}

const CommandRegistrar kRegistrar(20, [](CLI::App& root) {
  auto args = std::make_shared<RecordArgs>();
  auto* cmd = root.add_subcommand(
      "record",
      "Record the rig's IMU and every configured camera into one session log on one clock: IMU timestamps "
      "reconstructed per sample from the data-ready interrupt (or the kernel's, when its inv-mpu6050 driver "
      "owns the chip: imu.driver), gaps flagged; frames stamped by their camera "
      "on CLOCK_MONOTONIC and stored losslessly. --sim records the virtual rig (and its virtual cameras) "
      "through the same driver and acquisition code.");
  cmd->add_option("--config", args->config_path, "Rig configuration (YAML, docs/config.md)")->required();
  cmd->add_option("-o,--output", args->out_path, "Session log to write (.imulog)")->required();
  cmd->add_option("--duration", args->duration_s, "Seconds of samples to record (default 10)");
  cmd->add_flag("--sim", args->sim,
                "Record the simulated rig (MPU-6000 register emulator, data-ready jitter) instead of "
                "hardware; simulated time runs as fast as the host allows");
  cmd->add_flag(
      "--realtime", args->realtime,
      "With --sim: run the emulated chip in real time (CLOCK_MONOTONIC) and record it through "
      "the event loop a rig uses (data-ready edges on a file descriptor, a poll timer); takes "
      "--duration seconds of wall-clock time. SIGINT/SIGTERM/SIGHUP/SIGQUIT stop it with a complete log");
  cmd->add_option("--seed", args->seed, "Simulation: random seed (default 1)");
  cmd->add_option("--sim-clock-ppm", args->sim_clock_ppm,
                  "Simulation: the chip oscillator's error in ppm (default -15000, a 1.5 % slow chip)")
      ->check(CLI::Range(-80'000.0, 80'000.0));
  cmd->add_option("--sim-jitter-us", args->sim_jitter_us,
                  "Simulation: standard deviation of the data-ready edge latency, us (default 30)")
      ->check(CLI::Range(0.0, 1000.0));
  cmd->add_option(
         "--sim-motion", args->sim_motion,
         "Simulation: what the rig does: still (at rest on a table), static (the multi-position "
         "protocol of `imucal sim static`: 50 s still, then 40 poses; about 3.5 min) or checkerboard "
         "(moved in front of the configured target, as `imucal sim camimu`; the simulated cameras need it) "
         "(default: checkerboard when the configuration has cameras, else still)")
      ->check(CLI::IsMember({"still", "static", "checkerboard"}));
  cmd->add_option(
         "--sim-camera", args->sim_camera,
         "Simulation: what the simulated cameras show: render (the configured target as the rig "
         "moves, through the camera model; costly at high resolutions) or pattern (a cheap moving test "
         "pattern, for measuring the recording path at any frame rate) (default render)")
      ->check(CLI::IsMember({"render", "pattern"}));
  cmd->add_flag("--force", args->force, "Replace the log if it exists");
  cmd->add_flag("--json", args->json, "Print the summary as JSON");
  cmd->callback([args] { run_record(*args); });
});

}  // namespace
}  // namespace imucal::cli
