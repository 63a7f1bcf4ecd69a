// SPDX-License-Identifier: BSD-3-Clause
// The text helpers every layer shares (core/text_format.hpp): the one number parser, and the
// formatting of numbers, hex and UTC stamps.

#include <gtest/gtest.h>

#include <cmath>
#include <regex>

#include "core/text_format.hpp"

namespace imucal {
namespace {

TEST(TextFormat, ParseFiniteNumberTakesOneWholeFiniteNumber) {
  EXPECT_EQ(parse_finite_number("1.5"), 1.5);
  EXPECT_EQ(parse_finite_number("+2e-3"), 2e-3);
  EXPECT_EQ(parse_finite_number("-0.25"), -0.25);
  EXPECT_EQ(parse_finite_number("0"), 0.0);
  for (const char* bad :
       {"", "+", "-", "+-1", "++1", "-+1", " 1", "1 ", "1.5s", "0x10", "nan", "inf", "-inf", "1e999", "1,5"})
    EXPECT_FALSE(parse_finite_number(bad)) << "'" << bad << "' was taken as a number";
}

TEST(TextFormat, NumbersHexAndStamps) {
  EXPECT_EQ(fixed(1.23456, 2), "1.23");
  EXPECT_EQ(fixed(-0.5, 0), "-0");
  EXPECT_EQ(format_number("%+.2e", 1234.5), "+1.23e+03");
  EXPECT_EQ(format_hex(0x68, 2), "0x68");
  EXPECT_EQ(format_hex(0xabc, 2), "0xABC");
  EXPECT_TRUE(std::regex_match(utc_now_iso8601(), std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ)")))
      << utc_now_iso8601();
}

TEST(TextFormat, ASigmaGetsTwoSignificantDigitsAndNeverReadsAsZero) {
  EXPECT_EQ(decimals_for_sigma(0.0021, 2), 4);  // "0.0021", not "0.00"
  EXPECT_EQ(decimals_for_sigma(0.25, 2), 2);
  EXPECT_EQ(decimals_for_sigma(0.099, 2), 3);
  EXPECT_EQ(decimals_for_sigma(3.7, 2), 2);  // never fewer than asked for
  EXPECT_EQ(decimals_for_sigma(1e-15, 2), 9);
  EXPECT_EQ(decimals_for_sigma(std::nan(""), 3), 3);
  EXPECT_EQ(decimals_for_sigma(0.0, 3), 3);
  EXPECT_NE(fixed(0.0021, decimals_for_sigma(0.0021, 2)), fixed(0.0, decimals_for_sigma(0.0021, 2)));
}

}  // namespace
}  // namespace imucal
