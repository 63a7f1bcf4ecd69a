// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The static six-orientation g-sensitivity experiment (Krebs 2012, section 5.2.3): the rig is held
// still with each of its six faces up in turn; in every still hold the gyro's mean is
// b_g + H a + noise, with a the gravity reaction the accelerometer sees and H = A_g^-1 G the
// g-sensitivity in gyro input units per m/s^2. G and b_g come from a generalised least-squares fit
// over the holds, one per gyro axis, whose weights are the noise of a hold's mean: white noise
// over the hold's length and the bias random walk between holds (correlated from hold to hold),
// both read from the pooled Allan deviation of the holds. No solver library.
//
// The holds are found by the variance detector the static calibration uses (calib/static_scan.hpp).

#include <Eigen/Core>
#include <optional>
#include <span>
#include <vector>

#include "core/imu.hpp"
#include "core/imu_calibration.hpp"
#include "core/result.hpp"

namespace imucal::calib {

/// The relative uncertainty (1 sigma, every entry of A) of a nominal scale that no calibration
/// has checked: the MPU-6000's sensitivity tolerance (+-3 %, with +-2 % cross-axis sensitivity).
inline constexpr double kNominalModelRelSigma = 0.03;
/// The uncertainty (1 sigma) of a nominal accelerometer offset: the MPU-6000's zero-g tolerance
/// (+-50 mg on x and y, +-80 mg on z), m/s^2.
inline constexpr double kNominalAccelOffsetSigma = 0.08 * kStandardGravity;

struct GSensitivityOptions {
  /// Local gravity magnitude, m/s^2.
  double gravity_mps2 = kStandardGravity;
  /// Latitude, deg, when known: the vertical Earth rate (indistinguishable from an isotropic G in
  /// still holds) is removed from G (calib/gravity.hpp, earth_rate_gsens).
  std::optional<double> latitude_deg;
  /// The accelerometer model that turns a hold's raw mean into a (m/s^2): a = A_a (a_raw - b_a),
  /// and the gyro's A_g (G = A_g H); from a prior calibration or the nominal conversion.
  Eigen::Matrix3d A_a = Eigen::Matrix3d::Identity();
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  Eigen::Matrix3d A_g = Eigen::Matrix3d::Identity();
  /// Relative uncertainty of A_a's and A_g's entries, carried into G's covariance (G scales with
  /// both): kNominalModelRelSigma for a nominal conversion, 0 for a calibration.
  double accel_model_rel_sigma = 0.0;
  double gyro_model_rel_sigma = 0.0;
  /// Uncertainty of b_a, m/s^2 (1 sigma, each axis): it moves every a_k alike, so it leaves G alone
  /// and shifts b_g by H db_a. kNominalAccelOffsetSigma for a nominal offset, 0 for a calibration.
  double accel_offset_sigma_mps2 = 0.0;
  /// Variance detector window t_w (eq. 3.9), s; holds are trimmed by one window at each end.
  double window_s = 1.0;
  /// Shortest hold used, s (after trimming). The fixture protocol holds each face 30 s.
  double min_hold_s = 10.0;
  /// A hold belongs to the face whose axis is within this angle of its gravity reaction, deg.
  double max_face_angle_deg = 30.0;
  /// A hold that turns more than this (accelerometer tilt or residual gyro rate times its length)
  /// is reported as rotating, deg.
  double max_rotation_deg = 1.0;

  /// Checks ranges; the error says what is wrong.
  [[nodiscard]] Status validate() const;
};

/// Runs the experiment on one recording (raw counts or SI, in time order). Refuses
/// (Errc::kInsufficientData) when a face has no still hold, naming the missing faces.
[[nodiscard]] Result<GSensitivityResult> calibrate_gsens(std::span<const ImuSample> samples,
                                                         const GSensitivityOptions& options);

/// Covariance of the means of a unit bias random walk (a Brownian motion W with W(t_ref) = 0,
/// growing away from t_ref on both sides) over the disjoint time spans [t0[k], t1[k]] (s): entry
/// (k, j) is E[mean_k(W) mean_j(W)]. Times the random walk coefficient squared, it is the share of
/// the bias walk in the covariance of the holds' means.
Eigen::MatrixXd random_walk_mean_covariance(const std::vector<double>& t0, const std::vector<double>& t1,
                                            double t_ref);

}  // namespace imucal::calib
