// SPDX-License-Identifier: BSD-3-Clause
// The options of the camera intrinsic calibration, checked without the solver (so that a
// program can refuse bad options before it loads the camera module).

#include <cmath>
#include <string>

#include "calib/camera_chain.hpp"
#include "calib/camera_intrinsics.hpp"

namespace imucal::calib {

Status CameraIntrinsicsOptions::validate() const {
  auto fail = [](const std::string& msg) -> Status { return make_error(Errc::kInvalidArgument, msg); };
  if (min_views < 3) return fail("at least 3 views are needed to calibrate a camera (min_views)");
  if (min_points_per_view < 4)
    return fail("a view needs at least 4 points for its pose (min_points_per_view)");
  if (!(robust_loss_px > 0.0) || !std::isfinite(robust_loss_px))
    return fail("the robust loss scale must be a positive number of pixels");
  if (!(view_rms_factor > 1.0) || !std::isfinite(view_rms_factor))
    return fail("the view rejection factor must be above 1");
  if (!(view_rms_floor_px >= 0.0) || !std::isfinite(view_rms_floor_px))
    return fail("the view rejection floor must be >= 0 px");
  if (!(corner_sigmas >= 2.0) || !std::isfinite(corner_sigmas))
    return fail("the corner rejection threshold must be at least 2 sigmas");
  if (!(corner_floor_px >= 0.0) || !std::isfinite(corner_floor_px))
    return fail("the corner rejection floor must be >= 0 px");
  if (max_iterations < 1) return fail("the solver needs at least one iteration");
  if (start_views != 0 && start_views < min_views)
    return fail("the starts need at least min_views views (start_views; 0 = every view)");
  if (coverage_cols < 1 || coverage_cols > 100) return fail("the coverage grid needs 1 to 100 columns");
  if (!(max_focal_relative_sigma > 0.0)) return fail("the focal sigma limit must be positive");
  if (threads < 0) return fail("threads must be >= 0 (0 = all cores)");
  return {};
}

Status CameraChainOptions::validate() const {
  IMUCAL_TRY(intrinsics.validate());
  auto fail = [](const std::string& msg) -> Status { return make_error(Errc::kInvalidArgument, msg); };
  if (!(max_time_offset_s >= 0.0 && max_time_offset_s <= 1.0))
    return fail("the time offset search must cover 0 to 1 s (max_time_offset_s)");
  if (!(knot_spacing_s >= 0.0 && knot_spacing_s <= 1.0))
    return fail("the knot spacing must be 0 (from the frame rate) to 1 s");
  if (!(shared_view_fraction > 0.0 && shared_view_fraction <= 1.0))
    return fail("the shared-view fraction of a frame interval must be in (0, 1]");
  if (min_shared_views < 1) return fail("at least one shared view must link two cameras");
  if (!(loss_sigmas > 0.0) || !std::isfinite(loss_sigmas)) return fail("the loss scale must be positive");
  if (!(reject_sigmas >= 2.0) || !std::isfinite(reject_sigmas))
    return fail("the corner rejection threshold must be at least 2 sigmas");
  if (max_iterations < 1) return fail("the solver needs at least one iteration");
  if (threads < 0) return fail("threads must be >= 0 (0 = all cores)");
  if (shutter.line_delay_s &&
      (!(std::isfinite(*shutter.line_delay_s) && std::abs(*shutter.line_delay_s) <= 1e-3) ||
       shutter.mode == ShutterSolveOptions::Mode::kGlobal))
    return fail(
        "a line delay is seconds per row within +-1e-3 (30 us is 3.0e-05), for a rolling shutter only");
  return {};
}

std::string camera_model_option_name(CameraModelKind model) { return camera_model_name(model); }

Result<CameraModelKind> parse_camera_model_option(const std::string& text) {
  if (text == "radtan") return CameraModelKind{ProjectionModel::kPinhole, DistortionModel::kRadtan};
  if (text == "equidistant") return CameraModelKind{ProjectionModel::kPinhole, DistortionModel::kEquidistant};
  if (auto kind = parse_camera_model_name(text)) return *kind;
  return make_error(
      Errc::kInvalidArgument,
      "unknown camera model '" + text +
          "': use pinhole-radtan, pinhole-equi, pinhole-fov, pinhole-none, omni-none, omni-radtan, "
          "eucm-none or ds-none");
}

std::vector<CameraModelKind> default_model_candidates() {
  using P = ProjectionModel;
  using D = DistortionModel;
  return {{P::kPinhole, D::kRadtan}, {P::kPinhole, D::kEquidistant}, {P::kPinhole, D::kFov},
          {P::kOmni, D::kNone},      {P::kOmni, D::kRadtan},         {P::kEucm, D::kNone},
          {P::kDs, D::kNone}};
}

}  // namespace imucal::calib
