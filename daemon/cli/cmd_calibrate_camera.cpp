// SPDX-License-Identifier: BSD-3-Clause
// imucal calibrate camera LOG: camera intrinsics from the calibration target in a log's frames,
// see docs/camera-calibration.md.

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/results/camera_results.hpp"
#include "app/results/output.hpp"
#include "app/solvers.hpp"
#include "calib/camera_intrinsics.hpp"
#include "core/text_format.hpp"
#include "daemon/cli/bag_input.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

struct CameraCliOptions {
  std::string log_path;
  std::vector<std::string> topics;  // LOG a ROS bag: the topics to import
  std::vector<std::string> cameras;
  std::string target_path;
  std::vector<std::string> models;
  bool hold_time_offsets = false;
  ShutterArgs shutter;
  double knot_spacing_s = 0.0;
  int threads = 0;
  int max_views = app::CameraCalibrationRequest::kDefaultMaxViews;
  int self_check = 2;
  bool allow_damaged = false;
  DetectionStoreArgs detections;
  bool force = false;
  bool json = false;
  std::string yaml_path;
};

/// The target: --target, else the one the log names.

/// One camera's intrinsics, sigmas and figures.
void print_camera(const app::CameraCalibrationReport& r) {
  const auto& res = r.intrinsics;
  const auto& c = res.camera;
  std::printf("  model %s, %d x %d, target from %s\n", calib::camera_model_option_name(c.kind()).c_str(),
              c.width, c.height, r.target_source.c_str());
  if (r.model_choice) std::printf("  model chosen by the evidence: %s\n", r.model_choice->reason.c_str());
  // Kalibr's order: the projection's parameters, fu fv pu pv, the distortion's coefficients.
  const std::vector<std::string> names = kalibr_parameter_names(c.kind());
  const std::vector<int> index = kalibr_parameter_indices(c.kind());
  Eigen::Matrix<double, 10, 1> value, sigma;
  value << c.intrinsics, c.projection_params, c.distortion_coeffs;
  sigma << res.intrinsics_sigma, res.projection_sigma, res.distortion_sigma;
  for (std::size_t i = 0; i < names.size(); ++i) {
    const bool px = index[i] < 4;
    std::printf(px ? "  %-5s %12.5f +- %.5f px\n" : "  %-5s %12.6f +- %.6f\n", names[i].c_str(),
                value[index[i]], sigma[index[i]]);
  }
  std::printf(
      "  reprojection RMS %.4f px (residual sigma %.4f px per coordinate) over %d corners in %d views; "
      "%d views and %d corners rejected\n",
      res.rms_px, res.residual_sigma_px, res.points_used, res.views_used, res.views_total - res.views_used,
      res.corners_rejected);
  if (r.views_not_chosen > 0)
    std::printf(
        "  views: %d of the %d with the target, spread evenly over the recording (its consecutive views "
        "repeat each other; --max-views 0 solves every one)\n",
        res.views_total, res.views_total + r.views_not_chosen);
  std::printf("  coverage: %.0f %% of a %d x %d grid of the image\n", 100.0 * res.coverage, res.coverage_cols,
              res.coverage_rows);
  if (c.shutter.rolling()) {
    const bool held = !std::isfinite(r.line_delay_sigma_s);
    std::printf("  rolling shutter: line delay %.3f us/row %s (readout %.2f ms, %s, stamp at the %s row)\n",
                1e6 * c.shutter.line_delay_s,
                held ? "(held or not determined)"
                     : ("+- " + format_number("%.3f", 1e6 * r.line_delay_sigma_s) + " us").c_str(),
                1e3 * c.shutter.readout_s(c.height), readout_name(c.shutter.readout),
                stamp_row_name(c.shutter.stamp_row));
  }
  if (!r.shutter_choice.empty()) std::printf("  shutter: %s\n", r.shutter_choice.c_str());
}

void print_summary(const app::CameraCalibrationReport& r, const std::string& yaml_path) {
  std::printf("camera calibration of %s (%s, %lld frames, %d with the target; detections %s)\n",
              r.log_path.c_str(), r.stream.name.c_str(), static_cast<long long>(r.frames),
              r.frames_with_target,
              detections_in_words(r.detections_reused_from, r.detections_stored_in).c_str());
  print_camera(r);
  print_self_check(r.self_check, "  ");
  std::printf("  wrote %s\n", yaml_path.c_str());
  if (r.warnings.empty()) std::printf("  no warnings\n");
}

/// The smallest finite entry (NaN when none is).
double smallest_finite(const Eigen::Vector3d& v) {
  double m = std::nan("");
  for (double x : v)
    if (std::isfinite(x) && !(x >= m)) m = x;
  return m;
}

