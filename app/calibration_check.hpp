// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Checking given IMU calibrations on a recording of static poses, with two figures that need no
// ground truth (docs/static-calibration.md, "Checking a calibration"):
//   - the gravity magnitude residual | |A_a (mean_raw - b_a)| - g | of every static interval;
//   - the gravity direction error carried by the gyro: the calibrated gravity direction of one
//     interval rotated through the motion to the next by RK4n integration of the corrected gyro,
//     against the direction measured there.
// Both are computed on one fixed set of static intervals and motions (CheckSet), found by a rule
// that depends on the recording only, so that calibrations from different tools are compared on
// identical data. Calibrations are read from imucal's result YAML (`calibrate static -o`) or
// from imu_tk's pair of calib files. No solver library is involved.

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/imu_calibration.hpp"
#include "core/imu_model.hpp"
#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::app {

/// The fixed rule that finds the static intervals (independent of any calibration).
struct CheckSetOptions {
  double window_s = 1.0;        // variance detector window t_w (Tedaldi eq. 3.9)
  double multiplier = 6.0;      // static where varsigma < multiplier * sqrt(floor)
  double min_interval_s = 1.0;  // shortest static interval kept
  double floor_percentile = 0.1;

  [[nodiscard]] Status validate() const;
};

/// One static interval: samples [begin, end) of the recording, with their raw values (the gravity
/// direction at its ends is found by carrying every sample there with the gyro).
struct CheckInterval {
  std::size_t begin = 0;
  std::size_t end = 0;
  TimeNs t0_ns = 0;  // first sample
  TimeNs t1_ns = 0;  // last sample
  Eigen::Vector3d accel_mean_raw = Eigen::Vector3d::Zero();
  std::vector<double> t_s;  // relative to the first sample
  std::vector<Eigen::Vector3d> accel_raw;
  std::vector<Eigen::Vector3d> gyro_raw;
  std::size_t size() const { return end - begin; }
};

/// The motion from the last sample of interval `from` to the first sample of interval from + 1,
/// both included, with the raw samples the check integrates.
struct CheckTransfer {
  std::size_t from = 0;
  std::vector<double> t_s;  // relative to the first sample of the motion
  std::vector<Eigen::Vector3d> accel_raw;
  std::vector<Eigen::Vector3d> gyro_raw;
};

/// The fixed data every calibration is checked on.
struct CheckSet {
  CheckSetOptions options;
  std::size_t samples = 0;
  TimeNs t_first_ns = 0;   // first sample of the recording
  double rate_hz = 0.0;    // from the median sample period
  double floor_sq = 0.0;   // quiet floor: the floor_percentile of varsigma^2, input units^4
  double threshold = 0.0;  // on varsigma: multiplier * sqrt(floor_sq), input units^2
  int gaps = 0;            // breaks in the time base (gap, device reset, long step)
  int accel_saturated = 0, gyro_saturated = 0;
  int motions = 0;                                        // pairs of consecutive intervals
  int motions_with_gap = 0, motions_with_saturation = 0;  // not used as transfers
  std::vector<CheckInterval> intervals;
  std::vector<CheckTransfer> transfers;
};

/// Finds the static intervals and transfers of a recording (one stream's samples). Errc::kCorrupt
/// when timestamps do not increase; Errc::kInsufficientData when fewer than two static intervals
/// or no usable transfer are found.
[[nodiscard]] Result<CheckSet> build_check_set(std::span<const ImuSample> samples,
                                               const CheckSetOptions& options = {});

/// Mean, RMS and maximum of one figure over the intervals or transfers.
struct CheckFigures {
  int count = 0;
  double mean = 0.0;
  double rms = 0.0;
  double max = 0.0;
};

struct CheckFiguresPair {
  CheckFigures gravity_magnitude_mps2;              // | |a| - g | per static interval, m/s^2
  CheckFigures gravity_direction_rad;               // angle per transfer, rad
  std::vector<double> magnitude_per_interval_mps2;  // in the order of CheckSet::intervals
  std::vector<double> direction_per_transfer_rad;   // in the order of CheckSet::transfers
};

