// SPDX-License-Identifier: BSD-3-Clause
#include "app/session/option_words.hpp"

namespace imucal::app::session {

std::string session_option_words(CalibOption option, std::string_view value) {
  const std::string v(value);
  switch (option) {
    case CalibOption::kShutter:
      return "shutter: " + v + " in the camera's entry of the rig configuration";
    case CalibOption::kLineDelay:
      return "line_delay_us in the camera's entry of the rig configuration";
    case CalibOption::kReadout:
      return "readout_direction: " + v + " in the camera's entry of the rig configuration";
    default:
      return plain_option_words(option, value);
  }
}

}  // namespace imucal::app::session