/// A sigma with `decimals` decimals and its unit, or "not determined".
std::string sigma_text(double v, double scale, int decimals, const char* unit) {
  if (!std::isfinite(v)) return "(not determined)";
  char text[64];
  std::snprintf(text, sizeof text, "+- %.*f%s", decimals, v * scale, unit);
  return text;
}

void print_chain_summary(const app::CameraChainReport& r, const std::string& yaml_path) {
  const auto& first = r.cameras.front();
  std::printf("camera chain calibration of %s: %zu cameras in one solve, target from %s\n",
              first.log_path.c_str(), r.cameras.size(), first.target_source.c_str());
  for (std::size_t c = 0; c < r.cameras.size(); ++c) {
    const auto& cam = r.cameras[c];
    const auto& cc = r.chain.cameras[c];
    std::printf("cam%zu (%s, %lld frames, %d with the target; detections %s)\n", c, cam.stream.name.c_str(),
                static_cast<long long>(cam.frames), cam.frames_with_target,
                detections_in_words(cam.detections_reused_from, cam.detections_stored_in).c_str());
    print_camera(cam);
    if (c == 0) continue;
    // Every figure to two significant digits of its sigma (a sigma of 0.002 mm is not "0.00").
    const Eigen::Vector3d t = 1e3 * cc.T_cn_cnm1.translation();
    const Eigen::Vector3d t_sigma = 1e3 * cc.T_cn_cnm1_translation_sigma_m;
    const int td = decimals_for_sigma(smallest_finite(t_sigma), 2);
    const Eigen::AngleAxisd aa(cc.T_cn_cnm1.linear());
    std::printf(
        "  T_cn_cnm1 (against cam%zu): translation [%.*f %.*f %.*f] mm (sigma [%s %s %s]), rotation %.3f "
        "deg\n",
        c - 1, td, t.x(), td, t.y(), td, t.z(), sigma_text(t_sigma.x(), 1.0, td, "").c_str(),
        sigma_text(t_sigma.y(), 1.0, td, "").c_str(), sigma_text(t_sigma.z(), 1.0, td, "").c_str(),
        aa.angle() * 180.0 / M_PI);
    const Eigen::Vector3d r_sigma = cc.T_cn_cnm1_rotation_sigma_rad * 180.0 / M_PI;
    const int rd = decimals_for_sigma(smallest_finite(r_sigma), 4);
    const int bd = decimals_for_sigma(1e3 * cc.baseline_sigma_m, 2);
    std::printf("  rotation sigma [%s %s %s] deg; baseline %.*f mm %s\n",
                sigma_text(r_sigma.x(), 1.0, rd, "").c_str(), sigma_text(r_sigma.y(), 1.0, rd, "").c_str(),
                sigma_text(r_sigma.z(), 1.0, rd, "").c_str(), bd, 1e3 * cc.baseline_m,
                sigma_text(cc.baseline_sigma_m, 1e3, bd, " mm").c_str());
    if (cc.timeshift_estimated) {
      const int od = decimals_for_sigma(1e3 * cc.timeshift_sigma_s, 3);
      std::printf("  time offset: t_cam0 = t_cam%zu %+.*f ms %s\n", c, od, 1e3 * cc.timeshift_cam0_s,
                  sigma_text(cc.timeshift_sigma_s, 1e3, od, " ms").c_str());
    } else {
      std::printf("  time offset held at 0 (--hold-time-offsets)\n");
    }
  }
  std::printf("shared views (row: camera, column: the camera it shares them with):\n");
  for (std::size_t c = 0; c < r.chain.cameras.size(); ++c) {
    std::printf("  cam%zu", c);
    for (int n : r.chain.cameras[c].shared_views) std::printf(" %6d", n);
    std::printf("\n");
  }
  std::printf("reprojection RMS %.4f px over all cameras; %d iterations, %.1f s of CPU\n", r.chain.rms_px,
              r.chain.iterations, r.chain.solve_cpu_s);
  print_self_check(r.self_check, "");
  std::printf("wrote %s\n", yaml_path.c_str());
  if (r.warnings.empty()) std::printf("no warnings\n");
}

