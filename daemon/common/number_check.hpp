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
/// An option's value as a message quotes it: at most 40 characters.
inline std::string quoted_value(const std::string& text) {
  return "'" + (text.size() > 40 ? text.substr(0, 40) + "..." : text) + "'";
}

inline CLI::Validator finite_number(NumberSign sign) {
  return CLI::Validator(
      [sign](std::string& text) -> std::string {
        const std::optional<double> number = parse_finite_number(text);
        const std::string shown = quoted_value(text);
        if (!number) return shown + " is not a finite number";
        const double v = *number;
        if (sign == NumberSign::kPositive && v <= 0.0) return shown + " must be more than zero";
        if (sign == NumberSign::kNonNegative && v < 0.0) return shown + " must be zero or more";
        return {};
      },
      sign == NumberSign::kPositive      ? "NUMBER>0"
      : sign == NumberSign::kNonNegative ? "NUMBER>=0"
                                         : "NUMBER");
}

/// 0 (an option's "chosen for you" or "off") or a finite number within [lo, hi]: the one range of an
/// option whose library check reads the same (CamImuOptions::validate()).
inline CLI::Validator zero_or_range(double lo, double hi) {
  const std::string range = format_number("%g", lo) + " - " + format_number("%g", hi);
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        const std::optional<double> number = parse_finite_number(text);
        if (!number) return quoted_value(text) + " is not a finite number";
        if (*number != 0.0 && (*number < lo || *number > hi))
          return quoted_value(text) + " must be 0 or in " + range;
        return {};
      },
      "0 or [" + range + "]");
}

/// A value that is not empty (an empty value is a mistake, never "the default").
inline CLI::Validator non_empty() {
  return CLI::Validator([](std::string& text) -> std::string { return text.empty() ? "an empty value" : ""; },
                        "");
}

}  // namespace imucal::cli
