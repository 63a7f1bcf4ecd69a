// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate camimu LOG: camera-IMU extrinsics, time offsets and the IMU's intrinsics from
// the target seen by the cameras while the rig moves, see docs/camimu-calibration.md.

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/camimu_inputs.hpp"
#include "app/results/camera_results.hpp"
#include "app/results/camimu_results.hpp"
#include "app/results/output.hpp"
#include "app/solvers.hpp"
#include "daemon/cli/bag_input.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

struct CamImuCliOptions {
  std::string log_path;
  std::vector<std::string> topics;  // LOG a ROS bag: the topics to import
  std::vector<std::string> camera_paths;
  std::string target_path;
  std::string imu_path;
  std::string imu_intrinsics_path;
  std::string thermal_path;
  std::string gsens_path;
  std::string imu_stream;
  std::string model = "auto";
  ShutterArgs shutter;
  bool keep_noise = false;
  bool no_prior = false;
  std::vector<std::string> fix;
  calib::CamImuOptions defaults;
  GravityArgs grav;
  int threads = 0;
  int self_check = 2;
  bool allow_damaged = false;
  DetectionStoreArgs detections;
  bool force = false;
  bool json = false;
  std::string out_dir;
};

constexpr double kDeg = 180.0 / M_PI;

/// The target: --target, else the one the log names.

/// The result files in OUT_DIR, checked before the work: never an input, never an existing file
/// without --force.
std::vector<std::string> check_outputs(const CamImuCliOptions& o, const app::OutputPolicy& policy) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(o.out_dir, ec) && !fs::is_directory(o.out_dir, ec))
    throw CliExit{kExitUsage, o.out_dir + " is a file: -o takes the folder to write the results into"};
  std::vector<std::string> paths;
  for (const char* name : {app::kCamchainImucamFile, app::kCamImuImuFile, app::kCamImuImuResultFile,
                           app::kCamImuCalibrationFile, app::kCamImuJsonFile}) {
    paths.push_back((fs::path(o.out_dir) / name).string());
    if (auto s = app::check_output(paths.back(), policy); !s.ok()) fail(s.error());
  }
  return paths;
}

/// The method's options from the command line, checked before the log is read.
app::CamImuRequest build_request(const CamImuCliOptions& o) {
  app::CamImuRequest q;
  const calib::ShutterSolveOptions shutter = shutter_solve_options(o.shutter);  // exit 2 before any work
  q.log_path = o.log_path;
  q.imu_stream = o.imu_stream;
  if (!o.camera_paths.empty()) {
    auto cams = app::read_camchain_files(o.camera_paths);
    if (!cams.ok()) fail(cams.error(), "--camera");
    q.cameras = std::move(*cams);
  }
  if (!o.imu_path.empty()) {
    auto noise = app::read_kalibr_imu_noise(o.imu_path);
    if (!noise.ok()) fail(noise.error(), "--imu");
    q.imu_noise = *noise;
    q.imu_noise_source = o.imu_path;
    auto topic = app::read_kalibr_imu_topic(o.imu_path);
    if (!topic.ok()) fail(topic.error(), "--imu");
    q.imu_rostopic = topic->rostopic;
    q.imu_update_rate = topic->update_rate;
  }
  if (!o.imu_intrinsics_path.empty()) {
    auto c = app::read_imucal_calibration(o.imu_intrinsics_path);
    if (!c.ok()) fail(c.error(), "--imu-intrinsics");
    q.imu_intrinsics = *c;
  }
  if (!o.thermal_path.empty()) {
    auto t = app::read_thermal_file(o.thermal_path);
    if (!t.ok()) fail(t.error(), "--thermal");
    q.thermal = std::move(*t);
  }
  if (!o.gsens_path.empty()) {
    auto g = app::read_gsens_input(o.gsens_path);
    if (!g.ok()) fail(g.error(), "--gsens");
    q.gsens = *g;
  }
  q.options = o.defaults;
  q.options.model = o.model == "basic"      ? CamImuModelKind::kBasic
                    : o.model == "extended" ? CamImuModelKind::kExtended
                                            : CamImuModelKind::kAuto;
  q.options.shutter = shutter;
  for (auto& cam : q.cameras) {
    apply_shutter_args(o.shutter, &cam.camera.shutter);
    cam.stamp_row_given = cam.stamp_row_given || !o.shutter.stamp_row.empty();
  }
  q.options.imu_noise_from_residuals = !o.keep_noise;
  q.options.prior.enabled = !o.no_prior;
  for (const auto& name : o.fix) {
    if (auto s = app::set_fixed_block(name, &q.options.fixed); !s.ok()) fail(s.error(), "--fix");
  }
  const app::GravityChoice gravity = resolve_gravity(o.grav);
  q.options.gravity_mps2 = gravity.mps2;
  q.gravity_source = gravity.source;
  q.options.threads = o.threads;
  q.threads = o.threads;
  q.self_check_parts = o.self_check;
  q.allow_damaged = o.allow_damaged;
  q.reuse_detections = !o.detections.no_reuse;
  q.store_detections = o.detections.store_in_log;
  q.cache_dir = detection_cache_dir(o.detections);
  return q;
}

