// SPDX-License-Identifier: BSD-3-Clause
// imucal sim static|gsens|still|camimu: simulated MPU-6000 recordings with their ground truth
// (docs/simulator.md, docs/simulator-camera.md).

#include <fcntl.h>
#include <fmt/printf.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "app/module_loader.hpp"
#include "app/results/output_checks.hpp"
#include "core/text_format.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"
#include "log/dataset_io.hpp"
#include "log/session_log.hpp"
#include "sim/camera_scene.hpp"
#include "sim/camimu.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/motion.hpp"
#include "sim/render_module.hpp"
#include "sim/rig.hpp"
#include "sim/session.hpp"
#include "sim/truth.hpp"

namespace imucal::cli {
namespace {

/// The file at a path before a run, held (O_PATH: nothing opened for reading or writing, a device
/// untouched) so that its inode cannot be reused: a log the run did not replace is still it.
class FileBefore {
 public:
  explicit FileBefore(const std::string& path) : fd_(::open(path.c_str(), O_PATH | O_CLOEXEC | O_NOFOLLOW)) {}
  ~FileBefore() {
    if (fd_ >= 0) ::close(fd_);
  }
  FileBefore(const FileBefore&) = delete;
  FileBefore& operator=(const FileBefore&) = delete;
  /// True when `path` names the file that was there.
  bool still_at(const std::string& path) const {
    struct stat held {};
    struct stat now {};
    return fd_ >= 0 && ::fstat(fd_, &held) == 0 && ::lstat(path.c_str(), &now) == 0 &&
           held.st_dev == now.st_dev && held.st_ino == now.st_ino;
  }

 private:
  int fd_;
};

/// What a log that stopped early (a write failed) still holds, for the error message. A file the
/// run never replaced (another recording's live log, refused) holds nothing of this run's.
std::string kept_in(const std::string& log_path, const FileBefore& before) {
  if (before.still_at(log_path))
    return "; nothing was written: " + log_path + " is the file that was there before, left as it was";
  auto reader = log::SessionLogReader::open(log_path);
  if (!reader.ok() || (*reader)->imu_streams().empty()) return "; nothing was kept";
  const int id = (*reader)->imu_streams().begin()->first;
  auto samples = (*reader)->read_imu(id);
  if (!samples.ok() || samples->empty()) return "; nothing was kept";
  const double span = ns_to_s(samples->back().t_ns - samples->front().t_ns);
  return fmt::sprintf("; stopped, %zu samples (%.1f s) kept in %s, readable and marked incomplete",
                      samples->size(), span, log_path.c_str());
}

struct SimCommon {
  std::uint64_t seed = 1;
  double imu_rate_hz = 100.0;
  int accel_range_g = 4;
  int gyro_range_dps = 500;
  std::string truth_in;
  std::string out_path;
  bool force = false;
  bool tremor = false;
  bool no_noise = false;
  std::vector<std::string> drops;
  std::string bus = "spi";
  double clock_ppm = sim::kDefaultClockPpm;
  double jitter_us = 30.0;
  // Die temperature (sim still): profile and bias-temperature coefficients drawn from the seed.
  std::string temp_profile;
  double temp_start_c = 30.0;
  double temp_final_c = 36.0;
  double temp_tau_s = 600.0;
  double temp_ramp_s = 600.0;
  double temp_step_s = 0.0;
  int temp_coeff_order = 0;
  // Die temperature held (sim static) and scale against temperature (every command), ppm/K.
  std::optional<double> temp_hold_c;
  std::vector<double> accel_scale_tc_ppm, gyro_scale_tc_ppm;

