#pragma once
// Calibration-target detection in 8-bit grey images: the checkerboard (OpenCV's detector with
// subpixel refinement) and Kalibr's AprilGrid (tag36h11 through libapriltag). A detection is the
// set of target points seen in one image, each with its id, so a board only partly in view
// still gives what it shows. Point ids index TargetDescription::points().
//
// Threads: a TargetDetector is immutable after create(); detect() may run on many threads at
// once (each call uses its own scratch state).

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/result.hpp"
#include "core/target.hpp"
#include "core/time.hpp"

namespace imucal::calib {

/// The target points one image shows.
struct TargetObservation {
  TimeNs t_ns = 0;  // the frame's time (stamped by the caller)
  int width = 0;    // image size, pixels
  int height = 0;
  std::vector<int> ids;             // indices into TargetDescription::points(), ascending
  std::vector<Eigen::Vector2d> px;  // the corners, pixels (integer = pixel centre, OpenCV)
  bool empty() const { return ids.empty(); }
};

/// A grey image borrowed for one call.
struct GrayView {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  std::size_t stride = 0;  // bytes per row; 0 = width
};

struct DetectionOptions {
  /// Subpixel refinement of the corners (cornerSubPix for both targets).
  bool subpixel = true;
  /// Checkerboard: also accept a board only partly in view (fewer than all inner corners), for
  /// the detectors that can; a full board is always preferred.
  bool partial = true;
  /// AprilGrid: fewest tags for a detection (Kalibr uses 4 tags' corners as the minimum).
  int min_tags = 1;
};

class TargetDetector {
 public:
  virtual ~TargetDetector() = default;
  /// A detector for `target` (validated). Fails for targets it cannot detect.
  [[nodiscard]] static Result<std::unique_ptr<TargetDetector>> create(const TargetDescription& target,
                                                                      const DetectionOptions& options = {});
  /// Finds the target; an image without it gives an empty observation, not an error.
  [[nodiscard]] virtual Result<TargetObservation> detect(const GrayView& image) const = 0;
  virtual const TargetDescription& target() const = 0;
};

}  // namespace imucal::calib
