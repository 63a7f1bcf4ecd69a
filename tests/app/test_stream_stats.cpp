// SPDX-License-Identifier: BSD-3-Clause
// Stream statistics and the clean run of the Allan deviation, against the fixtures' known
// figures (fixtures/README.md: 98.5 Hz measured at a nominal 100 Hz).

#include <gtest/gtest.h>

#include "app/stream_stats.hpp"
#include "app/streams.hpp"
#include "tests/support/test_helpers.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

TEST(StreamStats, StaticFixture) {
  auto s = summarize_log(test::source_path("fixtures/static.imulog"));
  ASSERT_TRUE(s.ok()) << s.error().message;
  ASSERT_EQ(s->imu.size(), 1u);
  const auto& imu = s->imu[0];
  EXPECT_EQ(imu.timing.count, 18744);
  EXPECT_NEAR(imu.timing.measured_rate_hz, 98.5, 1e-3);
  EXPECT_EQ(imu.timing.median_period_ns, 10152131);
  EXPECT_EQ(imu.timing.gap_intervals, 0);
  EXPECT_EQ(imu.timing.non_increasing, 0);
  EXPECT_NEAR(imu.timing.duration_s(), 190.284, 1e-3);
  EXPECT_EQ(imu.flagged_gap, 0);
  EXPECT_TRUE(imu.read_error.empty());
  EXPECT_TRUE(s->any_time);
  EXPECT_EQ(s->t_start_ns, 1930143);
  EXPECT_FALSE(s->health.damaged);
  EXPECT_EQ(s->meta("schema_version"), "1");
}

TEST(StreamStats, GapFixtureCountsItsGaps) {
  auto s = summarize_log(test::source_path("fixtures/broken-gap.imulog"));
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->imu[0].flagged_gap, 2);
  EXPECT_EQ(s->imu[0].timing.gap_intervals, 2);
  EXPECT_GT(s->imu[0].timing.longest_interval_ns, 900'000'000);
}

TEST(StreamStats, TimingOfHandMadeTimes) {
  const StreamTiming t = timing_of({0, 10, 20, 20, 50, 60});
  EXPECT_EQ(t.count, 6);
  EXPECT_EQ(t.median_period_ns, 10);
  EXPECT_EQ(t.gap_intervals, 1);  // 30 > 1.5 x 10, and 20 -> 60 is not under 2.5 x 10
  // A coarse or jittery clock: 16 next to 4 lost nothing.
  EXPECT_EQ(timing_of({0, 10, 26, 30, 40, 50}).gap_intervals, 0);
  EXPECT_EQ(t.non_increasing, 1);
  EXPECT_EQ(t.longest_interval_ns, 30);
  EXPECT_EQ(t.longest_interval_at_ns, 50);
  EXPECT_EQ(timing_of({}).count, 0);
}

