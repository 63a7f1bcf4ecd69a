#include <gtest/gtest.h>

#include <vector>

#include "core/time.hpp"

namespace imucal {
namespace {

TEST(MedianInterval, IgnoresGapsAndNeedsTwoTimes) {
  EXPECT_EQ(median_interval_ns(std::vector<TimeNs>{}), 0);
  EXPECT_EQ(median_interval_ns(std::vector<TimeNs>{5}), 0);
  // 10 ms steps with one 2.5 s gap: the gap does not move the median.
  std::vector<TimeNs> t;
  for (int i = 0; i < 20; ++i) t.push_back(i * 10'000'000);
  t.push_back(t.back() + 2'500'000'000);
  t.push_back(t.back() + 10'000'000);
  EXPECT_EQ(median_interval_ns(t), 10'000'000);
  // An even count of intervals takes the upper median.
  EXPECT_EQ(median_interval_ns(std::vector<TimeNs>{0, 1, 3, 6, 10}), 3);
}

}  // namespace
}  // namespace imucal
