// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The options of the virtual rig's camera renderer (sim/camera_render.hpp), apart from the
// renderer so that a program can check them without loading OpenCV.

#include "core/result.hpp"

namespace imucal::sim {

struct BoardAppearance {
  double white_dn = 215.0;       // printed white, grey levels
  double black_dn = 30.0;        // printed black
  double background_dn = 105.0;  // everything beyond the board
  /// White margin around the pattern, in units of its square size: the checkerboard's squares,
  /// the AprilGrid's small corner squares (tagSpacing x tagSize), measured from the outermost
  /// of them.
  double margin_squares = 0.75;
  /// AprilGrid: black border of each tag in bits. Kalibr prints 2 (kalibr_create_target_pdf,
  /// borderBits; its detector expects it); libapriltag's tag36h11 has 1.
  int tag_border_bits = 2;
  /// AprilGrid: Kalibr's black squares in the gaps at the tag corners (symmCorners). They make
  /// the tag corners checkerboard-like X-junctions, and they break libapriltag's detection.
  bool tag_corner_squares = true;
};

struct CameraRenderOptions {
  int supersampling = 2;      // n x n samples per pixel, 1..8
  double noise_sigma_dn = 0;  // Gaussian sensor noise, grey levels, >= 0
  /// Lens point-spread function: a Gaussian of this sigma (pixels) applied to the irradiance;
  /// 0 leaves the pure pixel-area sampling. Real lenses blur by 0.5-1 px.
  double optics_blur_sigma_px = 0.0;
  BoardAppearance appearance;

  [[nodiscard]] Status validate() const;
};

}  // namespace imucal::sim
