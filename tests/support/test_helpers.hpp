// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Helpers that several test files share. The test executables are unity builds in `make test`
// (tests/CMakeLists.txt), where test files of one module share a translation unit, so a helper
// two files need lives here once instead of in each file's anonymous namespace.

#include <Eigen/Core>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "core/camera_model.hpp"
#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::test {

inline constexpr double kDeg = std::numbers::pi / 180.0;

/// Times of `n` samples at 100 Hz as a host stamps them on receipt: each up to 4 ms late, on a
/// clock that ticks every 5.12 ms. The steps are 5.12, 10.24 and 15.36 ms, a long one always next
/// to a short one; no sample is lost. Deterministic under `seed`.
inline std::vector<TimeNs> coarse_clock_times_100hz(std::size_t n, unsigned seed) {
  constexpr TimeNs kTick = 5'120'000;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<TimeNs> delay(0, 4'000'000);
  std::vector<TimeNs> t(n);
  for (std::size_t i = 0; i < n; ++i)
    t[i] = ((static_cast<TimeNs>(i) * 10'000'000 + delay(rng)) / kTick) * kTick;
  return t;
}

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
