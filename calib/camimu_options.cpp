// CamImuOptions::validate(): in the light calib library, so that a program checks the options
// before it loads the camera module that solves (docs/architecture.md).

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <string>

#include "calib/camimu_calibration.hpp"

namespace imucal::calib {

Status CamImuOptions::validate() const {
  using L = CamImuLimits;
  if (spline_order < L::kMinSplineOrder || spline_order > L::kMaxSplineOrder)
    return make_error(Errc::kInvalidArgument, "spline order must be 4, 5 or 6 (cubic to quintic)");
  if (!(knot_spacing_s == 0.0 ||
        (knot_spacing_s >= L::kMinKnotSpacingS && knot_spacing_s <= L::kMaxKnotSpacingS)))
    return make_error(Errc::kInvalidArgument,
                      "knot spacing must be 0 (chosen from the motion) or within 0.005-0.5 s");
  if (!(bias_knot_spacing_s >= std::max(knot_spacing_s, L::kMinBiasKnotSpacingS) &&
        bias_knot_spacing_s <= L::kMaxBiasKnotSpacingS))
    return make_error(Errc::kInvalidArgument,
                      "bias knot spacing must be within 0.05-60 s and at least the knot spacing");
  if (!(corner_sigma_px >= 0.0 && corner_sigma_px <= L::kMaxCornerSigmaPx) ||
      !(reprojection_loss_sigmas > 0.0))
    return make_error(Errc::kInvalidArgument,
                      "the corner sigma must be within 0-50 px (0: estimated) and the loss scale positive");
  if (!(noise.accel_noise_density > 0 && noise.gyro_noise_density > 0 && noise.accel_random_walk > 0 &&
        noise.gyro_random_walk > 0))
    return make_error(Errc::kInvalidArgument, "every IMU noise figure must be positive (imu.yaml)");
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9))
    return make_error(Errc::kInvalidArgument, "gravity must be within 9.7-9.9 m/s^2");
  if (!(max_timeshift_s > 0.0 && max_timeshift_s <= 1.0))
    return make_error(Errc::kInvalidArgument, "the largest time offset searched must be within (0, 1] s");
  if (max_iterations < 1 || max_iterations > L::kMaxIterations)
    return make_error(Errc::kInvalidArgument, "the solver's iterations must be within 1-10000");
  if (!(covariance_cluster_s >= 0.0 && covariance_cluster_s <= L::kMaxCovarianceClusterS))
    return make_error(Errc::kInvalidArgument, "the covariance's cluster length must be within 0-3600 s");
  if (!(imu_max_rate_hz == 0.0 ||
        (imu_max_rate_hz >= L::kMinImuMaxRateHz && imu_max_rate_hz <= L::kMaxImuMaxRateHz)))
    return make_error(Errc::kInvalidArgument,
                      "the IMU's largest rate must be 0 (one residual per sample) or within 20-100000 Hz");
  if (shutter.line_delay_s &&
      (!(std::isfinite(*shutter.line_delay_s) && std::abs(*shutter.line_delay_s) <= 1e-3) ||
       shutter.mode == CamImuShutterOptions::Mode::kGlobal))
    return make_error(
        Errc::kInvalidArgument,
        "a line delay is seconds per row within +-1e-3 (30 us is 3.0e-05), for a rolling shutter only");
  for (const CamImuChainPrior& cp : chain_priors) {
    const Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(cp.covariance);
    if (cp.camera < 1 || !cp.T_cn_cnm1.matrix().allFinite() || !cp.covariance.allFinite() ||
        llt.info() != Eigen::Success) {
      return make_error(Errc::kInvalidArgument,
                        "the camera chain of " + cp.source +
                            " has no usable pose or covariance for its camera " + std::to_string(cp.camera) +
                            " (T_cn_cnm1 with a positive definite covariance is needed)");
    }
  }
  return {};
}

}  // namespace imucal::calib
