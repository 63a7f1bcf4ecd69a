// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The CLI's words for the options a calibration's messages point to (core/option_words.hpp): its
// flags with their values ("--shutter rolling"). main() installs them.

#include <string>
#include <string_view>

#include "core/option_words.hpp"

namespace imucal::cli {

std::string cli_option_words(CalibOption option, std::string_view value);

}  // namespace imucal::cli
