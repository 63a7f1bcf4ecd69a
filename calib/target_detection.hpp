// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Calibration-target detection in 8-bit grey images: the checkerboard (OpenCV's detector with
// subpixel refinement) and Kalibr's AprilGrid (tag36h11 through libapriltag). A detection is the
// set of target points seen in one image, each with its id, so a board only partly in view
// still gives what it shows. Point ids index TargetDescription::points().
//
// Point ids (core/target.hpp) and the conventions that fix them, for both targets:
//   checkerboard: id = r * cols + c. As OpenCV and Kalibr, the board's x axis (along a row)
//     turns to its y axis clockwise in the image (the board's z axis points away from the
//     camera), and corner 0 is the inner corner whose diagonal outer square is black. A board
//     with cols + rows odd is thereby unique in every view; a board that a half turn maps onto
//     itself (cols + rows even) is not, and of the orderings its pattern allows the one whose
//     x axis points most to the right of the image is reported.
//   aprilgrid: Kalibr's grid (tag 0 at the lower left of the page, x to the right, y up the
//     page, z towards the camera that sees the printed side), tags with a 2-bit black border;
//     each tag's corners by TargetDescription::tag_point_ids().
// docs/targets.md has the details, the methods and the measured accuracy and speed.
//
// Threads: a TargetDetector is immutable after create(); detect() may run on many threads at
// once (each call uses its own scratch state).

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/target.hpp"
#include "core/time.hpp"

namespace imucal::calib {

/// Raised whenever a change to the detectors changes what they find, so that detections stored in
/// a log by an earlier detector (app/camera_results.hpp detection_key) are not reused.
/// 2: the checkerboard search falls back to the sector-based detector.
/// 3: the checkerboard is tracked from the previous frames, searched without the adaptive
///    threshold, and every board is checked (grid shape, alternating squares).
/// 4: a board whose corner-0 square is out of view no longer turns half round (resolve_turn);
///    a track whose corners the refinement left where they were is searched instead.
/// 5: AprilGrid quads are searched at half resolution when the frame before showed tags of
///    28 px or more (kCoarseTagEdgePx).
/// 6: the checkerboard is first searched as a grid of X junctions (checkerboard_grid.hpp);
///    AprilGrid quads only in the region where the frame before puts the grid.
/// 7: the junction grid smooths through sepFilter2D (its junctions move by hundredths of a
///    pixel); an AprilGrid tag is kept only with its corners on X junctions.
/// 8: libapriltag's threshold needs 12 grey levels between a tile's brightest and darkest (5).
/// 9: after a junction grid that stopped short, only the quad search, only in the region
///    around the grid (no sector-based search); at most 700 junctions (1000).
inline constexpr int kTargetDetectorRevision = 9;

/// The target points one image shows.
struct TargetObservation {
  TimeNs t_ns = 0;  // the frame's time (stamped by the caller)
  int width = 0;    // image size, pixels
  int height = 0;
  std::vector<int> ids;             // indices into TargetDescription::points(), ascending
  std::vector<Eigen::Vector2d> px;  // the corners, pixels (integer = pixel centre, OpenCV)
  bool empty() const { return ids.empty(); }
};

/// What the caller knows from the frames just before this one (same camera, in time order). The
/// checkerboard detector first tracks the board from there (a constant-velocity prediction of
/// every corner, refined and checked), which costs well under a millisecond, and searches the
/// whole image only when that fails. Empty: search.
struct DetectionHistory {
  TimeNs t_ns = 0;                                 // this frame's time (0: frames evenly spaced)
  const TargetObservation* last = nullptr;         // the previous frame's detection, or null
  const TargetObservation* before_last = nullptr;  // the one before it, or null
};

/// A grey image borrowed for one call.
struct GrayView {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  std::size_t stride = 0;  // bytes per row; 0 = width
};

/// OpenCV's two checkerboard detectors (docs/targets.md compares them).
enum class CheckerboardMethod {
  kClassic,      // tracking, the junction grid, findChessboardCorners around it; cornerSubPix
  kSectorBased,  // findChessboardCornersSB (ACCURACY) alone, no further refinement
};

struct DetectionOptions {
  /// Subpixel refinement of the corners (cornerSubPix for both targets).
  bool subpixel = true;
  /// Checkerboard: also accept a board only partly in view. OpenCV 4.6 cannot place a plain
  /// board's corners without seeing all of them (its partial mode needs boards with markers),
  /// so this has no effect today: a checkerboard is reported only when every inner corner is
  /// found (docs/targets.md, "Partial views"). An AprilGrid always gives the tags in view.
  bool partial = true;
  /// AprilGrid: fewest tags for a detection (Kalibr asks for 4).
  int min_tags = 1;
  CheckerboardMethod checkerboard_method = CheckerboardMethod::kClassic;
  /// AprilGrid: libapriltag's quad_decimate (quads are found on an image this many times
  /// smaller; decoding and corners use the full image). 1 is measured to find far more of
  /// Kalibr's tags (its corner squares merge with the tags at 2; docs/targets.md).
  double aprilgrid_decimate = 1.0;
};

class TargetDetector {
 public:
  virtual ~TargetDetector() = default;
  /// A detector for `target` (validated). Fails for targets it cannot detect.
  [[nodiscard]] static Result<std::unique_ptr<TargetDetector>> create(const TargetDescription& target,
                                                                      const DetectionOptions& options = {});
  /// Finds the target; an image without it gives an empty observation, not an error.
  [[nodiscard]] Result<TargetObservation> detect(const GrayView& image) const { return detect(image, {}); }
  /// The same, tracking from the frames before when `history` has them.
  [[nodiscard]] virtual Result<TargetObservation> detect(const GrayView& image,
                                                         const DetectionHistory& history) const = 0;
  virtual const TargetDescription& target() const = 0;
  /// For an image in which detect() found nothing: what target of the same kind it seems to show
  /// instead, in words ("a checkerboard of 7 x 6 inner corners"), when that differs from the
  /// description; empty when it shows none or this one. Costs about one sector-based search (tens
  /// to a few hundred milliseconds): meant for a few frames at the start of a recording, to stop
  /// early on a target file that does not match the board.
  [[nodiscard]] virtual std::string describe_other_target(const GrayView& image) const = 0;
};

}  // namespace imucal::calib
