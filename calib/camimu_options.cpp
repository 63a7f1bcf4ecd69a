// SPDX-License-Identifier: BSD-3-Clause
// CamImuOptions::validate(): in the light calib library, so that a program checks the options
// before it loads the camera module that solves (docs/architecture.md).

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <string>

#include "calib/camimu_calibration.hpp"
#include "core/text_format.hpp"

namespace imucal::calib {
namespace {

/// "lo-hi" of two limits, as the messages give a range.
std::string range_text(double lo, double hi) {
  return format_number("%g", lo) + "-" + format_number("%g", hi);
}

}  // namespace

Status CamImuOptions::validate() const {
  using L = CamImuLimits;
  if (spline_order < L::kMinSplineOrder || spline_order > L::kMaxSplineOrder)
    return make_error(Errc::kInvalidArgument, "spline order must be within " +
                                                  range_text(L::kMinSplineOrder, L::kMaxSplineOrder) +
                                                  " (4 cubic, 6 quintic)");
  if (!(knot_spacing_s == 0.0 ||
        (knot_spacing_s >= L::kMinKnotSpacingS && knot_spacing_s <= L::kMaxKnotSpacingS)))
    return make_error(Errc::kInvalidArgument, "knot spacing must be 0 (chosen from the motion) or within " +
                                                  range_text(L::kMinKnotSpacingS, L::kMaxKnotSpacingS) +
                                                  " s");
  if (!(bias_knot_spacing_s >= std::max(knot_spacing_s, L::kMinBiasKnotSpacingS) &&
        bias_knot_spacing_s <= L::kMaxBiasKnotSpacingS))
    return make_error(Errc::kInvalidArgument,
                      "bias knot spacing must be within " +
                          range_text(L::kMinBiasKnotSpacingS, L::kMaxBiasKnotSpacingS) +
                          " s and at least the knot spacing");
  if (!(corner_sigma_px >= 0.0 && corner_sigma_px <= L::kMaxCornerSigmaPx) ||
      !(reprojection_loss_sigmas > 0.0))
    return make_error(Errc::kInvalidArgument, "the corner sigma must be within " +
                                                  range_text(0.0, L::kMaxCornerSigmaPx) +
                                                  " px (0: estimated) and the loss scale positive");
  if (!(noise.accel_noise_density > 0 && noise.gyro_noise_density > 0 && noise.accel_random_walk > 0 &&
        noise.gyro_random_walk > 0))
    return make_error(Errc::kInvalidArgument, "every IMU noise figure must be positive (imu.yaml)");
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9))
    return make_error(Errc::kInvalidArgument, "gravity must be within 9.7-9.9 m/s^2");
  if (!(max_timeshift_s > 0.0 && max_timeshift_s <= 1.0))
    return make_error(Errc::kInvalidArgument, "the largest time offset searched must be within (0, 1] s");
  if (max_iterations < 1 || max_iterations > L::kMaxIterations)
    return make_error(Errc::kInvalidArgument,
                      "the solver's iterations must be within " + range_text(1, L::kMaxIterations));
  if (!(covariance_cluster_s >= 0.0 && covariance_cluster_s <= L::kMaxCovarianceClusterS))
    return make_error(Errc::kInvalidArgument, "the covariance's cluster length must be within " +
                                                  range_text(0.0, L::kMaxCovarianceClusterS) + " s");
  if (!(imu_max_rate_hz == 0.0 ||
        (imu_max_rate_hz >= L::kMinImuMaxRateHz && imu_max_rate_hz <= L::kMaxImuMaxRateHz)))
    return make_error(Errc::kInvalidArgument,
                      "the IMU's largest rate must be 0 (one residual per sample) or within " +
                          range_text(L::kMinImuMaxRateHz, L::kMaxImuMaxRateHz) + " Hz");
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