/// The camera streams to calibrate: --camera as given, else every camera stream of the log.
std::vector<std::string> streams_to_calibrate(const CameraCliOptions& o) {
  for (std::size_t i = 0; i < o.cameras.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (o.cameras[i] == o.cameras[j])
        throw CliExit{kExitUsage, "--camera " + o.cameras[i] + " is given twice"};
  if (!o.cameras.empty()) return o.cameras;
  auto reader = log::SessionLogReader::open(o.log_path);
  if (!reader.ok()) fail(reader.error());
  std::vector<std::string> names;
  for (const auto& [id, info] : (*reader)->camera_streams()) names.push_back(info.name);
  if (names.empty()) throw CliExit{kExitInput, o.log_path + " holds no camera stream"};
  return names;
}

/// One model for every camera, or one per camera, in the order of the cameras ("auto": every
/// camera's by the evidence, set apart by the caller).
std::vector<CameraModelKind> models_for(const CameraCliOptions& o, std::size_t cameras) {
  std::vector<std::string> names = o.models.empty() ? std::vector<std::string>{"pinhole-radtan"} : o.models;
  if (names.size() == 1 && names.front() == "auto") names.front() = "pinhole-radtan";
  if (std::find(names.begin(), names.end(), "auto") != names.end())
    throw CliExit{kExitUsage, "--model auto chooses every camera's model: give it alone"};
  if (names.size() != 1 && names.size() != cameras) {
    throw CliExit{kExitUsage, "--model: give one model for every camera, or one per camera (" +
                                  std::to_string(cameras) + "), in the order of the cameras"};
  }
  std::vector<CameraModelKind> out;
  for (std::size_t c = 0; c < cameras; ++c) {
    auto model = calib::parse_camera_model_option(names[names.size() == 1 ? 0 : c]);
    if (!model.ok()) throw CliExit{kExitUsage, "--model: " + model.error().message};
    out.push_back(*model);
  }
  return out;
}

void run(const CameraCliOptions& given) {
  const calib::ShutterSolveOptions shutter = shutter_solve_options(given.shutter);  // exit 2 before any work
  // Outputs are checked before the work: never the log (or the bag) or the target file, never an
  // existing file without --force.
  app::OutputPolicy outputs{given.force, {given.log_path}};
  if (!given.target_path.empty()) outputs.inputs.push_back(given.target_path);
  if (auto s = app::check_output(given.yaml_path, outputs); !s.ok()) fail(s.error());
  const CameraCliOptions o = with_log_of_input(given);

  const app::TargetChoice target = resolve_target(o.target_path, o.log_path);
  const std::vector<std::string> streams = streams_to_calibrate(o);
  const std::vector<CameraModelKind> models = models_for(o, streams.size());
  app::CameraCalibrationRequest q;
  q.intrinsics.model = models.front();
  if (o.models.size() == 1 && o.models.front() == "auto")
    q.model_candidates = calib::default_model_candidates();
  q.intrinsics.threads = o.threads;
  if (auto valid = q.intrinsics.validate(); !valid.ok()) throw CliExit{kExitUsage, valid.error().message};
  q.log_path = o.log_path;
  q.log_name = given.log_path;  // a bag, not its import
  q.camera = streams.front();
  q.target = target.target;
  q.target_source = target.source;
  q.threads = o.threads;
  q.max_views = o.max_views;
  q.self_check_parts = o.self_check;
  q.allow_damaged = o.allow_damaged;
  q.reuse_detections = !o.detections.no_reuse;
  q.store_detections = o.detections.store_in_log;
  q.cache_dir = detection_cache_dir(o.detections);
  q.shutter = shutter;
  apply_shutter_args(o.shutter, &q.known_shutter);
  q.known_stamp_row = !o.shutter.stamp_row.empty();
  Progress detecting("detecting the target", 1.0);
  Progress solving("solving", 1.0);
  q.detection_progress = [&detecting](double f) { detecting.update(f); };
  q.solve_progress = [&detecting, &solving](double f) {
    detecting.finish();
    solving.update(f);
  };

  if (streams.size() > 1) {
    app::CameraChainRequest cq;
    cq.base = q;
    cq.cameras = streams;
    cq.models = models;
    cq.chain.estimate_time_offsets = !o.hold_time_offsets;
    cq.chain.knot_spacing_s = o.knot_spacing_s;
    cq.chain.shutter = q.shutter;
    auto report = app::calibrate_camera_chain(cq);
    detecting.finish();
    solving.finish();
    if (!report.ok()) fail(report.error(), "calibrate camera");
    for (const auto& w : report->warnings) spdlog::warn("{}", w);
    const int min_shared = cq.chain.min_shared_views;
    if (auto s = app::write_text_file(o.yaml_path, app::camera_chain_yaml(*report, min_shared), outputs);
        !s.ok())
      fail(s.error());
    if (o.json) {
      std::cout << app::camera_chain_json(*report, min_shared);
    } else {
      print_chain_summary(*report, o.yaml_path);
    }
    return;
  }
  auto report = app::calibrate_camera(q);
  detecting.finish();
  solving.finish();
  if (!report.ok()) fail(report.error(), "calibrate camera");
  for (const auto& w : report->warnings) spdlog::warn("{}", w);
  if (auto s = app::write_text_file(o.yaml_path, app::camera_result_yaml(*report), outputs); !s.ok())
    fail(s.error());
  if (o.json) {
    std::cout << app::camera_result_json(*report);
  } else {
    print_summary(*report, o.yaml_path);
  }
}

void setup(CLI::App& root) {
  CLI::App* cmd = calibrate_group(root)->add_subcommand(
      "camera",
      "Camera intrinsics (Kalibr's camera models: pinhole-radtan, pinhole-equi, pinhole-fov, omni-none, "
      "omni-radtan, eucm-none, ds-none, or chosen by the evidence) from the calibration target in a "
      "log's camera streams; with several cameras one joint solve of every camera's intrinsics, their poses "
      "relative to cam0 (T_cn_cnm1) and their time offsets; writes a Kalibr camchain YAML with sigmas and "
      "quality figures");
  cmd->footer(
      "Examples:\n"
      "  imucal calibrate camera rig.imulog -o camchain.yaml\n"
      "  imucal calibrate camera stereo.imulog --camera left --camera right --model pinhole-equi -o "
      "camchain.yaml\n"
      "  imucal calibrate camera fisheye.imulog --model auto -o camchain.yaml\n"
      "  imucal calibrate camera calib.bag --topics /cam0/image_raw /cam1/image_raw -o camchain.yaml   # "
      "a Kalibr bag");
  auto o = std::make_shared<CameraCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) with the camera streams, or a ROS 1 bag")
      ->required();
  add_bag_topics_option(cmd, &o->topics);
  cmd->add_option(
      "--camera", o->cameras,
      "Camera stream name; repeat it for several cameras, the first becoming cam0 (default: every "
      "camera stream of the log, in the log's order)");
  cmd->add_option(
      "--target", o->target_path,
      "Calibration target, Kalibr target YAML (default: the target in the log's rig configuration or "
      "metadata)");
  cmd->add_option(
         "--model", o->models,
         "Camera model, Kalibr's names: pinhole-radtan (default), pinhole-equi (fisheye to about 180 "
         "degrees), pinhole-fov, omni-none, omni-radtan (Mei's unified model), eucm-none (extended "
         "unified), ds-none (double sphere; lenses beyond 180 degrees), or auto: every model calibrated "
         "and the one with the lowest BIC on the views they share kept (the summary and the JSON say "
         "why); one for every camera, or repeated once per camera in the order of the cameras")
      ->check(CLI::IsMember({"pinhole-radtan", "pinhole-equi", "pinhole-fov", "omni-none", "omni-radtan",
                             "eucm-none", "ds-none", "auto"}));
  cmd->add_flag("--hold-time-offsets", o->hold_time_offsets,
                "Several cameras: hold their time offsets against cam0 at 0 and give every instant its own "
                "pose (cameras triggered together, or still pairs taken seconds apart) instead of estimating "
                "the offsets on a trajectory");
  add_shutter_options(
      cmd, &o->shutter,
      "Camera shutter: auto (a video is also solved on a trajectory with a rolling shutter's line "
      "delay, kept when the data support it; the summary says why), global (each view its own "
      "pose), or rolling (the line delay estimated)");
  cmd->add_option(
         "--knot-spacing", o->knot_spacing_s,
         "Several cameras: knot spacing in s of the target's trajectory (default: the shortest frame "
         "interval)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--threads", o->threads,
                  "Worker threads for the detection and the solver (default: all cores)")
      ->check(CLI::Range(0, 256));
  cmd->add_option("--max-views", o->max_views,
                  "One camera: solve on at most this many of the views with the target, spread evenly over "
                  "the recording (consecutive views of a video repeat each other; the self-check's parts use "
                  "the same views, so the sigmas stay honest); 0: every view. A rolling-shutter camera is "
                  "solved on every view")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000000));
  add_self_check_option(cmd, &o->self_check);
  add_detection_store_options(cmd, &o->detections);
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path,
                  "Write the cameras as Kalibr camchain YAML (cam0, cam1 ... with T_cn_cnm1) with imucal's "
                  "figures")
      ->required();
  cmd->add_flag("--force", o->force, "Replace the output file if it exists (never the log or the target)");
  cmd->add_flag("--json", o->json,
                "Print the result and its figures as JSON on stdout instead of the summary");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(32, setup);

}  // namespace
}  // namespace imucal::cli
