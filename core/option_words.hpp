// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The options a calibration's messages point to ("as requested (...)", "... keeps it anyway"),
// named by what they set. calib/ composes its sentences with option_words() and names no flag
// or key of its own: the program that hosts it installs its vocabulary once at start-up. The CLI
// says "--shutter rolling" (daemon/cli), the guided session says what the operator sets in the
// rig's configuration where there is such a key (app/session), and without a vocabulary (a
// library's user, the unit tests) the quantity is named with its value: "shutter: rolling".

#include <string>
#include <string_view>

namespace imucal {

enum class CalibOption {
  kShutter,          // value: global, rolling
  kLineDelay,        // a rolling shutter's line delay given (held)
  kReadout,          // value: top_to_bottom, bottom_to_top
  kHoldTimeOffsets,  // a camera chain's time offsets held at their stamps' (one pose per instant)
  kCamImuModel,      // value: basic, extended
  kImuIntrinsics,    // a static calibration given to the camera-IMU solve
  kGsens,            // a g-sensitivity given
  kFix,              // intrinsics held at their given values
  kKeepNoise,        // the given noise figures kept whatever the residuals say
  kAccelModel,       // value: faces, scale-bias
  kImportOffsets,    // the accelerometer's and gyroscope's zero counts given at import
  kImportScales,     // their scales given at import
};

/// A host's words for `option` set to `value` (empty when the option takes none).
using OptionVocabulary = std::string (*)(CalibOption option, std::string_view value);

/// The words without a host: the quantity and its value ("shutter: rolling", "line delay: given").
std::string plain_option_words(CalibOption option, std::string_view value);

/// Installs the vocabulary (nullptr: the plain words) and returns the one before. Meant for a
/// program's start; safe to call from any thread. A shared module holds its own copy of this
/// state: app's module loader passes the program's on (core/module.hpp).
OptionVocabulary set_option_vocabulary(OptionVocabulary vocabulary);

/// The installed vocabulary (nullptr: the plain words).
OptionVocabulary option_vocabulary();

/// `option` (set to `value`) in the installed vocabulary.
std::string option_words(CalibOption option, std::string_view value = {});

}  // namespace imucal
