// SPDX-License-Identifier: BSD-3-Clause
// The steps of the static calibration that need no solver: the still start (given, or found and
// its length chosen from the gyroscope Allan deviation) and the pseudo-inverse of the normal
// matrix. Declared in calib/static_steps.hpp.

#include "calib/static_steps.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <string>

#include "calib/allan.hpp"
#include "calib/quality.hpp"
#include "calib/static_gyro.hpp"
#include "core/option_words.hpp"
#include "core/threads.hpp"

namespace imucal::calib {

// ---- steps of calibrate_static, in the order it runs them ------------------------------------

namespace {

double seconds_from_start(std::span<const ImuSample> samples, std::size_t i) {
  return ns_to_s(samples[i].t_ns - samples[0].t_ns);
}

/// Samples of the given initial still period, refused when the rig moves in it (by the same
/// absolute criterion as the automatic still start, StaticDetection::moving).
Result<std::size_t> given_still_start(std::span<const ImuSample> samples, const ScannedRecording& scan,
                                      const StaticDetection& det, double init_still_s,
                                      double min_init_still_s) {
  const std::size_t n = samples.size();
  if (init_still_s < min_init_still_s) {
    return make_error(Errc::kInvalidArgument,
                      "the initial still period " + format_number("%.1f", init_still_s) +
                          " s is too short: at least " + format_number("%.0f", min_init_still_s) +
                          " s are needed for the bias and the noise level (the protocol asks for about 50 s)")
        .with_remedy("init_still_s");
  }
  std::size_t n_init = 0;
  while (n_init < n && seconds_from_start(samples, n_init) < init_still_s) ++n_init;
  if (n_init >= n) {
    return make_error(Errc::kInvalidArgument,
                      "the initial still period " + format_number("%.1f", init_still_s) +
                          " s is longer than the recording (" +
                          format_number("%.1f", seconds_from_start(samples, n - 1)) + " s)");
  }
  for (std::size_t i = 0; i < n_init; ++i) {
    const bool interior = i >= det.half && i + det.half < n_init;
    if ((interior && det.moving(i)) || !scan.accel_ok[i] || !scan.gyro_ok[i] ||
        (i > 0 && scan.reset_before[i])) {
      return make_error(Errc::kInsufficientData,
                        "the given initial still period is not still: the rig moves (or the log has a "
                        "device reset or saturation) at t = " +
                            format_number("%.2f", seconds_from_start(samples, i)) +
                            " s. Give an initial still period (init_still_s) no longer than that, or "
                            "record again starting with the rig at rest for about 50 s")
          .with_remedy("init_still_s");
    }
  }
  return n_init;
}

/// Samples of the still start found by the detector, its length chosen from the gyroscope Allan
/// deviation (section 3.4.3).
Result<std::size_t> automatic_still_start(std::span<const ImuSample> samples, const ScannedRecording& scan,
                                          const StaticDetection& det, double min_init_still_s) {
  const std::size_t n = samples.size();
  std::size_t end = 0;
  // A gap (samples lost while the rig stays still) does not end the still start: the bias mean
  // and the white-noise level do not depend on it. A device reset does.
  while (end < n && scan.accel_ok[end] && scan.gyro_ok[end] && !det.moving(end) &&
         (end == 0 || !scan.reset_before[end]))
    ++end;
  const double still_s = end > 0 ? seconds_from_start(samples, end - 1) : 0.0;
  if (still_s < min_init_still_s) {
    return make_error(Errc::kInsufficientData,
                      "no still period at the start of the recording: the rig is still for only " +
                          format_number("%.1f", still_s) + " s (at least " +
                          format_number("%.0f", min_init_still_s) +
                          " s needed; it moves at t = " + format_number("%.2f", still_s) +
                          " s, where both sensors' variance exceeds 10 times their quietest level). "
                          "Record again starting with the rig at rest for about 50 s")
        .with_remedy("init_still_s");
  }
  auto curve = allan_deviation(std::span<const Eigen::Vector3d>(scan.gyro.data(), end), scan.rate_hz);
  if (!curve.ok()) return curve.error();
  const double t_init = choose_init_period_s(*curve, still_s);
  std::size_t n_init = 0;
  while (n_init < end && seconds_from_start(samples, n_init) <= t_init) ++n_init;
  return n_init;
}

}  // namespace

Result<StillStart> find_still_start(std::span<const ImuSample> samples, const ScannedRecording& scan,
                                    const StaticDetection& detection, const StaticCalibrationOptions& opt,
                                    std::vector<std::string>* warnings) {
  StillStart still;
  still.from_allan = !(opt.init_still_s > 0.0);
  Result<std::size_t> found =
      still.from_allan ? automatic_still_start(samples, scan, detection, opt.min_init_still_s)
                       : given_still_start(samples, scan, detection, opt.init_still_s, opt.min_init_still_s);
  if (!found.ok()) return found.error();
  const std::size_t n_init = *found;
  int init_gaps = 0;
  for (std::size_t i = 1; i < n_init; ++i) init_gaps += scan.break_before[i] ? 1 : 0;
  if (init_gaps > 0) {
    warnings->push_back("the initial still period contains " + std::to_string(init_gaps) +
                        " gap(s): its samples were used as one still period (bias mean and Allan "
                        "deviation); no integration crosses a gap");
  }
  still.samples = n_init;
  still.length_s = seconds_from_start(samples, n_init - 1) + scan.period_s;
  if (still.length_s < 10.0) {
    warnings->push_back("the still start is only " + format_number("%.1f", still.length_s) +
                        " s: the noise level that sets the static threshold and the Allan check of the "
                        "bias rest on few samples; record about 50 s of rest before the first pose");
  }
  still.sigma_init_sq = variance_magnitude_sq_of(std::span<const Eigen::Vector3d>(scan.accel.data(), n_init));
  Eigen::Vector3d gyro_sq = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n_init; ++i) {
    still.gyro_bias_raw += scan.gyro[i];
    still.accel_mean_raw += scan.accel[i] - scan.accel[0];
  }
  still.gyro_bias_raw /= static_cast<double>(n_init);
  still.accel_mean_raw = still.accel_mean_raw / static_cast<double>(n_init) + scan.accel[0];
  for (std::size_t i = 0; i < n_init; ++i) gyro_sq += (scan.gyro[i] - still.gyro_bias_raw).cwiseAbs2();
  still.gyro_bias_sigma =
      (gyro_sq / static_cast<double>(n_init - 1)).cwiseSqrt() / std::sqrt(static_cast<double>(n_init));
  // The mean stands for the bias over the whole session, which wanders (random walk, bias
  // instability): its uncertainty is at least the Allan deviation at the longest averaging time
  // the still start supports, not only the white noise over sqrt(n).
  auto curve = allan_deviation(std::span<const Eigen::Vector3d>(scan.gyro.data(), n_init), scan.rate_hz);
  if (curve.ok() && !curve->adev.empty())
    still.gyro_bias_sigma = still.gyro_bias_sigma.cwiseMax(curve->adev.back());
  return still;
}

