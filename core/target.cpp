// SPDX-License-Identifier: BSD-3-Clause
#include "core/target.hpp"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/yaml.h>

#include <sstream>

#include "core/text_file.hpp"

namespace imucal {

std::vector<Eigen::Vector3d> TargetDescription::corner_points() const {
  std::vector<Eigen::Vector3d> points;
  if (type != Type::kCheckerboard) return points;
  points.reserve(static_cast<std::size_t>(rows * cols));
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) points.emplace_back(c * col_spacing_m, r * row_spacing_m, 0.0);
  }
  return points;
}

std::vector<Eigen::Vector3d> TargetDescription::points() const {
  if (type == Type::kCheckerboard) return corner_points();
  std::vector<Eigen::Vector3d> points;
  const int rows = 2 * tag_rows;
  const int cols = 2 * tag_cols;
  points.reserve(static_cast<std::size_t>(rows * cols));
  const double pitch = (1.0 + tag_spacing) * tag_size_m;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      points.emplace_back((c / 2) * pitch + (c % 2) * tag_size_m, (r / 2) * pitch + (r % 2) * tag_size_m,
                          0.0);
    }
  }
  return points;
}

int TargetDescription::point_count() const {
  return type == Type::kCheckerboard ? rows * cols : 4 * tag_rows * tag_cols;
}

std::array<int, 4> TargetDescription::tag_point_ids(int tag) const {
  const int cols = 2 * tag_cols;
  const int base = (tag / tag_cols) * 2 * cols + (tag % tag_cols) * 2;
  return {base, base + 1, base + cols + 1, base + cols};
}

namespace {
// Larger targets fit no camera image: 256 inner corners a side need over 2,500 px at the
// detector's 10 px a square, and Kalibr's AprilGrid numbers its tags from the tag36h11 family,
// which has 587 codes.
constexpr int kMaxCheckerboardCorners = 256;
constexpr long long kMaxAprilgridTags = 587;
}  // namespace

Status TargetDescription::validate() const {
  if (type == Type::kCheckerboard) {
    if (cols < 2 || rows < 2) {
      return make_error(Errc::kInvalidArgument,
                        "checkerboard needs at least 2x2 inner corners (targetCols, targetRows)");
    }
    if (cols > kMaxCheckerboardCorners || rows > kMaxCheckerboardCorners) {
      return make_error(Errc::kInvalidArgument,
                        "a checkerboard of " + std::to_string(cols) + " x " + std::to_string(rows) +
                            " inner corners fits no camera image (the detector needs about 10 px a square): "
                            "targetCols and targetRows count inner corners, at most " +
                            std::to_string(kMaxCheckerboardCorners) + " each");
    }
    if (!(col_spacing_m > 0.0) || !(row_spacing_m > 0.0) || col_spacing_m > 10.0 || row_spacing_m > 10.0) {
      return make_error(
          Errc::kInvalidArgument,
          "checkerboard spacing must be in metres, > 0 and < 10 (rowSpacingMeters, colSpacingMeters)");
    }
  } else {
    if (tag_cols < 1 || tag_rows < 1)
      return make_error(Errc::kInvalidArgument, "aprilgrid needs tagCols, tagRows >= 1");
    if (static_cast<long long>(tag_cols) * tag_rows > kMaxAprilgridTags) {
      return make_error(Errc::kInvalidArgument,
                        "an aprilgrid of " + std::to_string(tag_cols) + " x " + std::to_string(tag_rows) +
                            " tags needs more ids than the tag36h11 family has (" +
                            std::to_string(kMaxAprilgridTags) + "): check tagCols and tagRows");
    }
    if (!(tag_size_m > 0.0) || tag_size_m > 10.0) {
      return make_error(Errc::kInvalidArgument, "aprilgrid tagSize must be in metres, > 0 and < 10");
    }
    if (!(tag_spacing > 0.0) || tag_spacing > 10.0) {
      return make_error(Errc::kInvalidArgument, "aprilgrid tagSpacing is a fraction of tagSize, > 0");
    }
  }
  return {};
}

