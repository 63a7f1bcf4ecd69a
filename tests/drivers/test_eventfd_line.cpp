// SPDX-License-Identifier: BSD-3-Clause
// The eventfd-backed simulated data-ready line (drivers/gpio/fake/eventfd_line.hpp): edges
// are scheduled at their kernel-like timestamps, released by time, and read through a real
// descriptor that is readable exactly while edges are.

#include <gtest/gtest.h>
#include <poll.h>

#include "drivers/gpio/fake/eventfd_line.hpp"

namespace imucal::fake {
namespace {

// The real-time line: an edge is readable on its eventfd only once CLOCK_MONOTONIC has passed
// its timestamp, and the descriptor is readable exactly while edges are.
TEST(RealtimeDataReadyLine, EdgesBecomeReadableAtTheirTimestamps) {
  fake::DataReadyTiming timing;
  timing.sigma_ns = 0;
  auto line = RealtimeDataReadyLine::create(timing);
  ASSERT_TRUE(line.ok());
  RealtimeDataReadyLine& l = **line;
  auto readable = [&] {
    pollfd p{l.fd(), POLLIN, 0};
    return ::poll(&p, 1, 0) == 1;
  };
  const TimeNs t0 = 1'000'000'000;
  l.raise(t0);
  l.raise(t0 + 1'000'000);
  EXPECT_FALSE(readable());
  EXPECT_EQ(l.release(t0 + 19'999), t0 + 20'000);
  EXPECT_FALSE(readable());
  EXPECT_EQ(l.release(t0 + 20'000), t0 + 1'020'000);
  EXPECT_TRUE(readable());
  auto e = l.wait(0);
  ASSERT_TRUE(e.ok());
  ASSERT_TRUE(e->has_value());
  EXPECT_EQ((*e)->t_ns, t0 + 20'000);
  EXPECT_EQ((*e)->sequence, 1u);
  EXPECT_FALSE(readable());
  e = l.wait(0);
  ASSERT_TRUE(e.ok());
  EXPECT_FALSE(e->has_value());
  EXPECT_EQ(l.release(t0 + 2'000'000), fake::SimTimeSource::kNever);
  e = l.wait(1'000'000);
  ASSERT_TRUE(e.ok());
  ASSERT_TRUE(e->has_value());
  EXPECT_EQ((*e)->sequence, 2u);
  EXPECT_FALSE(l.wait(-1).ok());
}

}  // namespace
}  // namespace imucal::fake
