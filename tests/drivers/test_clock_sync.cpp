// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "drivers/camera/clock_sync.hpp"

namespace imucal::drivers::camera {
namespace {

// A device clock running `ppm` fast from `device0_ns`, frames every `period_ns` of true (host)
// time, received after an exponentially distributed latency of mean `latency_mean_ns`.
struct SyntheticDevice {
  double ppm = 50.0;
  TimeNs device0_ns = 5'000'000'000;
  TimeNs host0_ns = 1'000'000'000'000;
  TimeNs period_ns = 33'333'333;
  double latency_mean_ns = 2e6;
  std::mt19937_64 rng{1};

  TimeNs true_ns(int k) const { return host0_ns + k * period_ns; }
  TimeNs device_ns(int k) const {
    return device0_ns +
           static_cast<TimeNs>(std::llround(static_cast<double>(k * period_ns) * (1.0 + ppm * 1e-6)));
  }
  TimeNs received_ns(int k) {
    std::exponential_distribution<double> latency(1.0 / latency_mean_ns);
    return true_ns(k) + static_cast<TimeNs>(latency(rng));
  }
};

TEST(ClockSync, MapsADriftingDeviceClockWithin200usAfter100Pairs) {
  // 50 seeds of a device 50 ppm fast, frames at 30 Hz, 2 ms exponential latency. After 100
  // pairs (3.3 s), the 100 frames seen are mapped back ("in window"); then each of the next 100
  // frames is mapped as it arrives ("on arrival", as the camera backend does: the fit has seen
  // the pair, but nothing after it).
  std::vector<double> in_window, on_arrival, drift_error;
  for (std::uint64_t seed = 1; seed <= 50; ++seed) {
    SyntheticDevice dev;
    dev.rng.seed(seed);
    ClockSync sync;
    int k = 0;
    for (; k < 100; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k))) << "seed " << seed;
    for (int j = 0; j < 100; ++j) {
      in_window.push_back(std::abs(static_cast<double>(sync.to_host(dev.device_ns(j)) - dev.true_ns(j))));
    }
    for (; k < 200; ++k) {
      ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k))) << "seed " << seed;
      on_arrival.push_back(std::abs(static_cast<double>(sync.to_host(dev.device_ns(k)) - dev.true_ns(k))));
    }
    const ClockSyncState s = sync.state();
    EXPECT_TRUE(s.valid);
    EXPECT_TRUE(s.drift_fitted);
    drift_error.push_back(std::abs(s.drift_ppm - 50.0));
    EXPECT_EQ(s.samples, 200u);
    EXPECT_EQ(s.resets, 0u);
    // The median of an exponential latency of mean 2 ms is 2 ms * ln 2 = 1.39 ms.
    EXPECT_NEAR(static_cast<double>(s.residual_median_ns), 2e6 * std::log(2.0), 0.4e6);
    EXPECT_GE(s.residual_median_ns, 0);
  }
  auto quantile = [](std::vector<double> v, double q) {
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
  };
  std::printf("in window: median %.0f us, p99 %.0f us, max %.0f us\n", quantile(in_window, 0.5) / 1e3,
              quantile(in_window, 0.99) / 1e3, quantile(in_window, 1.0) / 1e3);
  std::printf("on arrival: median %.0f us, p99 %.0f us, max %.0f us\n", quantile(on_arrival, 0.5) / 1e3,
              quantile(on_arrival, 0.99) / 1e3, quantile(on_arrival, 1.0) / 1e3);
  std::printf("drift error after 200 pairs: median %.1f ppm, max %.1f ppm\n", quantile(drift_error, 0.5),
              quantile(drift_error, 1.0));
  // 99 % within 0.2 ms; the rest are cases where the quickest frames of the window all came
  // late (the estimate cannot know the latency floor better than the pairs show it).
  EXPECT_LT(quantile(in_window, 0.99), 200e3);
  EXPECT_LT(quantile(on_arrival, 0.99), 200e3);
  EXPECT_LT(quantile(in_window, 0.5), 50e3);
  EXPECT_LT(quantile(on_arrival, 0.5), 50e3);
  EXPECT_LT(quantile(on_arrival, 1.0), 500e3);
  EXPECT_LT(quantile(drift_error, 0.5), 15.0);
}

TEST(ClockSync, ThePairsMappedBackLieOnOrBelowTheirReceiveTimes) {
  SyntheticDevice dev;
  ClockSync sync;
  for (int k = 0; k < 300; ++k) (void)sync.add(dev.device_ns(k), dev.received_ns(k));
  dev.rng.seed(1);
  for (int k = 0; k < 300; ++k) {
    const TimeNs received = dev.received_ns(k);
    EXPECT_LE(sync.to_host(dev.device_ns(k)), received + 1) << k;  // the lower envelope
  }
}

