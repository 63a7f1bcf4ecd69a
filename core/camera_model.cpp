// SPDX-License-Identifier: BSD-3-Clause
#include "core/camera_model.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

namespace imucal {

const char* distortion_model_name(DistortionModel model) {
  switch (model) {
    case DistortionModel::kRadtan:
      return "radtan";
    case DistortionModel::kEquidistant:
      return "equidistant";
    case DistortionModel::kNone:
      return "none";
    case DistortionModel::kFov:
      return "fov";
  }
  return "unknown";
}

const char* projection_model_name(ProjectionModel model) {
  switch (model) {
    case ProjectionModel::kPinhole:
      return "pinhole";
    case ProjectionModel::kOmni:
      return "omni";
    case ProjectionModel::kEucm:
      return "eucm";
    case ProjectionModel::kDs:
      return "ds";
  }
  return "unknown";
}

int projection_param_count(ProjectionModel model) {
  return static_cast<int>(projection_param_names(model).size());
}

int distortion_coeff_count(DistortionModel model) {
  return static_cast<int>(distortion_coeff_names(model).size());
}

std::vector<std::string> projection_param_names(ProjectionModel model) {
  switch (model) {
    case ProjectionModel::kPinhole:
      return {};
    case ProjectionModel::kOmni:
      return {"xi"};
    case ProjectionModel::kEucm:
      return {"alpha", "beta"};
    case ProjectionModel::kDs:
      return {"xi", "alpha"};
  }
  return {};
}

std::vector<std::string> distortion_coeff_names(DistortionModel model) {
  switch (model) {
    case DistortionModel::kRadtan:
      return {"k1", "k2", "p1", "p2"};
    case DistortionModel::kEquidistant:
      return {"k1", "k2", "k3", "k4"};
    case DistortionModel::kFov:
      return {"w"};
    case DistortionModel::kNone:
      return {};
  }
  return {};
}

bool camera_model_supported(CameraModelKind kind) {
  switch (kind.projection) {
    case ProjectionModel::kPinhole:
      return true;
    case ProjectionModel::kOmni:
      return kind.distortion == DistortionModel::kNone || kind.distortion == DistortionModel::kRadtan;
    case ProjectionModel::kEucm:
    case ProjectionModel::kDs:
      return kind.distortion == DistortionModel::kNone;
  }
  return false;
}

std::string camera_model_name(CameraModelKind kind) {
  const char* distortion =
      kind.distortion == DistortionModel::kEquidistant ? "equi" : distortion_model_name(kind.distortion);
  return std::string(projection_model_name(kind.projection)) + "-" + distortion;
}

std::vector<double> kalibr_intrinsics(ProjectionModel model, const Eigen::Vector4d& intrinsics,
                                      const Eigen::Vector2d& projection_params) {
  std::vector<double> out;
  for (int i = 0; i < projection_param_count(model); ++i) out.push_back(projection_params[i]);
  for (int i = 0; i < 4; ++i) out.push_back(intrinsics[i]);
  return out;
}

std::vector<double> kalibr_distortion(DistortionModel model, const Eigen::Vector4d& coeffs) {
  std::vector<double> out;
  for (int i = 0; i < distortion_coeff_count(model); ++i) out.push_back(coeffs[i]);
  return out;
}

const char* shutter_kind_name(Shutter::Kind kind) {
  return kind == Shutter::Kind::kRolling ? "rolling" : "global";
}
const char* readout_name(Shutter::Readout readout) {
  return readout == Shutter::Readout::kBottomToTop ? "bottom_to_top" : "top_to_bottom";
}
std::optional<Shutter::StampRow> stamp_row_of_timestamp_source(const std::string& timestamp_source) {
  if (timestamp_source == "mid-exposure" || timestamp_source == "start-of-exposure")
    return Shutter::StampRow::kFirst;
  if (timestamp_source == "end-of-frame") return Shutter::StampRow::kLast;
  return std::nullopt;
}

const char* stamp_row_name(Shutter::StampRow stamp_row) {
  switch (stamp_row) {
    case Shutter::StampRow::kFirst:
      return "first";
    case Shutter::StampRow::kMiddle:
      return "middle";
    case Shutter::StampRow::kLast:
      return "last";
  }
  return "first";
}

namespace {

/// The model is one imucal calibrates, and its projection's parameters are in their ranges:
/// omni xi >= 0; eucm alpha in [0, 1], beta > 0; ds xi in (-1, 1), alpha in [0, 1].
Status validate_projection(const CameraModel& c) {
  if (!camera_model_supported(c.kind())) {
    return make_error(Errc::kUnsupported,
                      "camera model '" + camera_model_name(c.kind()) +
                          "' is not supported (pinhole-radtan, pinhole-equi, pinhole-fov, pinhole-none, "
                          "omni-none, omni-radtan, eucm-none, ds-none)");
  }
  const Eigen::Vector2d& e = c.projection_params;
  if (!e.allFinite())
    return make_error(Errc::kInvalidArgument, "camera projection parameters must be finite");
  bool ok = true;
  switch (c.projection) {
    case ProjectionModel::kPinhole:
      break;
    case ProjectionModel::kOmni:
      ok = e[0] >= 0.0;
      break;
    case ProjectionModel::kEucm:
      ok = e[0] >= 0.0 && e[0] <= 1.0 && e[1] > 0.0;
      break;
    case ProjectionModel::kDs:
      ok = e[0] > -1.0 && e[0] < 1.0 && e[1] >= 0.0 && e[1] <= 1.0;
      break;
  }
  if (!ok) {
    return make_error(Errc::kInvalidArgument,
                      std::string("camera ") + projection_model_name(c.projection) +
                          " parameters out of range (omni: xi >= 0; eucm: 0 <= alpha <= 1, beta > 0; ds: "
                          "-1 < xi < 1, 0 <= alpha <= 1): check the order of the intrinsics (Kalibr's: the "
                          "projection's parameters first, then fu fv pu pv)");
  }
  if (c.distortion_model == DistortionModel::kFov && !(std::abs(c.distortion_coeffs[0]) < std::numbers::pi)) {
    return make_error(Errc::kInvalidArgument,
                      "camera fov distortion w must be an angle within (-pi, pi) rad");
  }
  return {};
}

}  // namespace

Status validate_camera(const CameraModel& c) {
  if (c.width <= 0 || c.height <= 0 || c.width > 65536 || c.height > 65536) {
    return make_error(Errc::kInvalidArgument,
                      "camera resolution must be positive [width, height] in pixels, got [" +
                          std::to_string(c.width) + ", " + std::to_string(c.height) + "]");
  }
  if (!c.intrinsics.allFinite() || !(c.intrinsics[0] > 0.0) || !(c.intrinsics[1] > 0.0)) {
    return make_error(Errc::kInvalidArgument,
                      "camera intrinsics must be [fu, fv, pu, pv] in pixels with fu, fv > 0");
  }
  // A focal length a thousand times the image's size (a field of view below 0.06 deg) is no
  // lens: a unit mix-up or a damaged file, which would otherwise project every target point onto
  // the principal point and end in "the target is not in view".
  const double max_focal_px = 1000.0 * std::max(c.width, c.height);
  if (c.intrinsics[0] > max_focal_px || c.intrinsics[1] > max_focal_px) {
    char text[160];
    std::snprintf(text, sizeof text, "camera focal length (fu, fv) = (%.6g, %.6g) px is more than 1000 times",
                  c.intrinsics[0], c.intrinsics[1]);
    return make_error(Errc::kInvalidArgument, std::string(text) +
                                                  " the image's size: check that intrinsics are "
                                                  "[fu, fv, pu, pv] in pixels");
  }
  if (c.intrinsics[2] < -0.5 || c.intrinsics[3] < -0.5 || c.intrinsics[2] > c.width - 0.5 ||
      c.intrinsics[3] > c.height - 0.5) {
    return make_error(Errc::kInvalidArgument,
                      "camera principal point (pu, pv) lies outside the image: check that intrinsics are in "
                      "pixels of the stated resolution");
  }
  if (!c.distortion_coeffs.allFinite()) {
    return make_error(Errc::kInvalidArgument, "camera distortion_coeffs must be finite");
  }
  if (auto s = validate_projection(c); !s.ok()) return s;
  // A rolling shutter reads a frame out in at most a second (a line delay of 1e-3 s on a 1000-row
  // sensor); more is a unit mix-up (microseconds given as seconds). A negative line delay is a
  // readout the other way round than readout_direction says, as a solve may find it.
  if (c.shutter.rolling() &&
      !(std::isfinite(c.shutter.line_delay_s) && std::abs(c.shutter.readout_s(c.height)) <= 1.0)) {
    return make_error(
        Errc::kInvalidArgument,
        "camera line_delay_s must be seconds per row, with the whole frame read out in at most 1 s "
        "(30 us per row is 3.0e-05)");
  }
  return {};
}

namespace {

Result<std::vector<double>> read_numbers(const YAML::Node& node, const char* key, std::size_t count,
                                         const std::string& source) {
  const YAML::Node value = node[key];
  if (!value) return make_error(Errc::kInvalidArgument, source + ": missing key '" + key + "'");
  if (!value.IsSequence() || value.size() != count) {
    return make_error(Errc::kInvalidArgument,
                      source + ": '" + key + "' must be a list of " + std::to_string(count) + " numbers");
  }
  std::vector<double> out;
  try {
    for (const auto& v : value) out.push_back(v.as<double>());
  } catch (const YAML::Exception&) {
    return make_error(Errc::kInvalidArgument, source + ": '" + key + "' must hold numbers");
  }
  return out;
}

Result<std::string> read_string(const YAML::Node& node, const char* key, const std::string& source) {
  const YAML::Node value = node[key];
  if (!value) return make_error(Errc::kInvalidArgument, source + ": missing key '" + key + "'");
  try {
    return value.as<std::string>();
  } catch (const YAML::Exception&) {
    return make_error(Errc::kInvalidArgument, source + ": '" + key + "' must be a string");
  }
}

/// imucal's shutter keys of a camera map; absent: global.
Status read_shutter(const YAML::Node& node, const std::string& source, Shutter* out) {
  *out = Shutter{};
  if (!node["shutter"]) return {};
  auto kind = read_string(node, "shutter", source);
  if (!kind.ok()) return kind.error();
  if (*kind == "global") return {};
  if (*kind != "rolling") {
    return make_error(Errc::kInvalidArgument,
                      source + ": shutter '" + *kind + "' is not known (global or rolling)");
  }
  out->kind = Shutter::Kind::kRolling;
  const YAML::Node delay = node["line_delay_s"];
  if (!delay) {
    return make_error(Errc::kInvalidArgument,
                      source + ": a rolling shutter needs line_delay_s (seconds per row; 3.0e-05 for 30 us)");
  }
  try {
    out->line_delay_s = delay.as<double>();
  } catch (const YAML::Exception&) {
    return make_error(Errc::kInvalidArgument, source + ": 'line_delay_s' must be a number (seconds per row)");
  }
  if (node["readout_direction"]) {
    auto dir = read_string(node, "readout_direction", source);
    if (!dir.ok()) return dir.error();
    if (*dir == "bottom_to_top") {
      out->readout = Shutter::Readout::kBottomToTop;
    } else if (*dir != "top_to_bottom") {
      return make_error(Errc::kInvalidArgument, source + ": readout_direction '" + *dir +
                                                    "' is not known (top_to_bottom or bottom_to_top)");
    }
  }
  if (node["stamp_row"]) {
    auto row = read_string(node, "stamp_row", source);
    if (!row.ok()) return row.error();
    if (*row == "middle") {
      out->stamp_row = Shutter::StampRow::kMiddle;
    } else if (*row == "last") {
      out->stamp_row = Shutter::StampRow::kLast;
    } else if (*row != "first") {
      return make_error(Errc::kInvalidArgument,
                        source + ": stamp_row '" + *row + "' is not known (first, middle or last)");
    }
  }
  return {};
}

}  // namespace

std::optional<ProjectionModel> parse_projection_name(const std::string& name) {
  for (auto p :
       {ProjectionModel::kPinhole, ProjectionModel::kOmni, ProjectionModel::kEucm, ProjectionModel::kDs})
    if (name == projection_model_name(p)) return p;
  return std::nullopt;
}

std::optional<DistortionModel> parse_distortion_name(const std::string& name) {
  if (name == "equi") return DistortionModel::kEquidistant;
  for (auto d : {DistortionModel::kRadtan, DistortionModel::kEquidistant, DistortionModel::kNone,
                 DistortionModel::kFov})
    if (name == distortion_model_name(d)) return d;
  return std::nullopt;
}

std::optional<CameraModelKind> parse_camera_model_name(const std::string& name) {
  const auto dash = name.find('-');
  if (dash == std::string::npos) return std::nullopt;
  const auto p = parse_projection_name(name.substr(0, dash));
  const auto d = parse_distortion_name(name.substr(dash + 1));
  if (!p || !d || !camera_model_supported({*p, *d})) return std::nullopt;
  return CameraModelKind{*p, *d};
}

std::vector<int> kalibr_parameter_indices(CameraModelKind kind) {
  std::vector<int> out;
  for (int i = 0; i < projection_param_count(kind.projection); ++i) out.push_back(4 + i);
  for (int i = 0; i < 4; ++i) out.push_back(i);
  for (int i = 0; i < distortion_coeff_count(kind.distortion); ++i) out.push_back(6 + i);
  return out;
}

std::vector<std::string> kalibr_parameter_names(CameraModelKind kind) {
  std::vector<std::string> out = projection_param_names(kind.projection);
  for (const char* n : {"fu", "fv", "pu", "pv"}) out.emplace_back(n);
  for (auto& n : distortion_coeff_names(kind.distortion)) out.push_back(n);
  return out;
}

std::string kalibr_intrinsics_layout(ProjectionModel model) {
  std::string out = "[";
  for (const auto& n : projection_param_names(model)) out += n + ", ";
  return out + "fu, fv, pu, pv]";
}

Status set_kalibr_parameters(CameraModel* camera, const std::vector<double>& intrinsics,
                             const std::vector<double>& distortion) {
  const int extra = projection_param_count(camera->projection);
  const int ncoeffs = distortion_coeff_count(camera->distortion_model);
  const std::string model = camera_model_name(camera->kind());
  if (intrinsics.size() != static_cast<std::size_t>(4 + extra)) {
    return make_error(Errc::kInvalidArgument, model + " has intrinsics " +
                                                  kalibr_intrinsics_layout(camera->projection) + ", " +
                                                  std::to_string(4 + extra) + " numbers");
  }
  if (!distortion.empty() && distortion.size() != static_cast<std::size_t>(ncoeffs)) {
    return make_error(Errc::kInvalidArgument,
                      model + " has " + std::to_string(ncoeffs) + " distortion coefficients");
  }
  for (int i = 0; i < extra; ++i) camera->projection_params[i] = intrinsics[static_cast<std::size_t>(i)];
  for (int i = 0; i < 4; ++i) camera->intrinsics[i] = intrinsics[static_cast<std::size_t>(extra + i)];
  for (std::size_t i = 0; i < distortion.size(); ++i)
    camera->distortion_coeffs[static_cast<Eigen::Index>(i)] = distortion[i];
  return validate_camera(*camera);
}

Result<CameraModel> camera_from_yaml(const YAML::Node& node, const std::string& source) {
  if (!node.IsMap()) {
    return make_error(Errc::kInvalidArgument,
                      source +
                          ": expected a camera map with camera_model, intrinsics, distortion_model, "
                          "distortion_coeffs, resolution");
  }
  auto model = read_string(node, "camera_model", source);
  if (!model.ok()) return model.error();
  CameraModel camera;
  if (auto p = parse_projection_name(*model); p) {
    camera.projection = *p;
  } else {
    return make_error(Errc::kUnsupported, source + ": camera_model '" + *model +
                                              "' is not supported (use pinhole, omni, eucm or ds)");
  }
  auto distortion = read_string(node, "distortion_model", source);
  if (!distortion.ok()) return distortion.error();
  if (auto d = parse_distortion_name(*distortion); d) {
    camera.distortion_model = *d;
  } else {
    return make_error(Errc::kUnsupported, source + ": distortion_model '" + *distortion +
                                              "' is not supported (use radtan, equidistant, fov or none)");
  }
  if (!camera_model_supported(camera.kind())) {
    return make_error(Errc::kUnsupported, source + ": camera model " + camera_model_name(camera.kind()) +
                                              " is not supported (pinhole with radtan, equidistant, fov or "
                                              "none; omni with none or radtan; eucm-none; ds-none)");
  }
  const int extra = projection_param_count(camera.projection);
  const int ncoeffs = distortion_coeff_count(camera.distortion_model);
  auto intrinsics = read_numbers(node, "intrinsics", static_cast<std::size_t>(4 + extra), source);
  if (!intrinsics.ok()) {
    Error e = intrinsics.error();
    e.message += " (" + kalibr_intrinsics_layout(camera.projection) + " for camera_model " + *model + ")";
    return e;
  }
  std::vector<double> coeffs;
  if (ncoeffs > 0 || node["distortion_coeffs"]) {
    auto read = read_numbers(node, "distortion_coeffs", static_cast<std::size_t>(ncoeffs), source);
    if (!read.ok()) {
      Error e = read.error();
      e.message += " (for distortion_model " + *distortion + ")";
      return e;
    }
    coeffs = std::move(*read);
  }
  auto resolution = read_numbers(node, "resolution", 2, source);
  if (!resolution.ok()) return resolution.error();
  for (int i = 0; i < extra; ++i) camera.projection_params[i] = (*intrinsics)[static_cast<std::size_t>(i)];
  for (int i = 0; i < 4; ++i) camera.intrinsics[i] = (*intrinsics)[static_cast<std::size_t>(extra + i)];
  for (int i = 0; i < ncoeffs; ++i) camera.distortion_coeffs[i] = coeffs[static_cast<std::size_t>(i)];
  const double w = (*resolution)[0];
  const double h = (*resolution)[1];
  if (w != static_cast<int>(w) || h != static_cast<int>(h)) {
    return make_error(Errc::kInvalidArgument, source + ": resolution must be whole pixels [width, height]");
  }
  camera.width = static_cast<int>(w);
  camera.height = static_cast<int>(h);
  if (auto s = read_shutter(node, source, &camera.shutter); !s.ok()) return s.error();
  if (auto s = validate_camera(camera); !s.ok()) return s.error().context(source);
  return camera;
}

void camera_to_yaml(const CameraModel& camera, YAML::Node& node) {
  node["camera_model"] = projection_model_name(camera.projection);
  YAML::Node intrinsics(YAML::NodeType::Sequence);
  YAML::Node coeffs(YAML::NodeType::Sequence);
  for (double v : kalibr_intrinsics(camera.projection, camera.intrinsics, camera.projection_params))
    intrinsics.push_back(v);
  for (double v : kalibr_distortion(camera.distortion_model, camera.distortion_coeffs)) coeffs.push_back(v);
  intrinsics.SetStyle(YAML::EmitterStyle::Flow);
  coeffs.SetStyle(YAML::EmitterStyle::Flow);
  node["intrinsics"] = intrinsics;
  node["distortion_model"] = distortion_model_name(camera.distortion_model);
  node["distortion_coeffs"] = coeffs;
  YAML::Node resolution(YAML::NodeType::Sequence);
  resolution.push_back(camera.width);
  resolution.push_back(camera.height);
  resolution.SetStyle(YAML::EmitterStyle::Flow);
  node["resolution"] = resolution;
  if (camera.shutter.rolling()) {
    node["shutter"] = shutter_kind_name(camera.shutter.kind);
    node["line_delay_s"] = camera.shutter.line_delay_s;
    node["readout_direction"] = readout_name(camera.shutter.readout);
    node["stamp_row"] = stamp_row_name(camera.shutter.stamp_row);
  }
}

Result<CameraModel> parse_camera_yaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kInvalidArgument, source + ": not valid YAML: " + e.what());
  }
  return camera_from_yaml(root, source);
}

std::string camera_to_yaml_text(const CameraModel& camera) {
  YAML::Node node(YAML::NodeType::Map);
  camera_to_yaml(camera, node);
  YAML::Emitter out;
  out << node;
  return std::string(out.c_str()) + "\n";
}

}  // namespace imucal