/// "0.1234" with `digits` decimals, or the words for a sigma that has none.
std::string sig(double v, int digits, bool fixed = false) {
  if (fixed) return "fixed";
  if (!std::isfinite(v)) return "not determined";
  return fmt::format("{:.{}f}", v, digits);
}

std::string sig3(const Eigen::Vector3d& s, double k, int digits, bool fixed = false) {
  if (fixed) return "fixed";
  if (!s.allFinite() && !s.array().isFinite().any()) return "not determined";
  return "[" + sig(s[0] * k, digits) + " " + sig(s[1] * k, digits) + " " + sig(s[2] * k, digits) + "]";
}

bool is_fixed(const CamImuCalibrationResult& res, const char* name) {
  return std::find(res.fixed.begin(), res.fixed.end(), name) != res.fixed.end();
}

void print_camera(const CamImuCalibrationResult& res, const CamImuCameraResult& c,
                  const app::CamImuCameraReport& in) {
  const Eigen::AngleAxisd aa(c.T_cam_imu.rotation());
  const Eigen::Vector3d rv = aa.angle() * aa.axis() * kDeg;
  const Eigen::Vector3d t = c.T_cam_imu.translation() * 1e3;
  const bool fixed_T = is_fixed(res, "T_cam_imu"), fixed_shift = is_fixed(res, "timeshift");
  std::printf("  %s (stream %s, %d frames with the target of %lld; detections %s)\n", c.name.c_str(),
              c.stream.c_str(), in.frames_with_target, static_cast<long long>(in.frames),
              detections_in_words(in.detections_reused_from, in.detections_stored_in).c_str());
  std::printf("    R_cam_imu rotation vector [%.4f %.4f %.4f] deg, sigma %s deg\n", rv[0], rv[1], rv[2],
              sig3(c.rotation_sigma_rad, kDeg, 4, fixed_T).c_str());
  std::printf("    t_cam_imu [%.2f %.2f %.2f] mm, sigma %s mm\n", t[0], t[1], t[2],
              sig3(c.translation_sigma_m, 1e3, 2, fixed_T).c_str());
  std::printf("    timeshift_cam_imu %.4f ms +- %s ms (t_imu = t_cam + shift)\n", c.timeshift_cam_imu_s * 1e3,
              sig(c.timeshift_sigma_s * 1e3, 4, fixed_shift).c_str());
  if (c.camera.shutter.rolling()) {
    std::printf(
        "    rolling shutter: line delay %.3f us/row +- %s us (readout %.2f ms, %s, stamp at the %s row)\n",
        c.camera.shutter.line_delay_s * 1e6, sig(c.line_delay_sigma_s * 1e6, 3).c_str(),
        c.camera.shutter.readout_s(c.camera.height) * 1e3, readout_name(c.camera.shutter.readout),
        stamp_row_name(c.camera.shutter.stamp_row));
  }
  if (!c.shutter_choice.empty()) std::printf("    shutter: %s\n", c.shutter_choice.c_str());
  if (!c.intrinsics_uncertainty.empty()) {
    std::printf("    intrinsics (held): %s", c.intrinsics_uncertainty.c_str());
    if (c.translation_sigma_from_intrinsics_m.allFinite())
      std::printf("; their share of the sigmas: translation %s mm, rotation %s deg",
                  sig3(c.translation_sigma_from_intrinsics_m, 1e3, 2).c_str(),
                  sig3(c.rotation_sigma_from_intrinsics_rad, kDeg, 4).c_str());
    std::printf("\n");
  }
  std::printf("    reprojection RMS %.4f px over %d corners, %d down-weighted as outliers\n",
              c.reprojection_rms_px, c.corners, c.outlier_corners);
}

