// SPDX-License-Identifier: BSD-3-Clause
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

TEST(StepLostSamples, ALongStepMadeUpForByItsNeighbourIsNot) {
  // Median 10: 10 -> 26 is long but 26 -> 30 makes up for it; 40 -> 60 lost a sample; 70 -> 86 is
  // long and 60 -> 70 before it, 86 -> 100 after it are not short enough to make up for it.
  const std::vector<TimeNs> t = {0, 10, 26, 30, 40, 60, 70, 86, 100, 110};
  const TimeNs median = 10;
  const std::vector<bool> expected = {false, false, false, false, true, false, true, false, false};
  for (std::size_t k = 0; k + 1 < t.size(); ++k) EXPECT_EQ(step_lost_samples(t, k, median), expected[k]) << k;
  // A short step before the long one makes up for it as well as one after it.
  EXPECT_FALSE(step_lost_samples(std::vector<TimeNs>{0, 10, 14, 30, 40}, 2, median));
  // At the ends there is only one neighbour.
  EXPECT_TRUE(step_lost_samples(std::vector<TimeNs>{0, 20, 30}, 0, median));
  EXPECT_FALSE(step_lost_samples(std::vector<TimeNs>{0, 16, 20}, 0, median));
}

}  // namespace
}  // namespace imucal
