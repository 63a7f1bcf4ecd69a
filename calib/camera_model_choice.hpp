// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera model chosen by the evidence (`--model auto`, docs/camera-calibration.md, "Choosing
// the model"): every candidate model calibrated on the same views, the candidates that explain
// fewer views than the best left out (a pinhole model cannot see a board beyond 90 degrees), and
// among the rest the lowest Bayesian information criterion on the views and corners all of them
// use, BIC = n ln(RSS / n) + k ln n (n coordinates, k parameters: the camera's and 6 per view).

#include <span>
#include <string>
#include <vector>

#include "calib/camera_intrinsics.hpp"
#include "core/camera_model.hpp"
#include "core/result.hpp"
#include "core/target.hpp"

namespace imucal::calib {

/// One candidate's fit.
struct CameraModelFit {
  CameraModelKind model;
  bool compared = false;  // false: left out (`why_not`)
  std::string why_not;    // the solve's error, or the views it does not explain
  int views_used = 0;     // by its own solve
  double rms_px = 0.0;    // of its own solve
  /// On the common views and corners: the RSS (px^2), the parameters k, BIC and its difference
  /// to the chosen one's (0 for the chosen).
  double rss_px2 = 0.0;
  int params = 0;
  double bic = 0.0;
  double delta_bic = 0.0;
};

struct CameraModelChoice {
  CameraModelKind chosen;
  std::vector<CameraModelFit> fits;  // in the order of the candidates
  int common_views = 0;
  int common_corners = 0;
  std::string reason;  // one sentence: the chosen model, by how much, over which data
};

struct ChosenCamera {
  CameraIntrinsicsResult result;  // the chosen model's calibration
  CameraModelChoice choice;
};

/// Calibrates every candidate with `options` (its model replaced) and chooses. Fails when no
/// candidate calibrates (the first candidate's error) or candidates is empty.
[[nodiscard]] Result<ChosenCamera> choose_camera_model(const TargetDescription& target,
                                                       std::span<const TargetObservation> observations,
                                                       const CameraIntrinsicsOptions& options,
                                                       const std::vector<CameraModelKind>& candidates);

}  // namespace imucal::calib