Eigen::MatrixXd normal_pseudo_inverse(const Eigen::MatrixXd& J) {
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  Eigen::VectorXd inv_sq = Eigen::VectorXd::Zero(sv.size());
  const double min_ratio = std::sqrt(1e-14);
  for (Eigen::Index i = 0; i < sv.size(); ++i) {
    if (!(sv[i] / sv[0] >= min_ratio)) break;
    inv_sq[i] = 1.0 / (sv[i] * sv[i]);
  }
  return svd.matrixV() * inv_sq.asDiagonal() * svd.matrixV().transpose();
}

TedaldiTriad triad_from_conversion(const AxisConversion& c) {
  TedaldiTriad t;
  t.scale = c.scale;
  t.bias = -c.offset;
  return t;
}

StaticQuality quality_figures(const std::vector<Transfer>& transfers,
                              const std::vector<StaticInterval>& intervals,
                              const std::vector<Eigen::Vector3d>& means, const ScannedRecording& scan,
                              std::span<const ImuSample> samples, const StillStart& still,
                              const StaticCalibrationOptions& opt, const TedaldiImuModel& model) {
  StaticQuality q;
  std::vector<GravityTransfer> checks;
  for (const auto& tr : transfers) checks.push_back({tr.u0, tr.u1, tr.gyro_raw, tr.t_s});
  q.accel_after = gravity_magnitude_error(means, model.accel, opt.gravity_mps2);
  q.gyro_after = gravity_direction_error(checks, model.gyro, opt.gravity_mps2);
  if (!opt.accel_init) return q;
  TedaldiTriad gyro_nominal;
  gyro_nominal.scale = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  gyro_nominal.bias = opt.gyro_init ? Eigen::Vector3d(-opt.gyro_init->offset) : Eigen::Vector3d::Zero();
  q.before_available = true;
  const TedaldiTriad accel_nominal = triad_from_conversion(*opt.accel_init);
  q.accel_before = gravity_magnitude_error(means, accel_nominal, opt.gravity_mps2);
  // Gravity directions from the nominal accelerometer, rates from the nominal gyro.
  std::vector<GravityTransfer> nominal = checks;
  const auto dirs = pose_directions(intervals, scan.accel, scan.gyro, samples, accel_nominal,
                                    initial_gyro(still.gyro_bias_raw, opt), threads_or_cores(opt.threads));
  for (std::size_t k = 0; k < nominal.size(); ++k) {
    nominal[k].u0 = dirs[transfers[k].pose0].u_end;
    nominal[k].u1 = dirs[transfers[k].pose0 + 1].u_start;
  }
  q.gyro_before = gravity_direction_error(nominal, gyro_nominal, opt.gravity_mps2);
  return q;
}

void set_aside_an_implausible_accel_conversion(const StillStart& still, StaticCalibrationOptions* opt,
                                               std::vector<std::string>* warnings) {
  if (!opt->accel_init) return;
  const double a = opt->accel_init->to_si(still.accel_mean_raw).norm();
  const double g = opt->gravity_mps2;
  if (a > 0.5 * g && a < 2.0 * g) return;
  warnings->push_back(
      "at rest the accelerometer reads " + format_number("%.3g", a) + " m/s^2 (" +
      format_number("%.2g", a / g) +
      " g) through its stream's nominal conversion: its values carry an offset or a scale that conversion "
      "does not have (raw counts of a sensor whose zero is mid-range sit near 32768). The poses were told "
      "apart about the centre of their means and the solve started from an ellipsoid fit, so the biases "
      "hold that offset; to see them near zero, import with the counts at zero given (" +
      option_words(CalibOption::kImportOffsets) +
      "). If the scale is what is wrong (a full-scale range other than the one the import assumed), the "
      "fitted scales hold it instead: import with the scales given (" +
      option_words(CalibOption::kImportScales) + ": m/s^2 and rad/s per count at the sensor's range)");
  opt->accel_init.reset();
}

}  // namespace imucal::calib
