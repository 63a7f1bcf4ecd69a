// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// How a solve treats the cameras' shutters (core/camera_model.hpp Shutter): the camera-IMU solve
// (calib/camimu_calibration.hpp) and the camera solve on a trajectory (calib/camera_chain.hpp)
// share it. Method: docs/camimu-calibration.md and docs/camera-calibration.md, "Rolling shutter".

#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include "core/camera_model.hpp"
#include "core/option_words.hpp"

namespace imucal::calib {

/// kAuto:    global or rolling by the evidence: the global solution, then the line delay freed;
///           rolling is kept when the drop of the chi-square exceeds what the parameters cost (BIC,
///           k ln n with n the corner measurements), and the result says which and why.
/// kGlobal:  every camera global (a camera file's rolling shutter is ignored, with a note).
/// kRolling: every camera rolling, its line delay estimated (started from the camera's).
/// A line delay given here holds every camera rolling at that value (kGlobal with one is an error).
/// The readout direction and the stamped row are the camera's (CameraModel::shutter).
struct ShutterSolveOptions {
  enum class Mode { kAuto, kGlobal, kRolling };
  Mode mode = Mode::kAuto;
  std::optional<double> line_delay_s;
};

/// The BIC test of a rolling against a global shutter: `lr` the drop of the chi-square (twice the
/// cost's drop at the same weights), `k` the line delays freed, `n` their cameras' corner
/// measurements (two per corner).
inline double shutter_bic_threshold(double k, double n) { return k * std::log(n > 2.0 ? n : 2.0); }

/// The shortest readout (|line delay| x (rows - 1)) kept as a rolling shutter by the evidence:
/// rolling-shutter sensors read a frame out in several milliseconds; a fitted line delay far
/// below that on a global-shutter camera only absorbs what the model leaves (the detector's
/// motion-dependent bias): statistically clear on a rendered recording with 0.03 px of corner
/// noise (-0.24 +- 0.03 us per row, 0.06 ms, on the camera fixture), physically nothing.
inline constexpr double kMinRollingReadoutS = 0.5e-3;

/// The shutter choice the user made: global (`note`: what else is known of the camera, or
/// empty), or rolling with the line delay given.
inline std::string global_as_requested(const std::string& note) {
  return "global, as requested (" + option_words(CalibOption::kShutter, "global") +
         (note.empty() ? "" : "; ") + note + ")";
}
inline std::string line_delay_as_given() {
  return "rolling, line delay held at the given value (" + option_words(CalibOption::kLineDelay) + ")";
}

/// The advice when a line delay comes out negative: the readout other than `current`, in the
/// host's words ("--readout bottom_to_top").
inline std::string other_readout_words(Shutter::Readout current) {
  return option_words(CalibOption::kReadout, readout_name(current == Shutter::Readout::kTopToBottom
                                                              ? Shutter::Readout::kBottomToTop
                                                              : Shutter::Readout::kTopToBottom));
}

/// What the evidence says of line delays freed after the global solution: `lr` the drop of the
/// chi-square, `k` the line delays freed, `n` their cameras' corner measurements, `readout_s`
/// the longest readout found; `choose` false when rolling was asked for (kept whatever the
/// evidence). `rolling` false: the global solution is to be restored.
struct ShutterVerdict {
  bool rolling = false;
  std::string text;  // the result's shutter_choice
};
inline ShutterVerdict judge_shutter(bool choose, double lr, double k, double n, double readout_s) {
  const double threshold = shutter_bic_threshold(k, n);
  char text[640];
  const std::string rolling = option_words(CalibOption::kShutter, "rolling");
  ShutterVerdict v;
  v.rolling = !choose || (lr > threshold && readout_s >= kMinRollingReadoutS);
  if (!v.rolling && lr > threshold) {
    std::snprintf(
        text, sizeof text,
        "global, chosen by the evidence: the line delay found reads a frame out in %.3f ms, less than "
        "the %.1f ms of any rolling-shutter sensor (its chi-square drop %.1f against %.1f is what the "
        "model leaves, not a shutter); asking for a rolling shutter (%s) keeps it anyway",
        1e3 * readout_s, 1e3 * kMinRollingReadoutS, lr, threshold, rolling.c_str());
  } else if (!v.rolling) {
    std::snprintf(
        text, sizeof text,
        "global, chosen by the evidence: freeing the line delay lowers the chi-square by only %.1f, less "
        "than the %.1f it costs (BIC: k ln n, n = %.0f corner measurements); asking for a rolling shutter "
        "(%s) estimates it anyway",
        lr, threshold, n, rolling.c_str());
  } else if (choose) {
    std::snprintf(
        text, sizeof text,
        "rolling, chosen by the evidence: freeing the line delay lowers the chi-square by %.1f, more "
        "than the %.1f it costs (BIC: k ln n, n = %.0f corner measurements)",
        lr, threshold, n);
  } else {
    std::snprintf(text, sizeof text,
                  "rolling, as requested (%s); the line delay lowers the chi-square by %.1f "
                  "(BIC threshold %.1f, n = %.0f corner measurements)",
                  rolling.c_str(), lr, threshold, n);
  }
  v.text = text;
  return v;
}

}  // namespace imucal::calib