void print_vec(const char* name, const Eigen::Vector3d& v, const Eigen::Vector3d& s, bool fixed) {
  std::printf("    %-4s [%.6f %.6f %.6f] +- %s\n", name, v[0], v[1], v[2], sig3(s, 1.0, 6, fixed).c_str());
}

void print_summary(const app::CamImuReport& r, const std::string& out_dir) {
  const auto& res = r.result;
  std::printf("camera-IMU calibration of %s (%s, %zu samples, %s; model %s; %d iterations)\n",
              r.log_path.c_str(), r.imu_stream.name.c_str(), r.imu_samples,
              imu_units_name(r.imu_stream.units), camimu_model_name(res.model), res.quality.iterations);
  if (!res.model_choice.empty()) std::printf("  model: %s\n", res.model_choice.c_str());
  for (std::size_t i = 0; i < res.cameras.size() && i < r.cameras.size(); ++i)
    print_camera(res, res.cameras[i], r.cameras[i]);
  const auto& k = res.imu;
  const auto& s = res.imu_sigma;
  std::printf("  IMU (Krebs form on nominal SI; fixed: %s%s)\n",
              res.fixed.empty() ? "none" : [&] {
                std::string f;
                for (const auto& n : res.fixed) f += (f.empty() ? "" : ",") + n;
                return f;
              }().c_str(),
              res.prior_source.empty() ? "" : ("; prior: " + res.prior_source).c_str());
  print_vec("S_a", k.S_a, s.S_a, is_fixed(res, "S_a"));
  print_vec("M_a", k.M_a, s.M_a, is_fixed(res, "M_a"));
  print_vec("S_g", k.S_g, s.S_g, is_fixed(res, "S_g"));
  print_vec("M_g", k.M_g, s.M_g, is_fixed(res, "M_g"));
  std::printf("    C_bg %.4f deg (sigma %s deg)\n", Eigen::AngleAxisd(k.C_bg).angle() * kDeg,
              sig3(s.C_bg, kDeg, 4, is_fixed(res, "C_bg")).c_str());
  std::printf("    B_g (deg/s per g):");
  const double g = r.options.gravity_mps2 * kDeg;
  for (int row = 0; row < 3; ++row) {
    std::printf(row ? "; " : " [");
    for (int col = 0; col < 3; ++col) std::printf(col ? " %.4f" : "%.4f", k.B_g(row, col) * g);
  }
  const bool fixed_B = is_fixed(res, "B_g");
  const double sB = s.B_g.allFinite() ? s.B_g.maxCoeff() * g : std::nan("");
  std::printf("], sigma up to %s\n", sig(sB, 4, fixed_B).c_str());
  const auto& q = res.quality;
  std::printf("  IMU noise per sample: accelerometer %.4g m/s^2%s, gyroscope %.4g rad/s%s\n", q.accel_sigma,
              q.accel_noise_from_residuals ? " (from the residuals)" : "", q.gyro_sigma,
              q.gyro_noise_from_residuals ? " (from the residuals)" : "");
  std::printf("  pose spline: knots every %.3f s (%s), %d IMU samples per residual\n", q.knot_spacing_s,
              q.knot_spacing_chosen ? "chosen from the motion" : "as given", q.imu_samples_per_residual);
  for (const auto& u : res.undetermined) std::printf("  not determined: %s\n", u.c_str());
  std::printf("  noise from %s; wrote %s, %s, %s, %s, %s in %s\n", r.noise_source.c_str(),
              app::kCamchainImucamFile, app::kCamImuImuFile, app::kCamImuImuResultFile,
              app::kCamImuCalibrationFile, app::kCamImuJsonFile, out_dir.c_str());
  if (r.thermal) {
    std::printf("  IMU biases at %.2f deg C: the samples were corrected with the thermal model %s\n",
                r.thermal->reference_c, r.thermal_source.c_str());
  }
  print_self_check(res.self_check, "  ");
  if (r.warnings.empty()) std::printf("  no warnings\n");
}