// A log of any length is summarised in bounded memory: the median interval comes from the
// first timestamps, and each later interval is judged as it comes. Short windows here, so that
// every way an interval can fall (inside the window, across its end, after it, the last one)
// is met; the figures are those of the whole vector.
TEST(StreamStats, TimingInBoundedMemoryMatchesTheWholeStream) {
  std::vector<TimeNs> times;
  TimeNs t = 1000;
  for (int i = 0; i < 200; ++i) {
    // 10 ns steps; a lost sample at 7, 40 and 199 (the last interval), a step back at 120,
    // jitter that makes up for itself at 60-61, and the longest interval at 150.
    TimeNs step = 10;
    if (i == 7 || i == 40 || i == 199) step = 20;
    if (i == 120) step = -3;
    if (i == 60) step = 16;
    if (i == 61) step = 4;
    if (i == 150) step = 55;
    times.push_back(t);
    t += step;
  }
  const StreamTiming whole = timing_of(times);
  EXPECT_EQ(whole.gap_intervals, 3);  // 7, 40 and 150 (199 is the step after the last timestamp)
  EXPECT_EQ(whole.non_increasing, 1);
  for (const std::size_t window : {4u, 5u, 8u, 41u, 199u, 200u, 1000u}) {
    SCOPED_TRACE(window);
    TimingAccumulator acc(window);
    for (const TimeNs x : times) acc.add(x);
    const StreamTiming bounded = acc.finish();
    EXPECT_EQ(bounded.count, whole.count);
    EXPECT_EQ(bounded.t_first_ns, whole.t_first_ns);
    EXPECT_EQ(bounded.t_last_ns, whole.t_last_ns);
    EXPECT_EQ(bounded.median_period_ns, 10);
    EXPECT_EQ(bounded.gap_intervals, whole.gap_intervals);
    EXPECT_EQ(bounded.non_increasing, whole.non_increasing);
    EXPECT_EQ(bounded.longest_interval_ns, whole.longest_interval_ns);
    EXPECT_EQ(bounded.longest_interval_at_ns, whole.longest_interval_at_ns);
    EXPECT_DOUBLE_EQ(bounded.measured_rate_hz, whole.measured_rate_hz);
  }
  // One and two timestamps.
  TimingAccumulator one(4);
  one.add(5);
  EXPECT_EQ(one.finish().count, 1);
  TimingAccumulator two(4);
  two.add(5);
  two.add(25);
  const StreamTiming t2 = two.finish();
  EXPECT_EQ(t2.median_period_ns, 20);
  EXPECT_EQ(t2.longest_interval_ns, 20);
  EXPECT_EQ(t2.gap_intervals, 0);
}

TEST(CleanRun, LongestRunBetweenGaps) {
  auto loaded = load_imu_stream(test::source_path("fixtures/broken-gap.imulog"), "", DamagePolicy::kRefuse);
  ASSERT_TRUE(loaded.ok());
  auto run = longest_clean_run(loaded->samples);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->breaks, 2);
  EXPECT_NEAR(run->rate_hz, 98.5, 0.1);
  // `imucal allan` reports 100.5 s of 199.5 s for this log.
  EXPECT_NEAR(static_cast<double>(run->size()) / run->rate_hz, 100.5, 0.05);
  for (std::size_t i = run->begin + 1; i < run->end; ++i) {
    ASSERT_EQ(loaded->samples[i].flags & kImuFlagGapBefore, 0u);
  }
}

TEST(CleanRun, ACoarseClockDoesNotBreakTheRun) {
  // 100 Hz samples stamped by a host on a coarse clock, no sample lost: one run, at the samples'
  // rate (the median step would say 97.7 Hz).
  std::vector<ImuSample> s(5000);
  const std::vector<TimeNs> t = test::coarse_clock_times_100hz(s.size(), 3);
  for (std::size_t i = 0; i < s.size(); ++i) s[i].t_ns = t[i];
  auto run = longest_clean_run(s);
  ASSERT_TRUE(run.ok());
  EXPECT_EQ(run->breaks, 0);
  EXPECT_EQ(run->size(), s.size());
  EXPECT_NEAR(run->rate_hz, 100.0, 0.01);
}

TEST(CleanRun, RefusesTimestampsThatDoNotIncrease) {
  std::vector<ImuSample> s(10);
  auto run = longest_clean_run(s);
  ASSERT_FALSE(run.ok());
  EXPECT_EQ(run.error().code, Errc::kCorrupt);
}

TEST(FirstMotion, StillAndMoving) {
  std::vector<Eigen::Vector3d> accel;
  for (int i = 0; i < 2000; ++i) accel.emplace_back(0.01 * ((i * 7919) % 13 - 6), 0.0, 9.81);
  EXPECT_FALSE(first_motion_s(accel, 100.0).has_value());
  for (int i = 1500; i < 1600; ++i) accel[i].x() += (i % 2 ? 5.0 : -5.0);
  const auto moved = first_motion_s(accel, 100.0);
  ASSERT_TRUE(moved.has_value());
  EXPECT_NEAR(*moved, 15.0, 1.5);
}

}  // namespace
}  // namespace imucal::app