/// Evaluates one calibration on the check set: the corrected gyro is w = A_g (w_raw - b_g) - G a
/// with a the calibrated accelerometer sample at the same time. The magnitude figure uses the
/// interval means. For the direction figure, the calibrated accelerometer samples of an interval
/// are carried by the corrected gyro to its last sample (direction before a motion) and to its
/// first sample (direction after the motion into it) before averaging, as the static calibration
/// does (docs/static-calibration.md, step 6): the slow start or end of a move that the detector
/// lets into an interval then biases neither direction.
CheckFiguresPair check_calibration(const CheckSet& set, const CanonicalImuModel& model, double gravity);

/// How much the RMS of one figure differs between two calibrations checked on the same items
/// (intervals or transfers), and whether that is more than chance: `sigma` is the standard error
/// of the difference, from the spread of the per-item differences of the squared errors (a
/// paired comparison: d_i = b_i^2 - a_i^2, RMS_b^2 - RMS_a^2 = mean(d), standard error
/// sd(d) / sqrt(n), divided by RMS_a + RMS_b). Items are treated as independent; consecutive
/// transfers share a pose, so sigma is if anything an underestimate.
struct RmsDifference {
  int count = 0;
  double reference = 0.0;   // RMS of a
  double difference = 0.0;  // RMS of b minus RMS of a
  double sigma = 0.0;       // NaN with fewer than two items
};
/// `a` and `b` per item, in the same order and of the same length.
RmsDifference paired_rms_difference(std::span<const double> a, std::span<const double> b);

/// Both figures of `b` against `a` (CheckFiguresPair of one check set).
struct CheckComparison {
  RmsDifference gravity_magnitude_mps2;
  RmsDifference gravity_direction_rad;
};
CheckComparison compare_checks(const CheckFiguresPair& a, const CheckFiguresPair& b);

/// A calibration read from a file, with the name it is reported under.
struct NamedCalibration {
  std::string name;    // the file name (imu_tk: "ACC + GYRO")
  std::string format;  // "imucal" or "imu_tk"
  std::string path;    // the file (imu_tk: "ACC,GYRO")
  CanonicalImuModel model;
  std::optional<ImuUnits> input_units;  // when the file says
  std::string accelerometer_of;         // crossed: the calibration whose accelerometer it has
  /// The static result's factors (A = T diag(scale) per triad) with their standard deviations
  /// (NaN where not determined), when the file has them: what `calibrate camimu` propagates into
  /// the cameras' rotation sigmas when it holds this calibration (app::held_axes_covariance).
  struct Spread {
    TedaldiTriad accel, gyro;
    TriadSigma accel_sigma, gyro_sigma;
  };
  std::optional<Spread> spread;
};

/// For each calibration after the first, that calibration's gyroscope (A_g, b_g and G) with the
/// first one's accelerometer (A_a, b_a), named "[gyro] NAME". The direction figure depends on
/// both sensors' calibrations (the accelerometer measures the directions, the gyroscope carries
/// them); with the accelerometer in common, the difference to the first is the gyroscopes' alone.
/// Empty with fewer than two calibrations.
std::vector<NamedCalibration> gyro_with_first_accelerometer(
    const std::vector<NamedCalibration>& calibrations);

/// imucal's static result YAML (`imucal calibrate static -o`): its `canonical:` section (A_a,
/// b_a, A_g, b_g, G) and `input_units`. `origin` names the text in errors.
[[nodiscard]] Result<NamedCalibration> parse_imucal_calibration(const std::string& yaml_text,
                                                                const std::string& origin);
[[nodiscard]] Result<NamedCalibration> read_imucal_calibration(const std::string& path);

/// One imu_tk calib file: 21 whitespace-separated numbers, the 3x3 misalignment T and the 3x3
/// scale K (row by row) and the bias B, for calibrated = T K (raw - B). Returns A = T K, b = B.
struct ImuTkTriad {
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
};
[[nodiscard]] Result<ImuTkTriad> parse_imu_tk_triad(const std::string& text, const std::string& origin);
/// imu_tk's accelerometer and gyroscope files as one canonical model (G = 0).
[[nodiscard]] Result<NamedCalibration> read_imu_tk_calibration(const std::string& accel_path,
                                                               const std::string& gyro_path);

/// The report as JSON (indented, ending in a newline): the check set and one entry per
/// calibration, in the order given.
std::string calibration_check_json(const std::string& log_path, const ImuStreamInfo& info,
                                   const CheckSet& set, double gravity, const std::string& gravity_source,
                                   const std::vector<NamedCalibration>& calibrations,
                                   const std::vector<CheckFiguresPair>& figures);

}  // namespace imucal::app