void run(const CamImuCliOptions& given) {
  app::OutputPolicy outputs{given.force, {given.log_path}};
  for (const auto* input : {&given.target_path, &given.imu_path, &given.imu_intrinsics_path,
                            &given.gsens_path, &given.thermal_path}) {
    if (!input->empty()) outputs.inputs.push_back(*input);
  }
  outputs.inputs.insert(outputs.inputs.end(), given.camera_paths.begin(), given.camera_paths.end());
  const std::vector<std::string> paths = check_outputs(given, outputs);
  const CamImuCliOptions o = with_log_of_input(given);
  app::CamImuRequest q = build_request(o);
  q.log_name = given.log_path;  // a bag, not its import
  // The options are checked here, before the camera module loads (one range per option:
  // calib::CamImuLimits, which the flags' checks above use too).
  if (Status s = q.options.validate(); !s.ok()) fail(s.error(), "calibrate camimu");
  const app::TargetChoice target = resolve_target(o.target_path, o.log_path);
  q.target = target.target;
  q.target_source = target.source;

  std::map<int, std::unique_ptr<Progress>> detecting;
  q.detection_progress = [&detecting](int camera, double f) {
    auto& p = detecting[camera];
    if (!p) p = std::make_unique<Progress>("detecting the target (cam" + std::to_string(camera) + ")", 1.0);
    p->update(f);
    if (f >= 1.0) p->finish();
  };
  q.solve_progress = [](const calib::CamImuIteration& it) {
    if (it.stage == "self-check") {
      std::fprintf(stderr, "self-check: calibrating %d parts of the recording apart\n", it.iteration);
      return;
    }
    std::fprintf(stderr, "%s: iteration %3d  cost %.6e  |gradient| %.3e\n", it.stage.c_str(), it.iteration,
                 it.cost, it.gradient_max_norm);
  };

  auto report = app::calibrate_camimu(q);
  if (!report.ok()) fail(report.error(), "calibrate camimu");
  // What was assumed (default noise, the frame of a given G) is said whatever the log level.
  for (const auto& n : report->notes) std::fprintf(stderr, "note: %s\n", n.c_str());
  for (const auto& w : report->warnings) spdlog::warn("{}", w);
  std::error_code ec;
  std::filesystem::create_directories(o.out_dir, ec);
  if (ec) throw CliExit{kExitIo, "could not create " + o.out_dir + ": " + ec.message()};
  const std::string texts[] = {app::camimu_camchain_yaml(*report), app::camimu_imu_input_yaml(*report),
                               app::camimu_imu_yaml(*report), app::camimu_calibration_yaml(*report),
                               app::camimu_result_json(*report)};
  for (std::size_t i = 0; i < paths.size(); ++i) {
    if (auto s = app::write_text_file(paths[i], texts[i], outputs); !s.ok()) fail(s.error());
  }
  if (o.json) {
    std::cout << texts[4];
  } else {
    print_summary(*report, o.out_dir);
  }
}

void add_options(CLI::App* cmd, CamImuCliOptions* o) {
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) with the IMU and camera streams, or a ROS 1 bag")
      ->required();
  add_bag_topics_option(cmd, &o->topics);
  cmd->add_option("--camera", o->camera_paths,
                  "Camera intrinsics: the YAML of imucal calibrate camera or a Kalibr camchain (cam0..camN); "
                  "repeat for more files")
      ->required();
  cmd->add_option("--target", o->target_path,
                  "Calibration target, Kalibr target YAML (default: the target the log names)");
  cmd->add_option(
      "--imu", o->imu_path,
      "IMU noise, Kalibr imu.yaml (imucal allan writes one; default: MPU-6000 datasheet figures)");
  cmd->add_option(
      "--imu-intrinsics", o->imu_intrinsics_path,
      "A static result YAML (calibrate static -o): start from its model and fix S_a, M_a, S_g, M_g, "
      "C_bg (and B_g when it has a g-sensitivity)");
  cmd->add_option("--gsens", o->gsens_path,
                  "Fix B_g to a g-sensitivity G (a result YAML's canonical.G, or a file with G: 3 rows of 3, "
                  "rad/s per m/s^2)");
  cmd->add_option("--thermal", o->thermal_path,
                  "A thermal model (calibrate thermal -o): correct the IMU samples to its reference "
                  "temperature before the solve; the result and a stored record carry it");
  cmd->add_option("--imu-stream", o->imu_stream, "IMU stream name (default: the first)");
  cmd->add_option("--model", o->model,
                  "IMU model: auto (basic or extended, whichever the data support; the summary says why), "
                  "extended (Krebs: S, M, C_bg, B_g) or basic (biases)")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "basic", "extended"}));
  add_shutter_options(
      cmd, &o->shutter,
      "Camera shutter: auto (global or rolling, whichever the data support; the summary says why), "
      "global, or rolling (its line delay estimated)");
  cmd->add_flag("--no-prior", o->no_prior,
                "No prior on the extended model's intrinsics (default: the MPU-6000 datasheet tolerances, "
                "docs/camimu-calibration.md)");
  cmd->add_flag("--keep-noise", o->keep_noise,
                "Weight the IMU with the given noise figures even when the residuals disagree with them by "
                "more than a factor two (default: re-weight with the residuals and say so)");
  cmd->add_option("--fix", o->fix,
                  "Blocks held at their initial value: S_a,M_a,S_g,M_g,C_bg,B_g,T_cam_imu,timeshift")
      ->delimiter(',');
}