  sim::SimImuPath path() const {
    sim::SimImuPath p;
    p.bus = bus == "i2c" ? drivers::mpu6000::BusKind::kI2c : drivers::mpu6000::BusKind::kSpi;
    p.clock_ppm = clock_ppm;
    p.data_ready.sigma_ns = static_cast<TimeNs>(std::llround(jitter_us * 1e3));
    return p;
  }
};

void add_common(CLI::App* cmd, SimCommon& o, bool drops = true) {
  cmd->add_option("--seed", o.seed, "Random seed: the same seed gives the same recording (default 1)");
  cmd->add_option("--imu-rate", o.imu_rate_hz,
                  "IMU output rate in Hz: 1000/n (DLPF on) or 8000/n (DLPF off), n = 1..256 (default 100; "
                  "camimu 200)")
      ->check(CLI::Range(4.0, 8000.0));
  cmd->add_option("--bus", o.bus,
                  "Bus of the emulated MPU-6000: spi (20 MHz reads) or i2c (400 kHz) (default spi)")
      ->check(CLI::IsMember({"spi", "i2c"}));
  cmd->add_option(
         "--clock-ppm", o.clock_ppm,
         "The emulated chip's oscillator error against the host clock in ppm; it sets how many samples a "
         "second arrive (default -15000: 1.5 % slow)")
      ->check(CLI::Range(-80'000.0, 80'000.0));
  cmd->add_option("--jitter-us", o.jitter_us,
                  "Standard deviation of the data-ready interrupt latency in us (default 30)")
      ->check(CLI::Range(0.0, 1000.0));
  cmd->add_option("--accel-range", o.accel_range_g,
                  "Accelerometer full-scale range in g: 2, 4, 8, 16 (default 4)")
      ->check(CLI::IsMember({2, 4, 8, 16}));
  cmd->add_option("--gyro-range", o.gyro_range_dps,
                  "Gyroscope full-scale range in deg/s: 250, 500, 1000, 2000 (default 500)")
      ->check(CLI::IsMember({250, 500, 1000, 2000}));
  cmd->add_option("--truth", o.truth_in,
                  "Take the IMU parameters from this truth file (its imu: section) instead of drawing them "
                  "from the seed; --accel-range/--gyro-range still apply when given");
  cmd->add_flag("--tremor", o.tremor, "Add a small hand tremor to the whole script");
  cmd->add_option(
         "--accel-scale-tc", o.accel_scale_tc_ppm,
         "Accelerometer scale against die temperature, ppm/K about 25 deg C, per axis: X,Y,Z (default "
         "those of --truth, or 0)")
      ->delimiter(',')
      ->expected(3)
      ->check(CLI::Range(-9999.0, 9999.0));
  cmd->add_option(
         "--gyro-scale-tc", o.gyro_scale_tc_ppm,
         "Gyro scale against die temperature, ppm/K about 25 deg C, per axis: X,Y,Z (default those of "
         "--truth, or 0)")
      ->delimiter(',')
      ->expected(3)
      ->check(CLI::Range(-9999.0, 9999.0));
  cmd->add_flag("--no-noise", o.no_noise, "Switch off white noise and bias random walks (for tests)");
  if (drops) {
    cmd->add_option(
        "--drop", o.drops,
        "Stall the host for START:DURATION (seconds from the start): the chip's FIFO holds 73 samples, "
        "what it cannot hold is lost and the next sample is flagged as after a gap. Repeatable");
  }
  cmd->add_option("-o,--output", o.out_path, "Session log to write (.imulog); the truth goes to .truth.yaml")
      ->required();
  cmd->add_flag("--force", o.force, "Replace the log and truth file if they exist");
}

std::vector<sim::SampleDrop> parse_drops(const std::vector<std::string>& specs) {
  std::vector<sim::SampleDrop> drops;
  for (const std::string& spec : specs) {
    const auto colon = spec.find(':');
    sim::SampleDrop d;
    const auto start = colon == std::string::npos ? std::nullopt : parse_finite_number(spec.substr(0, colon));
    const auto duration =
        colon == std::string::npos ? std::nullopt : parse_finite_number(spec.substr(colon + 1));
    if (!start || !duration) {
      throw CliExit{kExitUsage,
                    "--drop: expected START:DURATION in seconds (e.g. 120:0.5), got '" + spec + "'"};
    }
    d.start_s = *start;
    d.duration_s = *duration;
    if (!(d.start_s >= 0.0 && d.duration_s > 0.0)) {
      throw CliExit{kExitUsage, "--drop: START must be >= 0 and DURATION > 0, got '" + spec + "'"};
    }
    drops.push_back(d);
  }
  return drops;
}

/// The IMU parameters: from --truth or drawn from the seed; ranges and noise switches applied.
sim::ImuModelParams make_params(const SimCommon& o, const CLI::App* cmd, bool* from_file) {
  sim::ImuModelParams p;
  *from_file = !o.truth_in.empty();
  if (*from_file) {
    auto loaded = sim::load_imu_params(o.truth_in);
    if (!loaded.ok()) fail(loaded.error(), "--truth");
    p = *loaded;
    if (cmd->count("--accel-range") > 0) p.accel_full_scale_g = o.accel_range_g;
    if (cmd->count("--gyro-range") > 0) p.gyro_full_scale_dps = o.gyro_range_dps;
  } else {
    p = sim::ImuModelParams::draw(o.seed);
    p.accel_full_scale_g = o.accel_range_g;
    p.gyro_full_scale_dps = o.gyro_range_dps;
  }
  if (!o.temp_profile.empty()) {
    auto profile = sim::parse_temperature_profile(o.temp_profile);
    if (!profile.ok()) throw CliExit{kExitUsage, "--temp-profile: " + profile.error().message};
    p.temp_profile = *profile;
    p.temp_start_c = o.temp_start_c;
    p.temp_final_c = o.temp_final_c;
    p.temp_time_constant_s = o.temp_tau_s;
    p.temp_ramp_s = o.temp_ramp_s;
    p.temp_step_time_s = o.temp_step_s;
  }
  if (o.temp_coeff_order > 0) p.draw_temperature_coefficients(o.seed, o.temp_coeff_order);
  if (o.temp_hold_c) {
    p.temp_profile = sim::TemperatureProfile::kSoak;
    p.temp_start_c = p.temp_final_c = *o.temp_hold_c;
  }
  if (o.accel_scale_tc_ppm.size() == 3)
    p.accel_scale_temp_coeff = Eigen::Vector3d(o.accel_scale_tc_ppm.data()) * 1e-6;
  if (o.gyro_scale_tc_ppm.size() == 3)
    p.gyro_scale_temp_coeff = Eigen::Vector3d(o.gyro_scale_tc_ppm.data()) * 1e-6;
  if (o.no_noise) {
    p.accel_noise_density = p.gyro_noise_density = 0.0;
    p.accel_bias_random_walk = p.gyro_bias_random_walk = 0.0;
  }
  auto status = p.validate();
  if (!status.ok()) fail(status.error(), "IMU parameters");
  return p;
}

/// The log and its truth file, checked before the work: never an input (--truth, --target), never
/// a device, FIFO, socket or folder, and an existing file only with --force.
void refuse_overwrite(const SimCommon& o, const std::string& truth_path,
                      const std::vector<std::string>& more_inputs = {}) {
  std::vector<std::string> inputs = more_inputs;
  inputs.push_back(o.truth_in);
  std::error_code ec;
  for (const std::string& p : {o.out_path, truth_path}) {
    if (auto s = app::check_not_input(p, inputs); !s.ok()) fail(s.error());
    if (auto s = log::check_replaceable(p); !s.ok()) fail(s.error());
    if (!o.force && std::filesystem::exists(p, ec)) {
      throw CliExit{kExitUsage, p + " exists; pass --force to replace it"};
    }
  }
}

void run(const SimCommon& o, const CLI::App* cmd, const std::string& kind, const std::string& script,
         const sim::Trajectory& traj, int poses) {
  sim::SimImuSessionOptions opt;
  opt.kind = kind;
  opt.script = script;
  opt.poses = poses;
  opt.seed = o.seed;
  opt.imu_rate_hz = o.imu_rate_hz;
  opt.path = o.path();
  opt.imu = make_params(o, cmd, &opt.params_from_file);
  opt.drops = parse_drops(o.drops);
  opt.overwrite = o.force;
  const std::string truth_path = sim::truth_path_for(o.out_path);
  refuse_overwrite(o, truth_path);
  const FileBefore before(o.out_path);
  Progress progress("simulating " + kind, 1.0);
  auto truth = sim::write_sim_imu_session(opt, traj, o.out_path, truth_path,
                                          [&progress](double done) { progress.update(done); });
  progress.finish();
  if (!truth.ok()) {
    const Error& e = truth.error();
    // A refused overwrite is answered as in every command (exit 2), an unwritable path is exit 7.
    if (e.code == Errc::kAlreadyExists) throw CliExit{kExitUsage, e.message + "; pass --force to replace it"};
    if (e.code == Errc::kIo)
      throw CliExit{kExitIo, "sim " + kind + ": " + e.message + kept_in(o.out_path, before)};
    fail(e, "sim " + kind);
  }
  std::ostringstream msg;
  msg.precision(4);
  msg << "wrote " << truth->recording.samples << " samples (" << truth->trajectory.duration_s << " s at "
      << o.imu_rate_hz << " Hz nominal, chip clock " << std::showpos << std::lround(o.clock_ppm)
      << std::noshowpos << " ppm";
  if (poses > 1) msg << ", " << poses << " poses";
  msg << ") to " << o.out_path << "\n";
  msg << "truth: " << truth_path << "\n";
  msg << "mean |a| " << truth->trajectory.mean_accel_mps2 << " m/s^2, mean |w| "
      << truth->trajectory.mean_rate_radps << " rad/s";
  if (truth->recording.accel_saturated + truth->recording.gyro_saturated > 0) {
    msg << "\nsaturated samples: accel " << truth->recording.accel_saturated << ", gyro "
        << truth->recording.gyro_saturated;
  }
  if (truth->recording.dropped_samples > 0) {
    msg << "\ndropped samples: " << truth->recording.dropped_samples;
    if (o.drops.empty()) {
      msg << " (no host stall was asked for: the bus cannot carry this rate; docs/mpu6000.md gives the FIFO "
             "budget per bus)";
    }
  }
  std::cout << msg.str() << "\n";
}

template <class T>
T take(Result<T> r, const std::string& what) {
  if (!r.ok()) fail(r.error(), what);
  return std::move(r).value();
}

/// `sim static`: the multi-position protocol.
void add_static(CLI::App* sim) {
  auto o = std::make_shared<SimCommon>();
  auto so = std::make_shared<sim::StaticProtocolOptions>();
  CLI::App* cmd = sim->add_subcommand(
      "static", "Multi-position protocol (Tedaldi et al.): still period, then N attitudes held 1-4 s");
  add_common(cmd, *o);
  cmd->add_option("--poses", so->poses, "Number of attitudes, 9..100 (default 40)")
      ->check(CLI::Range(9, 100));
  cmd->add_option("--still", so->initial_still_s, "Initial still period in s (default 50)")
      ->check(CLI::Range(1.0, 3600.0));
  cmd->add_option("--hold-min", so->hold_min_s, "Shortest hold in s (default 1)")->check(kPositive);
  cmd->add_option("--hold-max", so->hold_max_s, "Longest hold in s (default 4)")->check(kPositive);
  cmd->add_option("--temp-hold", o->temp_hold_c,
                  "Die temperature held throughout, deg C (default: the model's own warm-up, 30 to 36 deg C "
                  "over 600 s)")
      ->check(CLI::Range(-40.0, 85.0));
  cmd->add_option("--excitation", so->excitation,
                  "Speed of the moves: 1 is a calm hand; 3 exceeds +-2 g and +-250 deg/s (default 1)")
      ->check(CLI::Range(0.1, 10.0));
  cmd->callback([o, so, cmd]() {
    so->tremor.enabled = o->tremor;
    auto traj = take(sim::make_static_protocol(*so, o->seed), "sim static");
    run(*o, cmd, "static", "static", *traj, traj->poses());
  });
}

/// `sim gsens`: six faces for the g-sensitivity experiment.
void add_gsens(CLI::App* sim) {
  auto o = std::make_shared<SimCommon>();
  auto fo = std::make_shared<sim::SixFaceOptions>();
  CLI::App* cmd =
      sim->add_subcommand("gsens", "Six-face holds for the gyroscope g-sensitivity experiment (Krebs 5.2.3)");
  add_common(cmd, *o);
  cmd->add_option("--hold", fo->hold_s, "Hold per face in s (default 30)")->check(CLI::Range(1.0, 3600.0));
  auto faces = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--faces", *faces,
                  "The faces held, in order, as a comma-separated list of +z,-y,-z,+y,+x,-x (the axis that "
                  "points up; default all six in that order)")
      ->delimiter(',')
      ->check(CLI::IsMember({"+z", "-y", "-z", "+y", "+x", "-x"}));
  cmd->add_option("--revisits", fo->revisits,
                  "Further holds after the faces, each on another face than the last, turned about the "
                  "vertical by 20-60 deg as well (default 0)")
      ->check(CLI::Range(0, 1000));
  cmd->add_option("--revisit-hold", fo->revisit_hold_s, "Hold per revisit in s (default 3)")
      ->check(CLI::Range(1.0, 3600.0));
  cmd->callback([o, fo, faces, cmd]() {
    fo->tremor.enabled = o->tremor;
    fo->faces.clear();
    for (const auto& f : *faces) {
      const auto& names = sim::six_face_names();
      const auto at = std::find(names.begin(), names.end(), f + " up");
      fo->faces.push_back(static_cast<int>(at - names.begin()));
    }
    auto traj = take(sim::make_six_face(*fo, o->seed), "sim gsens");
    run(*o, cmd, "gsens", "six-face", *traj, traj->poses());
  });
}

/// The simulated camera's sensor and shutter: --resolution, --line-delay, --readout, --stamp-row.
struct SimCameraArgs {
  std::string resolution;
  std::string model;               // Kalibr's name; empty: pinhole-radtan
  std::vector<double> intrinsics;  // Kalibr's order for the model; empty: the preset lens's
  std::vector<double> distortion;
  double line_delay_us = 0.0;
  ShutterArgs shutter;  // its readout and stamp_row
};

void add_sim_camera_options(CLI::App* cmd, SimCameraArgs* a) {
  cmd->add_option(
         "--camera-model", a->model,
         "Lens model, Kalibr's names: pinhole-radtan (default), pinhole-equi, pinhole-fov, omni-none, "
         "omni-radtan, eucm-none, ds-none; a lens of that model on the sensor (eucm-none and ds-none: "
         "about 195 degrees across), its parameters in the truth file")
      ->check(CLI::IsMember({"pinhole-radtan", "pinhole-equi", "pinhole-fov", "pinhole-none", "omni-none",
                             "omni-radtan", "eucm-none", "ds-none"}));
  cmd->add_option("--camera-intrinsics", a->intrinsics,
                  "The lens's intrinsics in Kalibr's order for its model, comma-separated: fu,fv,pu,pv; omni "
                  "xi first; eucm alpha,beta first; ds xi,alpha first (default: the model's preset lens)")
      ->delimiter(',');
  cmd->add_option("--camera-distortion", a->distortion,
                  "The lens's distortion_coeffs, comma-separated: radtan k1,k2,p1,p2; equi k1..k4; fov w "
                  "(default: the model's preset lens)")
      ->delimiter(',');
  cmd->add_option("--resolution", a->resolution,
                  "Camera resolution WIDTHxHEIGHT, the default lens on that sensor (default 376x240; the "
                  "WVGA sensor unbinned is 752x480)");
  CLI::Option* line_delay =
      cmd->add_option(
             "--line-delay", a->line_delay_us,
             "Rolling shutter: microseconds between the starts of consecutive rows (0: global shutter, "
             "the default; 30 us on 480 rows reads a frame out in 14.4 ms). Every camera renders each "
             "row at its own time and the truth has the line delay")
          ->check(CLI::Range(0.0, 1000.0));
  cmd->add_option("--readout", a->shutter.readout,
                  "With --line-delay: top_to_bottom (default) or bottom_to_top")
      ->check(CLI::IsMember({"top_to_bottom", "bottom_to_top"}))
      ->needs(line_delay);
  cmd->add_option("--stamp-row", a->shutter.stamp_row,
                  "With --line-delay: the row whose mid-exposure the frame's stamp marks: first (default), "
                  "middle or last")
      ->check(CLI::IsMember({"first", "middle", "last"}))
      ->needs(line_delay);
}

/// The camera the arguments describe (the default lens on the given sensor, its shutter).
void apply_sim_camera_args(const SimCameraArgs& a, CameraModel* camera) {
  int w = camera->width, h = camera->height;
  if (!a.resolution.empty()) {
    char x = 0;
    std::istringstream in(a.resolution);
    if (!(in >> w >> x >> h) || x != 'x' || !in.eof() || w < 16 || h < 16 || w > 8192 || h > 8192)
      throw CliExit{kExitUsage, "--resolution takes WIDTHxHEIGHT in pixels, 16-8192 each, e.g. 752x480"};
  }
  const auto model = parse_camera_model_name(a.model.empty() ? "pinhole-radtan" : a.model);
  if (!model) throw CliExit{kExitUsage, "--camera-model: unknown model '" + a.model + "'"};
  if (!a.resolution.empty() || !a.model.empty()) *camera = sim::sim_camera_for(w, h, *model);
  if (!a.intrinsics.empty() || !a.distortion.empty()) {
    std::vector<double> intrinsics = a.intrinsics;
    if (intrinsics.empty())
      intrinsics = kalibr_intrinsics(camera->projection, camera->intrinsics, camera->projection_params);
    if (auto s = set_kalibr_parameters(camera, intrinsics, a.distortion); !s.ok())
      throw CliExit{kExitUsage, "--camera-intrinsics/--camera-distortion: " + s.error().message};
  }
  if (a.line_delay_us > 0.0) {
    camera->shutter.kind = Shutter::Kind::kRolling;
    camera->shutter.line_delay_s = a.line_delay_us * 1e-6;
    apply_shutter_args(a.shutter, &camera->shutter);
  }
}

/// `sim camimu`: checkerboard motion with rendered frames, through its own session writer.
void add_camimu(CLI::App* sim) {
  auto o = std::make_shared<SimCommon>();
  auto co = std::make_shared<sim::CamImuSimOptions>();
  o->imu_rate_hz = co->imu_rate_hz;
  CLI::App* cmd = sim->add_subcommand(
      "camimu", "Camera-IMU session: checkerboard motion (Krebs 5.1.1) with rendered camera frames");
  add_common(cmd, *o, false);
  cmd->add_option("--duration", co->motion.duration_s,
                  "Length in s (default " + std::to_string(static_cast<int>(co->motion.duration_s)) + ")")
      ->check(CLI::Range(10.0, 3600.0));
  cmd->add_option("--camera-rate", co->camera_rate_hz, "Camera frame rate in Hz (default 20)")
      ->check(CLI::Range(1.0, 200.0));
  cmd->add_option("--excitation", co->motion.excitation,
                  "Scales the motion: mean |a| 3.12 m/s^2 and mean |w| 0.366 rad/s times this (default 1)")
      ->check(CLI::Range(0.1, 10.0));
  auto target_path = std::make_shared<std::string>();
  cmd->add_option(
      "--target", *target_path,
      "Kalibr target YAML to render: checkerboard or aprilgrid (default: checkerboard, 7 x 6 inner "
      "corners, 5 cm; e.g. config/aprilgrid-6x6.yaml)");
  auto stereo = std::make_shared<bool>(false);
  auto cam1_offset_ms = std::make_shared<double>(0.0);
  CLI::Option* stereo_flag = cmd->add_flag(
      "--stereo", *stereo,
      "A second camera, cam1: 11 cm beside cam0 along its x axis, turned by about a degree, with its "
      "own intrinsics (a stereo pair; the truth file has both cameras and T_cn_cnm1)");
  cmd->add_option("--cam1-offset-ms", *cam1_offset_ms,
                  "With --stereo: cam1 stamps its frames this many ms later than cam0 for the same scene "
                  "(cameras that are not synchronized; default 0)")
      ->check(CLI::Range(-100.0, 100.0))
      ->needs(stereo_flag);
  auto camera_args = std::make_shared<SimCameraArgs>();
  add_sim_camera_options(cmd, camera_args.get());
  cmd->callback([o, co, cmd, target_path, stereo, cam1_offset_ms, camera_args]() {
    apply_sim_camera_args(*camera_args, &co->camera);
    if (!target_path->empty()) {
      auto target = load_target_yaml(*target_path);
      if (!target.ok()) fail(target.error(), "sim camimu --target");
      co->target = *target;
    }
    if (*stereo) {
      co->more_cameras = {sim::CamImuSimOptions::default_stereo_camera(
          co->camera, co->T_cam_imu, co->timeshift_cam_imu_s, 1e-3 * *cam1_offset_ms)};
      co->more_cameras.back().camera.shutter = co->camera.shutter;
    }
    co->seed = o->seed;
    co->imu_rate_hz = o->imu_rate_hz;
    co->imu_path = o->path();
    co->motion.tremor.enabled = o->tremor;
    co->imu = make_params(*o, cmd, &co->imu_params_from_file);
    co->overwrite = o->force;
    const std::string truth_path = sim::truth_path_for(o->out_path);
    refuse_overwrite(*o, truth_path, {*target_path});
    auto valid = co->validate();
    if (!valid.ok()) fail(valid.error(), "sim camimu");
    auto render = app::load_module<sim::RenderModuleApi>(sim::kRenderModule, sim::kRenderModuleEntry);
    if (!render.ok()) fail(render.error(), "sim camimu");
    sim::CamImuSimSummary summary;
    Progress progress("simulating camimu", 1.0);
    auto status = (*render)->camimu_session(
        *co, o->out_path, truth_path, [&progress](double done) { progress.update(done); }, &summary);
    progress.finish();
    if (!status.ok()) {
      if (status.error().code == Errc::kAlreadyExists) {
        throw CliExit{kExitUsage, status.error().message + "; pass --force to replace it"};
      }
      fail(status.error(), "sim camimu");
    }
    std::ostringstream msg;
    msg.precision(4);
    msg << "wrote " << summary.imu_samples << " samples and " << summary.frames << " frames of "
        << 1 + co->more_cameras.size() << (co->more_cameras.empty() ? " camera (" : " cameras (")
        << summary.duration_s << " s, IMU " << co->imu_rate_hz << " Hz, camera " << co->camera_rate_hz
        << " Hz) to " << o->out_path << "\n";
    msg << "truth: " << truth_path << "\n";
    msg << "mean |a| " << summary.mean_accel_mps2 << " m/s^2, mean |w| " << summary.mean_rate_radps
        << " rad/s; frames with the whole board " << summary.frames_all_corners_visible
        << ", without any corner " << summary.frames_no_corner_visible;
    std::cout << msg.str() << "\n";
  });
}

/// `sim still`: a long still recording.
void add_still(CLI::App* sim) {
  auto o = std::make_shared<SimCommon>();
  auto so = std::make_shared<sim::StillOptions>();
  CLI::App* cmd =
      sim->add_subcommand("still", "A long still recording (Allan variance), on a table by default");
  add_common(cmd, *o);
  cmd->add_option("--duration", so->duration_s, "Length in s (default 600)")
      ->check(CLI::Range(1.0, 172800.0));
  auto* profile =
      cmd->add_option("--temp-profile", o->temp_profile,
                      "Die temperature over the recording: warmup (first-order from --temp-start "
                      "towards --temp-final, time constant --temp-tau), soak (linear ramp over "
                      "--temp-ramp, then held), step (held until --temp-step-at, then first-order); "
                      "default: the model's own warm-up, 30 to 36 deg C over 600 s")
          ->check(CLI::IsMember({"warmup", "soak", "step"}));
  cmd->add_option("--temp-start", o->temp_start_c, "Die temperature at the start, deg C (default 30)")
      ->check(CLI::Range(-40.0, 85.0))
      ->needs(profile);
  cmd->add_option("--temp-final", o->temp_final_c, "Die temperature approached, deg C (default 36)")
      ->check(CLI::Range(-40.0, 85.0))
      ->needs(profile);
  cmd->add_option("--temp-tau", o->temp_tau_s, "Time constant of warmup and step, s (default 600)")
      ->check(CLI::Range(1.0, 1e6))
      ->needs(profile);
  cmd->add_option("--temp-ramp", o->temp_ramp_s, "Length of the soak's ramp, s (default 600)")
      ->check(CLI::Range(1.0, 1e6))
      ->needs(profile);
  cmd->add_option("--temp-step-at", o->temp_step_s, "Time of the step, s from the start (default 0)")
      ->check(CLI::Range(0.0, 1e6))
      ->needs(profile);
  cmd->add_option(
         "--temp-coeffs", o->temp_coeff_order,
         "Draw the bias-temperature coefficients from the seed, a polynomial of this order (1..3) "
         "per axis (ImuModelParams::draw_temperature_coefficients); default: those of --truth, or none")
      ->check(CLI::Range(1, 3));
  cmd->callback([o, so, cmd]() {
    so->tremor.enabled = o->tremor;
    auto traj = take(sim::make_still(*so, o->seed), "sim still");
    run(*o, cmd, "still", "still", *traj, 1);
  });
}

void setup(CLI::App& root) {
  CLI::App* sim = root.add_subcommand(
      "sim", "Simulate an MPU-6000 rig recording (static protocol, six faces, long still) with ground truth");
  sim->require_subcommand(1);
  add_static(sim);
  add_gsens(sim);
  add_camimu(sim);
  add_still(sim);
}

const CommandRegistrar registrar(10, setup);

}  // namespace
}  // namespace imucal::cli
