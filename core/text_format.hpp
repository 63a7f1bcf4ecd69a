// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Small text helpers every layer uses for messages, reports and file stamps (one home each).

#include <optional>
#include <string>
#include <string_view>

namespace imucal {

/// `value` with `digits` digits after the point ("%.*f"): fixed(1.23456, 2) is "1.23".
std::string fixed(double value, int digits);

/// Digits after the point that show `sigma` to two significant digits, and never fewer than
/// `least` (nor more than 9): decimals_for_sigma(0.0021, 2) is 4, decimals_for_sigma(0.25, 2) is 2;
/// `least` for a sigma that is not finite or not positive. For a figure and its sigma alike, so
/// that a small sigma is never printed as 0.
int decimals_for_sigma(double sigma, int least);

/// `value` through one printf conversion for a double (`format` such as "%.3f" or "%+.2e").
std::string format_number(const char* format, double value);

/// `value` as "0x" and `digits` upper-case hex digits (at least): format_hex(0x68, 2) is "0x68".
std::string format_hex(unsigned long value, int digits);

/// The current UTC time through strftime's `format`; utc_now_iso8601() is
/// "YYYY-mm-ddTHH:MM:SSZ".
std::string utc_now(const char* format);
std::string utc_now_iso8601();

/// The number `text` holds, when it holds exactly one finite decimal number: an optional single
/// leading '+' or '-', then what std::from_chars reads (no spaces, no hex, no NaN or infinity).
/// The one number parser of the programs: option values, configuration, datasets, calib files.
std::optional<double> parse_finite_number(std::string_view text);

}  // namespace imucal
