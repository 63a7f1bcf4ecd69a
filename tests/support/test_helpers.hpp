#pragma once
// Helpers that several test files share. The test executables are unity builds in `make test`
// (tests/CMakeLists.txt), where test files of one module share a translation unit, so a helper
// two files need lives here once instead of in each file's anonymous namespace.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "core/camera_model.hpp"
#include "core/result.hpp"

namespace imucal::test {

inline constexpr double kDeg = std::numbers::pi / 180.0;

/// A JSON array of three numbers as a vector.
inline Eigen::Vector3d vec3(const nlohmann::json& j) {
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

/// True when `error` names the remedy `option` (with `value`, when given).
inline bool has_remedy(const Error& error, const std::string& option, const std::string& value = "") {
  for (const auto& r : error.remedies) {
    if (r.option == option && (value.empty() || r.value == value)) return true;
  }
  return false;
}

/// The EuRoC-like 376 x 240 pinhole cameras the renderer tests use, radial-tangential and
/// equidistant.
inline CameraModel radtan_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kRadtan;
  c.intrinsics << 285.0, 286.5, 190.3, 118.6;
  c.distortion_coeffs << -0.21, 0.045, 4e-4, -2e-4;
  c.width = 376;
  c.height = 240;
  return c;
}

inline CameraModel equi_camera() {
  CameraModel c;
  c.distortion_model = DistortionModel::kEquidistant;
  c.intrinsics << 230.0, 229.2, 187.1, 121.4;
  c.distortion_coeffs << 0.012, -0.004, 0.0021, -4e-4;
  c.width = 376;
  c.height = 240;
  return c;
}

}  // namespace imucal::test
