// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// CLI11 checks for option values that say what is wanted in a short message, unlike CLI11's
// PositiveNumber, whose range names the largest double in 310 digits. Used by imucal and imucald
// (daemon/common/: what the programs share, header-only).

#include <CLI/CLI.hpp>
#include <optional>
#include <string>

#include "core/text_format.hpp"

namespace imucal::cli {

enum class NumberSign { kAny, kPositive, kNonNegative };

/// A finite number (NaN and infinities refused), above zero or at zero or above as asked.
inline CLI::Validator finite_number(NumberSign sign) {
  return CLI::Validator(
      [sign](std::string& text) -> std::string {
        const std::optional<double> number = parse_finite_number(text);
        const std::string shown = text.size() > 40 ? text.substr(0, 40) + "..." : text;
        if (!number) return "'" + shown + "' is not a finite number";
        const double v = *number;
        if (sign == NumberSign::kPositive && v <= 0.0) return "'" + shown + "' must be more than zero";
        if (sign == NumberSign::kNonNegative && v < 0.0) return "'" + shown + "' must be zero or more";
        return {};
      },
      sign == NumberSign::kPositive      ? "NUMBER>0"
      : sign == NumberSign::kNonNegative ? "NUMBER>=0"
                                         : "NUMBER");
}

/// A value that is not empty (an empty value is a mistake, never "the default").
inline CLI::Validator non_empty() {
  return CLI::Validator([](std::string& text) -> std::string { return text.empty() ? "an empty value" : ""; },
                        "");
}

}  // namespace imucal::cli
