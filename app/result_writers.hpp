#pragma once
// The output schemas of the calibration results, in one place for the CLI and the rig service:
// the static calibration (YAML and JSON, docs/static-calibration.md), the six-orientation
// g-sensitivity experiment (YAML and JSON, docs/gsens.md) and the noise figures of the Allan
// deviation (Kalibr imu.yaml and JSON with the curves).

#include <map>
#include <string>
#include <vector>

#include "calib/allan.hpp"
#include "calib/gsens_calibration.hpp"
#include "calib/static_calibration.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// Static calibration as YAML: the canonical form, the triads with their sigmas, quality.
/// The g-sensitivity matrix G (rad/s per m/s^2) of a YAML file: `canonical: G:` of a static
/// result written by static_result_yaml, or a top-level `G:` (3 rows of 3). Errors name the file.
[[nodiscard]] Result<Eigen::Matrix3d> read_gsens_matrix(const std::string& path);

std::string static_result_yaml(const calib::StaticCalibrationResult& result, const ImuStreamInfo& info);

/// Static calibration as JSON (indented, ending in a newline): the YAML's content plus the
/// Tedaldi angles, the static intervals, quality before and after, warnings, CPU timings and
/// the log's "software_version" from `log_metadata` when present.
std::string static_result_json(const calib::StaticCalibrationResult& result, const ImuStreamInfo& info,
                               const std::string& gravity_source,
                               const std::map<std::string, std::string>& log_metadata);

/// Noise figures of a still recording, per axis, and where they come from.
struct AllanReport {
  std::string log_path;  // named in the outputs
  std::string stream;
  std::string rostopic = "/imu0";
  double rate_hz = 0.0;
  double duration_s = 0.0;  // of the analysed run
  calib::AllanCurve accel_curve, gyro_curve;
  std::vector<calib::AllanNoise> accel_fits, gyro_fits;  // x, y, z

  /// Kalibr's figures: the worst axis of each.
  double accel_noise_density() const;
  double accel_random_walk() const;
  double gyro_noise_density() const;
  double gyro_random_walk() const;
  /// True when any random walk is only an upper bound (recording too short for its slope).
  bool random_walk_is_upper_bound() const;
};

/// Allan deviations and noise fits of `accel` (m/s^2) and `gyro` (rad/s) sampled at
/// `rate_hz`; `log_path`, `stream` and `rostopic` are left for the caller.
[[nodiscard]] Result<AllanReport> analyse_allan(const std::vector<Eigen::Vector3d>& accel,
                                                const std::vector<Eigen::Vector3d>& gyro, double rate_hz);

/// The Kalibr imu.yaml of a report.
std::string allan_kalibr_yaml(const AllanReport& report);
/// The report as JSON with the curves and fitted lines (indented, ending in a newline).
std::string allan_json(const AllanReport& report);

/// Where a g-sensitivity result's inputs come from, written with it.
struct GSensProvenance {
  std::string models;          // "nominal conversion" or the --imu-intrinsics file
  std::string gravity_source;  // app::GravityChoice::source
};

/// The six-orientation g-sensitivity result as YAML: a top-level `G:` (3 rows of 3, rad/s per
/// m/s^2, what read_gsens_matrix and `calibrate static --gsens fix` read), G_sigma, b_g and its
/// sigma, the models used, the noise, residual figures and the holds.
std::string gsens_result_yaml(const GSensitivityResult& result, const ImuStreamInfo& info,
                              const GSensProvenance& provenance);
/// The same as JSON (indented, ending in a newline), with the full covariance and the warnings.
std::string gsens_result_json(const GSensitivityResult& result, const ImuStreamInfo& info,
                              const GSensProvenance& provenance);

/// How a result file may be written.
struct OutputPolicy {
  bool overwrite = false;           // replace an existing file
  std::vector<std::string> inputs;  // files the command reads: never written over
};

/// Whether `path` may be written under `policy`, checked before the work that produces it:
/// kInvalidArgument when it is one of the inputs (whatever the policy), kAlreadyExists when it
/// exists and may not be replaced.
[[nodiscard]] Status check_output(const std::string& path, const OutputPolicy& policy);

/// Writes `text` as the whole content of `path` after check_output: into a temporary file beside
/// it, flushed to disk, then renamed over `path`, so that a reader never sees a partial file and
/// a failure (a full disk) leaves any earlier file as it was. Errc::kIo on failure.
[[nodiscard]] Status write_text_file(const std::string& path, const std::string& text,
                                     const OutputPolicy& policy = {});

}  // namespace imucal::app
