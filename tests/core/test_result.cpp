// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal {
namespace {

Result<int> parse_positive(int v) {
  if (v <= 0) return make_error(Errc::kInvalidArgument, "not positive");
  return v;
}

Status chain(int v) {
  IMUCAL_TRY(parse_positive(v));
  return {};
}

TEST(Result, CarriesValueOrError) {
  auto good = parse_positive(3);
  ASSERT_TRUE(good.ok());
  EXPECT_EQ(*good, 3);
  auto bad = parse_positive(-1);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, Errc::kInvalidArgument);
  EXPECT_EQ(bad.error().context("x").message, "x: not positive");
}

TEST(Result, TryPropagates) {
  EXPECT_TRUE(chain(1).ok());
  EXPECT_FALSE(chain(0).ok());
}

TEST(Time, ConversionsRoundToNearestNanosecond) {
  EXPECT_EQ(s_to_ns(1.5), 1'500'000'000);
  EXPECT_EQ(s_to_ns(1e-9 * 0.6), 1);
  EXPECT_DOUBLE_EQ(ns_to_s(2'500'000'000), 2.5);
  EXPECT_GT(monotonic_now_ns(), 0);
}

}  // namespace
}  // namespace imucal
