// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The guided session's words for the options a calibration's messages point to
// (core/option_words.hpp): the rig configuration's key where the operator has one (a camera's
// shutter, line_delay_us, readout_direction), the quantity and its value otherwise, as the
// session runs with the solvers' defaults. imucald installs them at start-up and `imucal replay`
// while it replays, so that a replay says what the live session said.

#include <string>
#include <string_view>

#include "core/option_words.hpp"

namespace imucal::app::session {

std::string session_option_words(CalibOption option, std::string_view value);

}  // namespace imucal::app::session
