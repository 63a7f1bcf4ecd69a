// SPDX-License-Identifier: BSD-3-Clause
#include "sim/camera_render_options.hpp"

#include <string>

namespace imucal::sim {

Status CameraRenderOptions::validate() const {
  if (supersampling < 1 || supersampling > 8) {
    return make_error(Errc::kInvalidArgument,
                      "camera render supersampling must be 1..8 samples per pixel side, got " +
                          std::to_string(supersampling));
  }
  if (!(noise_sigma_dn >= 0.0) || noise_sigma_dn > 64.0) {
    return make_error(Errc::kInvalidArgument, "camera noise sigma must be in grey levels, 0..64");
  }
  if (!(optics_blur_sigma_px >= 0.0) || optics_blur_sigma_px > 10.0) {
    return make_error(Errc::kInvalidArgument, "camera lens blur sigma must be 0..10 pixels");
  }
  const BoardAppearance& a = appearance;
  for (double v : {a.white_dn, a.black_dn, a.background_dn}) {
    if (!(v >= 0.0 && v <= 255.0)) {
      return make_error(Errc::kInvalidArgument, "board grey levels must be within 0..255");
    }
  }
  if (!(a.white_dn > a.black_dn)) {
    return make_error(Errc::kInvalidArgument, "board white must be brighter than black");
  }
  if (!(a.margin_squares >= 0.0) || a.margin_squares > 100.0) {
    return make_error(Errc::kInvalidArgument, "board margin must be 0..100 squares");
  }
  if (a.tag_border_bits < 1 || a.tag_border_bits > 4) {
    return make_error(
        Errc::kInvalidArgument,
        "AprilGrid tag border must be 1..4 bits (Kalibr prints 2), got " + std::to_string(a.tag_border_bits));
  }
  return {};
}

}  // namespace imucal::sim
