// SPDX-License-Identifier: BSD-3-Clause
#include "core/text_format.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <ctime>

namespace imucal {

std::string fixed(double value, int digits) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", digits, value);
  return text;
}

int decimals_for_sigma(double sigma, int least) {
  if (!std::isfinite(sigma) || !(sigma > 0.0)) return least;
  return std::clamp(1 - static_cast<int>(std::floor(std::log10(sigma))), least, 9);
}

std::string format_number(const char* format, double value) {
  char text[64];
  std::snprintf(text, sizeof text, format, value);
  return text;
}

std::string format_hex(unsigned long value, int digits) {
  char text[24];
  std::snprintf(text, sizeof text, "0x%0*lX", digits, value);
  return text;
}

std::string utc_now(const char* format) {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[64];
  std::strftime(text, sizeof text, format, &tm);
  return text;
}

std::string utc_now_iso8601() { return utc_now("%Y-%m-%dT%H:%M:%SZ"); }

std::optional<double> parse_finite_number(std::string_view text) {
  std::string_view body = text;
  if (!body.empty() && body[0] == '+') {
    body.remove_prefix(1);
    // One sign at most: "+-1" and "++1" are not numbers.
    if (!body.empty() && (body[0] == '+' || body[0] == '-')) return std::nullopt;
  }
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(body.data(), body.data() + body.size(), v);
  if (body.empty() || ec != std::errc() || ptr != body.data() + body.size() || !std::isfinite(v))
    return std::nullopt;
  return v;
}

}  // namespace imucal