TEST(ClockSync, WithoutDriftEvidenceTheOffsetComesFromTheSmallestDelay) {
  SyntheticDevice dev;
  ClockSync sync;
  (void)sync.add(dev.device_ns(0), dev.true_ns(0) + 3'000'000);
  (void)sync.add(dev.device_ns(1), dev.true_ns(1) + 500'000);
  (void)sync.add(dev.device_ns(2), dev.true_ns(2) + 4'000'000);
  const ClockSyncState s = sync.state();
  EXPECT_FALSE(s.drift_fitted);
  EXPECT_DOUBLE_EQ(s.drift_ppm, 0.0);
  EXPECT_EQ(s.samples, 3u);
  // Frame 1 arrived quickest: it defines the offset (to within the 50 ppm over one frame).
  EXPECT_NEAR(static_cast<double>(sync.to_host(dev.device_ns(1)) - dev.true_ns(1)), 500'000.0, 2'000.0);
}

TEST(ClockSync, ADeviceClockResetIsDetectedAndTheFitRestarts) {
  SyntheticDevice dev;
  ClockSync sync;
  int k = 0;
  for (; k < 150; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k)));
  // Power cycle: the device counts from zero again.
  SyntheticDevice after = dev;
  after.device0_ns = 1'000'000 - k * dev.period_ns;
  EXPECT_TRUE(sync.add(after.device_ns(k), after.received_ns(k)));
  ClockSyncState s = sync.state();
  EXPECT_EQ(s.resets, 1u);
  EXPECT_EQ(s.samples, 1u);
  for (++k; k < 300; ++k) ASSERT_FALSE(sync.add(after.device_ns(k), after.received_ns(k))) << k;
  s = sync.state();
  EXPECT_EQ(s.resets, 1u);
  EXPECT_EQ(s.samples, 150u);
  EXPECT_NEAR(s.drift_ppm, 50.0, 30.0);
  EXPECT_LT(std::abs(static_cast<double>(sync.to_host(after.device_ns(299)) - after.true_ns(299))),
            200'000.0);
}

TEST(ClockSync, AForwardJumpIsDetectedAtOnce) {
  SyntheticDevice dev;
  ClockSync sync;
  int k = 0;
  for (; k < 100; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k)));
  SyntheticDevice after = dev;
  after.device0_ns += 10 * kNsPerSecond;  // e.g. a wall-clock step on the fake camera
  EXPECT_TRUE(sync.add(after.device_ns(k), after.received_ns(k)));
  EXPECT_EQ(sync.state().resets, 1u);
}

TEST(ClockSync, ABackwardJumpShorterThanAFrameIsConfirmedByARunOfLatePairs) {
  SyntheticDevice dev;
  ClockSync sync;
  int k = 0;
  for (; k < 100; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k)));
  SyntheticDevice after = dev;
  after.device0_ns -= 15'000'000;  // device times still increase (frames are 33 ms apart)
  int detected_at = -1;
  for (; k < 130 && detected_at < 0; ++k) {
    if (sync.add(after.device_ns(k), after.received_ns(k))) detected_at = k;
  }
  ASSERT_EQ(detected_at, 107) << "the eighth late pair confirms the jump";
  for (; k < 250; ++k) ASSERT_FALSE(sync.add(after.device_ns(k), after.received_ns(k))) << k;
  EXPECT_LT(std::abs(static_cast<double>(sync.to_host(after.device_ns(249)) - after.true_ns(249))),
            200'000.0);
}

TEST(ClockSync, ASingleLateFrameIsLatencyNotAJump) {
  SyntheticDevice dev;
  ClockSync sync;
  int k = 0;
  for (; k < 100; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k)));
  EXPECT_FALSE(sync.add(dev.device_ns(k), dev.true_ns(k) + 500'000'000));  // held for half a second
  for (++k; k < 120; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k)));
  EXPECT_EQ(sync.state().resets, 0u);
  EXPECT_LT(std::abs(static_cast<double>(sync.to_host(dev.device_ns(119)) - dev.true_ns(119))), 200'000.0);
}

TEST(ClockSync, WallClockDeviceStampsKeepNanosecondPrecision) {
  // Aravis's fake camera stamps with wall-clock time (~1.8e18 ns): beyond a double's exact range.
  SyntheticDevice dev;
  dev.device0_ns = 1'795'449'802'440'173'000;
  dev.ppm = 0.0;
  dev.latency_mean_ns = 100'000;
  ClockSync sync;
  for (int k = 0; k < 200; ++k) ASSERT_FALSE(sync.add(dev.device_ns(k), dev.received_ns(k)));
  EXPECT_LT(std::abs(static_cast<double>(sync.to_host(dev.device_ns(199)) - dev.true_ns(199))), 20'000.0);
  EXPECT_NEAR(sync.state().drift_ppm, 0.0, 5.0);
}

TEST(ClockSync, ClearForgetsThePairsButKeepsTheResetCount) {
  SyntheticDevice dev;
  ClockSync sync;
  for (int k = 0; k < 10; ++k) (void)sync.add(dev.device_ns(k), dev.received_ns(k));
  (void)sync.add(0, dev.true_ns(10));  // backwards: a reset
  sync.clear();
  const ClockSyncState s = sync.state();
  EXPECT_FALSE(s.valid);
  EXPECT_EQ(s.samples, 0u);
  EXPECT_EQ(s.resets, 1u);
  EXPECT_EQ(sync.to_host(12345), 12345);
}

}  // namespace
}  // namespace imucal::drivers::camera