namespace {

template <class T>
Result<T> required(const YAML::Node& node, const char* key, const std::string& source) {
  if (!node[key]) return make_error(Errc::kInvalidArgument, source + ": missing key '" + key + "'");
  try {
    return node[key].as<T>();
  } catch (const YAML::Exception&) {
    return make_error(Errc::kInvalidArgument, source + ": key '" + key + "' has the wrong type");
  }
}

}  // namespace

Result<TargetDescription> parse_target_yaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::DeepRecursion& e) {
    return make_error(Errc::kInvalidArgument, source + ":" + std::to_string(e.mark.line + 1) +
                                                  ": nested more than " + std::to_string(e.depth()) +
                                                  " levels deep: not a target description");
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kInvalidArgument, source + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap())
    return make_error(Errc::kInvalidArgument, source + ": expected a mapping with target_type");
  auto type = required<std::string>(root, "target_type", source);
  if (!type.ok()) return type.error();
  TargetDescription t;
  if (*type == "checkerboard") {
    t.type = TargetDescription::Type::kCheckerboard;
    auto cols = required<int>(root, "targetCols", source);
    auto rows = required<int>(root, "targetRows", source);
    auto rs = required<double>(root, "rowSpacingMeters", source);
    auto cs = required<double>(root, "colSpacingMeters", source);
    for (const Error* e : {cols.ok() ? nullptr : &cols.error(), rows.ok() ? nullptr : &rows.error(),
                           rs.ok() ? nullptr : &rs.error(), cs.ok() ? nullptr : &cs.error()}) {
      if (e) return *e;
    }
    t.cols = *cols;
    t.rows = *rows;
    t.row_spacing_m = *rs;
    t.col_spacing_m = *cs;
  } else if (*type == "aprilgrid") {
    t.type = TargetDescription::Type::kAprilgrid;
    auto cols = required<int>(root, "tagCols", source);
    auto rows = required<int>(root, "tagRows", source);
    auto size = required<double>(root, "tagSize", source);
    auto spacing = required<double>(root, "tagSpacing", source);
    for (const Error* e : {cols.ok() ? nullptr : &cols.error(), rows.ok() ? nullptr : &rows.error(),
                           size.ok() ? nullptr : &size.error(), spacing.ok() ? nullptr : &spacing.error()}) {
      if (e) return *e;
    }
    t.tag_cols = *cols;
    t.tag_rows = *rows;
    t.tag_size_m = *size;
    t.tag_spacing = *spacing;
  } else {
    return make_error(Errc::kInvalidArgument, source + ": target_type '" + *type +
                                                  "' is not supported (use checkerboard or aprilgrid)");
  }
  if (auto s = t.validate(); !s.ok()) return s.error().context(source);
  return t;
}

Result<TargetDescription> load_target_yaml(const std::string& path) {
  auto text = read_text_file(path, kMaxConfigFileBytes);
  if (!text.ok()) return make_error(text.error().code, text.error().message + " (a target file)");
  return parse_target_yaml(*text, path);
}

std::string target_to_yaml(const TargetDescription& t) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  if (t.type == TargetDescription::Type::kCheckerboard) {
    out << YAML::Key << "target_type" << YAML::Value << "checkerboard";
    out << YAML::Key << "targetCols" << YAML::Value << t.cols;
    out << YAML::Key << "targetRows" << YAML::Value << t.rows;
    out << YAML::Key << "rowSpacingMeters" << YAML::Value << t.row_spacing_m;
    out << YAML::Key << "colSpacingMeters" << YAML::Value << t.col_spacing_m;
  } else {
    out << YAML::Key << "target_type" << YAML::Value << "aprilgrid";
    out << YAML::Key << "tagCols" << YAML::Value << t.tag_cols;
    out << YAML::Key << "tagRows" << YAML::Value << t.tag_rows;
    out << YAML::Key << "tagSize" << YAML::Value << t.tag_size_m;
    out << YAML::Key << "tagSpacing" << YAML::Value << t.tag_spacing;
  }
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

}  // namespace imucal
