// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Calibration target descriptions. Kalibr target YAML is accepted as is:
//   target_type: 'checkerboard'   targetCols: 6  targetRows: 7  rowSpacingMeters: 0.06  colSpacingMeters:
//   0.06 target_type: 'aprilgrid'      tagCols: 6 tagRows: 6 tagSize: 0.088 tagSpacing: 0.3
// targetCols/targetRows count *inner* corners, as in Kalibr.

#include <Eigen/Core>
#include <array>
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

  /// Every point a detector can report, in the order of its ids (Kalibr's):
  ///   checkerboard: corner_points();
  ///   aprilgrid: a (2 tag_rows) x (2 tag_cols) grid, id = r * 2 tag_cols + c, at
  ///     x = (c / 2) (1 + tag_spacing) tag_size + (c % 2) tag_size, y likewise with r, z = 0:
  ///     the four corners of each tag's black square. Tag t (row t / tag_cols, column
  ///     t % tag_cols) has the ids b, b + 1, b + 2 tag_cols + 1, b + 2 tag_cols with
  ///     b = (t / tag_cols) 4 tag_cols + (t % tag_cols) 2: the tag's corners counter-clockwise from
  ///     its (x, y)-lowest one.
  std::vector<Eigen::Vector3d> points() const;
  /// points().size() without building them.
  int point_count() const;
  /// Aprilgrid: the ids of tag `tag`'s four corners in the order above.
  std::array<int, 4> tag_point_ids(int tag) const;

  [[nodiscard]] Status validate() const;
};

/// Parses Kalibr target YAML text; `source` names the file in error messages.
[[nodiscard]] Result<TargetDescription> parse_target_yaml(const std::string& text,
                                                          const std::string& source = "<target>");
[[nodiscard]] Result<TargetDescription> load_target_yaml(const std::string& path);
/// Kalibr-compatible YAML for the target.
std::string target_to_yaml(const TargetDescription& target);

}  // namespace imucal