void add_solver_options(CLI::App* cmd, CamImuCliOptions* o) {
  auto& d = o->defaults;
  cmd->add_option(
         "--knot-spacing", d.knot_spacing_s,
         "Pose spline knot spacing, s: 0 (chosen from the motion, 0.01-0.05 s; the summary says which) or "
         "0.005-0.5")
      ->capture_default_str()
      ->check(zero_or_range(calib::CamImuLimits::kMinKnotSpacingS, calib::CamImuLimits::kMaxKnotSpacingS));
  cmd->add_option("--spline-order", d.spline_order, "Pose spline order (degree + 1): 4 cubic to 6 quintic")
      ->capture_default_str()
      ->check(CLI::Range(calib::CamImuLimits::kMinSplineOrder, calib::CamImuLimits::kMaxSplineOrder));
  cmd->add_option("--bias-knot-spacing", d.bias_knot_spacing_s,
                  "Bias spline knot spacing, s (at least the knot spacing)")
      ->capture_default_str()
      ->check(
          CLI::Range(calib::CamImuLimits::kMinBiasKnotSpacingS, calib::CamImuLimits::kMaxBiasKnotSpacingS));
  cmd->add_option("--corner-sigma", d.corner_sigma_px,
                  "Corner noise, px (standard deviation per coordinate); 0: estimated per camera from the "
                  "reprojection residuals")
      ->capture_default_str()
      ->check(CLI::Range(0.0, calib::CamImuLimits::kMaxCornerSigmaPx));
  cmd->add_option("--imu-max-rate", d.imu_max_rate_hz,
                  "IMU samples above this rate are averaged in groups into one residual each, Hz: 0 (every "
                  "sample its own residual) or 20-100000")
      ->capture_default_str()
      ->check(zero_or_range(calib::CamImuLimits::kMinImuMaxRateHz, calib::CamImuLimits::kMaxImuMaxRateHz));
  cmd->add_option(
         "--covariance-blocks", d.covariance_cluster_s,
         "Length of the time blocks whose residuals may share their errors, s: every sigma is the larger "
         "of the plain and the cluster-robust one over these blocks (0: the plain covariance only)")
      ->check(CLI::Range(0.0, calib::CamImuLimits::kMaxCovarianceClusterS))
      ->capture_default_str();
  cmd->add_option("--max-iterations", d.max_iterations, "Solver iterations at most")
      ->capture_default_str()
      ->check(CLI::Range(1, calib::CamImuLimits::kMaxIterations));
  cmd->add_option("--threads", o->threads,
                  "Worker threads for the detection and the solver (default: all cores)")
      ->check(CLI::Range(0, 256));
  add_gravity_options(cmd, &o->grav);
  add_detection_store_options(cmd, &o->detections);
  cmd->add_option(
         "--self-check", o->self_check,
         "Calibrate this many consecutive parts of the recording apart and compare them against their "
         "sigmas (2: the halves; 0: no self-check)")
      ->check(CLI::Range(0, 8))
      ->capture_default_str();
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_option("-o,--output", o->out_dir,
                  "Folder for camchain-imucam.yaml, imu.yaml, calibration.yaml and result.json (created)")
      ->required();
  cmd->add_flag("--force", o->force, "Replace result files that exist in the folder (never an input)");
  cmd->add_flag("--json", o->json, "Print result.json on stdout instead of the summary");
}

void setup(CLI::App& root) {
  CLI::App* cmd =
      calibrate_group(root)->add_subcommand("camimu",
                                            "Camera-IMU calibration (continuous time, Krebs 2012): "
                                            "extrinsics and time offset of each camera and the "
                                            "IMU's intrinsics; writes Kalibr camchain-imucam.yaml and "
                                            "imu.yaml, the canonical record and result.json");
  auto o = std::make_shared<CamImuCliOptions>();
  add_options(cmd, o.get());
  add_solver_options(cmd, o.get());
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(33, setup);

}  // namespace
}  // namespace imucal::cli
