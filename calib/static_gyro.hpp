// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The gyroscope of the static calibration (eqs. 3.5-3.16): the motions between static poses, the
// gravity direction carried through them by the corrected gyro, the solve, its covariance and the
// parameters the motions leave undetermined. Internal to calib/static_calibration.cpp, which runs
// the steps; the shared small helpers of the method are here too.

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <span>
#include <string>
#include <vector>

#include "calib/static_calibration.hpp"
#include "calib/static_detector.hpp"
#include "calib/static_scan.hpp"
#include "core/text_format.hpp"

namespace imucal::calib {

using Vec9 = Eigen::Matrix<double, 9, 1>;

/// Square roots of a covariance's diagonal; NaN (undetermined) stays NaN.
inline Eigen::VectorXd sigmas_of(const Eigen::MatrixXd& cov) {
  return cov.diagonal().unaryExpr([](double v) { return std::isnan(v) ? v : std::sqrt(std::max(v, 0.0)); });
}

/// The accelerometer parameters in the order of eq. 3.2: [alpha_yz, alpha_zy, alpha_zx, s_x,
/// s_y, s_z, b_x, b_y, b_z] (bias in Tedaldi's sign), and back.
Vec9 accel_params(const TedaldiTriad& t);
TedaldiTriad accel_triad(const Vec9& p);

/// Levenberg-Marquardt, dense QR, one thread, silent.
ceres::Solver::Options solver_options(int max_iterations);

/// One gravity transfer between consecutive static poses.
struct Transfer {
  std::vector<Eigen::Vector3d> gyro_raw;
  std::vector<double> t_s;
  // Set before every solve; initialised so that copies of a fresh transfer read defined values.
  Eigen::Vector3d u0 = Eigen::Vector3d::Zero(), u1 = Eigen::Vector3d::Zero();
  std::size_t pose0 = 0;  // index of the static interval the motion starts from
};

/// Gravity direction at the first and at the last sample of a static interval. Every sample's
/// calibrated acceleration is carried to the first sample by the gyro-integrated rotation before
/// averaging, so slow motion the variance detector let into the interval (the start or the end of
/// a move) does not bias the directions used by eq. 3.8.

struct PoseDirections {
  Eigen::Vector3d u_start, u_end;
};

std::vector<PoseDirections> pose_directions(const std::vector<StaticInterval>& intervals,
                                            const std::vector<Eigen::Vector3d>& accel,
                                            const std::vector<Eigen::Vector3d>& gyro,
                                            std::span<const ImuSample> samples,
                                            const TedaldiTriad& accel_model, const TedaldiTriad& gyro_model,
                                            int threads);

/// The motions between consecutive static poses that can be integrated: none crossing a gap, a
/// reset or a saturated gyro sample (a warning in `warnings` counts those left out). Refuses when
/// too few remain for the gyroscope.
Result<std::vector<Transfer>> collect_transfers(const std::vector<StaticInterval>& intervals,
                                                const ScannedRecording& scan,
                                                std::span<const ImuSample> samples,
                                                const StaticCalibrationOptions& opt,
                                                std::vector<std::string>* warnings);

/// The gyro model before the solve: the nominal scale, the given bias (input units, canonical sign).
TedaldiTriad initial_gyro(const Eigen::Vector3d& bias_raw, const StaticCalibrationOptions& opt);

/// What the gyro solve takes from the rest of the method: the poses and the gyro's static model.
struct GyroSolveInput {
  const std::vector<StaticInterval>& intervals;
  const std::vector<Eigen::Vector3d>& means;  // accelerometer, input units
  Eigen::Vector3d bias, bias_sigma;           // gyro bias (input units, canonical sign), its sigma
};

/// What the gyro solve takes of the accelerometer's result: its model (the poses' reference
/// directions) and covariance (their uncertainty, carried into the gyro's).
struct AccelForGyro {
  const TedaldiTriad& triad;
  const Eigen::MatrixXd& covariance;
};

/// The gyroscope's part of the static result.
struct GyroPiece {
  TedaldiTriad triad;
  int iterations = 0;
  double residual_rms = 0.0;  // of eq. 3.8 residuals (unit vectors)
  FitDof dof;
  Eigen::MatrixXd covariance;
  TriadSigma sigma;
  std::vector<std::string> fixed;  // parameters the motions leave undetermined, held at nominal
  std::vector<std::string> warnings;
};

/// Eqs. 3.5-3.16 on the transfers (their directions are set here): the gyro's model, covariance,
/// sigmas, dof and held parameters.
Result<GyroPiece> solve_gyroscope(std::vector<Transfer>* transfers, const GyroSolveInput& best,
                                  const AccelForGyro& accel, const ScannedRecording& scan,
                                  std::span<const ImuSample> samples, const StaticCalibrationOptions& opt);

}  // namespace imucal::calib
