// imucal calibrate camera LOG: camera intrinsics from the calibration target in a log's frames,
// see docs/camera-calibration.md.

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include "app/results/camera_results.hpp"
#include "app/results/output.hpp"
#include "app/solvers.hpp"
#include "calib/camera_intrinsics.hpp"
#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

struct CameraCliOptions {
  std::string log_path;
  std::string camera;
  std::string target_path;
  std::string model = "pinhole-radtan";
  int threads = 0;
  bool allow_damaged = false;
  DetectionStoreArgs detections;
  bool force = false;
  bool json = false;
  std::string yaml_path;
};

/// The target: --target, else the one the log names.

void print_summary(const app::CameraCalibrationReport& r, const std::string& yaml_path) {
  const auto& res = r.intrinsics;
  const auto& c = res.camera;
  std::printf("camera calibration of %s (%s, %lld frames, %d with the target; detections %s)\n",
              r.log_path.c_str(), r.stream.name.c_str(), static_cast<long long>(r.frames),
              r.frames_with_target,
              detections_in_words(r.detections_reused_from, r.detections_stored_in).c_str());
  std::printf("  model %s, %d x %d, target from %s\n", calib::camera_model_option_name(c.distortion_model),
              c.width, c.height, r.target_source.c_str());
  static const char* kIntrinsics[] = {"fu", "fv", "pu", "pv"};
  static const char* kRadtan[] = {"k1", "k2", "p1", "p2"};
  static const char* kEqui[] = {"k1", "k2", "k3", "k4"};
  const char** dist = c.distortion_model == DistortionModel::kRadtan ? kRadtan : kEqui;
  for (int i = 0; i < 4; ++i)
    std::printf("  %s %12.5f +- %.5f px\n", kIntrinsics[i], c.intrinsics[i], res.intrinsics_sigma[i]);
  for (int i = 0; i < 4; ++i)
    std::printf("  %s %12.6f +- %.6f\n", dist[i], c.distortion_coeffs[i], res.distortion_sigma[i]);
  std::printf(
      "  reprojection RMS %.4f px (residual sigma %.4f px per coordinate) over %d corners in %d views; "
      "%d views and %d corners rejected\n",
      res.rms_px, res.residual_sigma_px, res.points_used, res.views_used, res.views_total - res.views_used,
      res.corners_rejected);
  std::printf("  coverage: %.0f %% of a %d x %d grid of the image\n", 100.0 * res.coverage, res.coverage_cols,
              res.coverage_rows);
  std::printf("  wrote %s\n", yaml_path.c_str());
  if (r.warnings.empty()) std::printf("  no warnings\n");
}

void run(const CameraCliOptions& o) {
  // Outputs are checked before the work: never the log or the target file, never an existing
  // file without --force.
  app::OutputPolicy outputs{o.force, {o.log_path}};
  if (!o.target_path.empty()) outputs.inputs.push_back(o.target_path);
  if (auto s = app::check_output(o.yaml_path, outputs); !s.ok()) fail(s.error());

  app::CameraCalibrationRequest q;
  auto model = calib::parse_camera_model_option(o.model);
  if (!model.ok()) throw CliExit{kExitUsage, "--model: " + model.error().message};
  q.intrinsics.model = *model;
  q.intrinsics.threads = o.threads;
  if (auto valid = q.intrinsics.validate(); !valid.ok()) throw CliExit{kExitUsage, valid.error().message};
  const app::TargetChoice target = resolve_target(o.target_path, o.log_path);
  q.log_path = o.log_path;
  q.camera = o.camera;
  q.target = target.target;
  q.target_source = target.source;
  q.threads = o.threads;
  q.allow_damaged = o.allow_damaged;
  q.reuse_detections = !o.detections.no_reuse;
  q.store_detections = o.detections.store_in_log;
  q.cache_dir = detection_cache_dir(o.detections);
  Progress detecting("detecting the target", 1.0);
  Progress solving("solving", 1.0);
  q.detection_progress = [&detecting](double f) { detecting.update(f); };
  q.solve_progress = [&detecting, &solving](double f) {
    detecting.finish();
    solving.update(f);
  };

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
      "Camera intrinsics (pinhole with radtan or equidistant distortion) from the calibration target in a "
      "camera stream's frames; writes a Kalibr camchain YAML with sigmas and quality figures");
  auto o = std::make_shared<CameraCliOptions>();
  cmd->add_option("LOG", o->log_path, "Session log (.imulog) with the camera stream")->required();
  cmd->add_option("--camera", o->camera, "Camera stream name (default: the first)");
  cmd->add_option(
      "--target", o->target_path,
      "Calibration target, Kalibr target YAML (default: the target in the log's rig configuration or "
      "metadata)");
  cmd->add_option("--model", o->model, "Camera model: pinhole-radtan (default) or pinhole-equi (fisheye)")
      ->check(CLI::IsMember({"pinhole-radtan", "pinhole-equi"}));
  cmd->add_option("--threads", o->threads,
                  "Worker threads for the detection and the solver (default: all cores)")
      ->check(CLI::Range(0, 256));
  add_detection_store_options(cmd, &o->detections);
  cmd->add_flag("--allow-damaged", o->allow_damaged, "Calibrate from what is readable in a damaged log");
  cmd->add_option("-o,--output", o->yaml_path,
                  "Write the camera as Kalibr camchain YAML (cam0) with imucal's figures")
      ->required();
  cmd->add_flag("--force", o->force, "Replace the output file if it exists (never the log or the target)");
  cmd->add_flag("--json", o->json,
                "Print the result and its figures as JSON on stdout instead of the summary");
  cmd->callback([o] { run(*o); });
}

const CommandRegistrar registrar(32, setup);

}  // namespace
}  // namespace imucal::cli
