// SPDX-License-Identifier: BSD-3-Clause
// The views a single camera's solve takes from a long recording (app/camera_calibration.hpp
// spread_views): at most the limit, spread evenly from the first view to near the last.

#include <gtest/gtest.h>

#include <set>

#include "app/camera_calibration.hpp"

namespace imucal::app {
namespace {

std::vector<calib::TargetObservation> numbered(int n) {
  std::vector<calib::TargetObservation> views(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    views[static_cast<std::size_t>(i)].t_ns = 1000 * static_cast<TimeNs>(i);
    views[static_cast<std::size_t>(i)].ids = {0};
    views[static_cast<std::size_t>(i)].px = {Eigen::Vector2d(1.0, 1.0)};
  }
  return views;
}

TEST(SpreadViews, AtMostTheLimitSpreadEvenlyOverTheRecording) {
  const auto views = numbered(1622);
  const auto chosen = spread_views(views, 400);
  ASSERT_EQ(chosen.size(), 400u);
  EXPECT_EQ(chosen.front().t_ns, 0);
  // Each chosen view opens its own run of 4 or 5 consecutive views, in order.
  std::set<TimeNs> distinct;
  for (std::size_t k = 0; k < chosen.size(); ++k) {
    distinct.insert(chosen[k].t_ns);
    if (k == 0) continue;
    const TimeNs gap = (chosen[k].t_ns - chosen[k - 1].t_ns) / 1000;
    EXPECT_GE(gap, 4) << "view " << k;
    EXPECT_LE(gap, 5) << "view " << k;
  }
  EXPECT_EQ(distinct.size(), 400u);
  EXPECT_GE(chosen.back().t_ns, 1617 * 1000) << "the last run ends at the recording's end";
}

TEST(SpreadViews, FramesWithoutTheTargetAreNotViews) {
  auto views = numbered(1000);
  for (std::size_t i = 0; i < views.size(); ++i)
    if (i % 2 == 1) {  // every other frame shows no target
      views[i].ids.clear();
      views[i].px.clear();
    }
  const auto chosen = spread_views(views, 400);
  ASSERT_EQ(chosen.size(), 400u);
  for (const auto& v : chosen) EXPECT_FALSE(v.empty()) << v.t_ns;
  EXPECT_EQ(spread_views(views, 0).size(), 500u);
}

TEST(SpreadViews, FewerViewsThanTheLimitOrNoLimitKeepEveryOne) {
  EXPECT_EQ(spread_views(numbered(399), 400).size(), 399u);
  EXPECT_EQ(spread_views(numbered(400), 400).size(), 400u);
  EXPECT_EQ(spread_views(numbered(1622), 0).size(), 1622u);
  EXPECT_TRUE(spread_views({}, 400).empty());
}

}  // namespace
}  // namespace imucal::app
