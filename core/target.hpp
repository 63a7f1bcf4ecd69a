#pragma once
// Calibration target descriptions. Kalibr target YAML is accepted as is:
//   target_type: 'checkerboard'   targetCols: 6  targetRows: 7  rowSpacingMeters: 0.06  colSpacingMeters:
//   0.06 target_type: 'aprilgrid'      tagCols: 6 tagRows: 6 tagSize: 0.088 tagSpacing: 0.3
// targetCols/targetRows count *inner* corners, as in Kalibr.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/result.hpp"

namespace imucal {

struct TargetDescription {
  enum class Type { kCheckerboard, kAprilgrid };
  Type type = Type::kCheckerboard;
  // Checkerboard: inner corners and square size.
  int cols = 0;                // inner corners along x (Kalibr targetCols)
  int rows = 0;                // inner corners along y (Kalibr targetRows)
  double col_spacing_m = 0.0;  // distance between corners along x
  double row_spacing_m = 0.0;  // distance between corners along y
  // Aprilgrid (Kalibr semantics): tag count, tag edge length, spacing as a fraction of the tag.
  int tag_cols = 0;
  int tag_rows = 0;
  double tag_size_m = 0.0;
  double tag_spacing = 0.0;

  /// Target-frame 3D positions (z = 0) of the checkerboard's inner corners, row-major:
  /// index = r * cols + c, position (c * col_spacing_m, r * row_spacing_m, 0).
  std::vector<Eigen::Vector3d> corner_points() const;

  [[nodiscard]] Status validate() const;
};

/// Parses Kalibr target YAML text; `source` names the file in error messages.
[[nodiscard]] Result<TargetDescription> parse_target_yaml(const std::string& text,
                                                          const std::string& source = "<target>");
[[nodiscard]] Result<TargetDescription> load_target_yaml(const std::string& path);
/// Kalibr-compatible YAML for the target.
std::string target_to_yaml(const TargetDescription& target);

}  // namespace imucal
