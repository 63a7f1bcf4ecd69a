// SPDX-License-Identifier: BSD-3-Clause
// GpiodDataReadyLine: what can be checked without a GPIO chip (the Debian kernel has neither
// gpio-sim nor gpio-mockup): configuration and lookup errors, the event-clock rule and the
// timestamp conversion; then edge numbering over a fake kernel event queue that drops edges as
// the uAPI v1 queue does (16 kept, newer edges dropped until it is read), alone and feeding the
// timestamper. Edges from a real gpiolib are checked under QEMU (docs/testing-devices.md).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <random>
#include <vector>

#include "acquisition/timestamp.hpp"
#include "core/imu.hpp"
#include "drivers/gpio/gpiod_line.hpp"

namespace imucal::drivers {
namespace {

bool any_gpiochip() {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec)) {
    if (e.path().filename().string().rfind("gpiochip", 0) == 0) return true;
  }
  return false;
}

TEST(GpiodLine, UnconfiguredLineIsInvalid) {
  auto line = GpiodDataReadyLine::open({});
  ASSERT_FALSE(line.ok());
  EXPECT_EQ(line.error().code, Errc::kInvalidArgument);
  EXPECT_NE(line.error().message.find("imu.data_ready.chip"), std::string::npos) << line.error().message;
}

TEST(GpiodLine, MissingChipSaysWhatToCheck) {
  GpiodLineOptions options;
  options.chip = "imucal-no-such-gpiochip";
  options.line = "17";
  auto line = GpiodDataReadyLine::open(options);
  ASSERT_FALSE(line.ok());
  EXPECT_EQ(line.error().code, Errc::kNotFound);
  const std::string& msg = line.error().message;
  EXPECT_NE(msg.find("imucal-no-such-gpiochip"), std::string::npos) << msg;
  EXPECT_NE(msg.find("gpiodetect"), std::string::npos) << msg;
  EXPECT_NE(msg.find("imu.data_ready.line"), std::string::npos) << msg;
}

TEST(GpiodLine, MissingLineOnARealChipSaysWhatToCheck) {
  if (!any_gpiochip()) GTEST_SKIP() << "no /dev/gpiochip* on this machine (needs a real GPIO chip)";
  GpiodLineOptions options;
  options.chip = "0";
  options.line = "4095";
  auto line = GpiodDataReadyLine::open(options);
  ASSERT_FALSE(line.ok());
  EXPECT_EQ(line.error().code, Errc::kNotFound) << line.error().message;
  EXPECT_NE(line.error().message.find("4095"), std::string::npos) << line.error().message;

  options.line = "imucal-no-such-line-name";
  auto named = GpiodDataReadyLine::open(options);
  ASSERT_FALSE(named.ok());
  EXPECT_NE(named.error().message.find("imucal-no-such-line-name"), std::string::npos);
}

TEST(GpiodLine, EventClockFollowsTheKernelVersion) {
  EXPECT_EQ(gpio_event_clock_for_kernel("4.19.97-v7l+"), GpioEventClock::kRealtime);
  EXPECT_EQ(gpio_event_clock_for_kernel("5.4.0-150-generic"), GpioEventClock::kRealtime);
  EXPECT_EQ(gpio_event_clock_for_kernel("5.6.19"), GpioEventClock::kRealtime);
  EXPECT_EQ(gpio_event_clock_for_kernel("5.7.0"), GpioEventClock::kMonotonic);
  EXPECT_EQ(gpio_event_clock_for_kernel("5.10.0-rpi"), GpioEventClock::kMonotonic);
  EXPECT_EQ(gpio_event_clock_for_kernel("6.1.0-56-amd64"), GpioEventClock::kMonotonic);
  EXPECT_EQ(gpio_event_clock_for_kernel("3"), GpioEventClock::kMonotonic);
  EXPECT_EQ(gpio_event_clock_for_kernel(""), GpioEventClock::kMonotonic);
}

TEST(GpiodLine, TimestampConversionToMonotonic) {
  const TimeNs mono_now = 5'000 * kNsPerSecond;
  const TimeNs real_now = 1'790'000'000 * kNsPerSecond;

  // Monotonic kernels: passed through.
  auto t = gpio_event_to_monotonic(mono_now - 300'000, GpioEventClock::kMonotonic, mono_now, real_now);
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(*t, mono_now - 300'000);

  // Realtime kernels: shifted by the realtime-monotonic offset.
  auto r = gpio_event_to_monotonic(real_now - 300'000, GpioEventClock::kRealtime, mono_now, real_now);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(*r, mono_now - 300'000);

  // A realtime stamp taken for monotonic (or the reverse) is caught, not passed on.
  auto wrong = gpio_event_to_monotonic(real_now, GpioEventClock::kMonotonic, mono_now, real_now);
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.error().code, Errc::kDevice);
  EXPECT_NE(wrong.error().message.find("CLOCK_MONOTONIC"), std::string::npos);
  EXPECT_FALSE(gpio_event_to_monotonic(mono_now, GpioEventClock::kRealtime, mono_now, real_now).ok());

  // Small future offsets (clock read just before the event was stamped) are tolerated.
  EXPECT_TRUE(
      gpio_event_to_monotonic(mono_now + 500'000, GpioEventClock::kMonotonic, mono_now, real_now).ok());
  EXPECT_FALSE(
      gpio_event_to_monotonic(mono_now + 5'000'000, GpioEventClock::kMonotonic, mono_now, real_now).ok());
  EXPECT_FALSE(gpio_event_to_monotonic(mono_now - 2 * 3600 * kNsPerSecond, GpioEventClock::kMonotonic,
                                       mono_now, real_now)
                   .ok());
}

// --- edge numbering over a fake kernel ----------------------------------------------------------

// The line's event queue as gpiolib-cdev.c keeps it for uAPI v1: 16 events; while it is full
// every new edge is dropped, until a read makes room.
struct V1EventQueue {
  std::deque<TimeNs> events;
  std::uint64_t edges = 0;    // edges made
  std::uint64_t dropped = 0;  // edges the queue had no room for
  void edge(TimeNs t_ns) {
    ++edges;
    if (events.size() < kGpioV1EventQueueDepth) {
      events.push_back(t_ns);
    } else {
      ++dropped;
    }
  }
};

class V1EventSource final : public GpioEventSource {
 public:
  explicit V1EventSource(V1EventQueue& queue) : queue_(queue) {}
  int wait(TimeNs) override { return queue_.events.empty() ? 0 : 1; }
  int read(std::span<TimeNs> stamps) override {
    const std::size_t n = std::min(stamps.size(), queue_.events.size());
    for (std::size_t i = 0; i < n; ++i) {
      stamps[i] = queue_.events.front();
      queue_.events.pop_front();
    }
    return static_cast<int>(n);
  }
  int fd() const override { return -1; }

 private:
  V1EventQueue& queue_;
};

// Edge n of a chip sampling every period_ns, stamped latency_ns (with Gaussian jitter) after its
// sample; the stamps lie in the recent past of CLOCK_MONOTONIC, as the line checks.
class EdgeTrain {
 public:
  EdgeTrain(TimeNs period_ns, TimeNs latency_ns, TimeNs jitter_ns, std::uint64_t seed)
      : period_ns_(period_ns), latency_ns_(latency_ns), jitter_ns_(jitter_ns), rng_(seed) {}
  TimeNs sample_t(std::int64_t n) const { return base_ns_ + n * period_ns_; }
  TimeNs stamp(std::int64_t n) {
    const double j = jitter_ns_ > 0 ? normal_(rng_) * static_cast<double>(jitter_ns_) : 0.0;
    return sample_t(n) + std::max<TimeNs>(0, latency_ns_ + static_cast<TimeNs>(std::llround(j)));
  }

 private:
  TimeNs base_ns_ = monotonic_now_ns() - 600 * kNsPerSecond;
  TimeNs period_ns_, latency_ns_, jitter_ns_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

std::vector<DataReadyEdge> drain(GpiodDataReadyLine& line) {
  std::vector<DataReadyEdge> got;
  for (;;) {
    auto e = line.wait(0);
    EXPECT_TRUE(e.ok()) << e.error().message;
    if (!e.ok() || !e->has_value()) return got;
    got.push_back(**e);
  }
}

TEST(GpiodLine, PromptReadsNumberEdgesInOrder) {
  V1EventQueue kernel;
  auto line = GpiodDataReadyLine::over(std::make_unique<V1EventSource>(kernel), "fake:3");
  EdgeTrain train(1'000'000, 50'000, 30'000, 1);
  for (std::int64_t n = 0; n < 100; ++n) {
    kernel.edge(train.stamp(n));
    const auto got = drain(*line);
    ASSERT_EQ(got.size(), 1u);
    EXPECT_EQ(got[0].sequence, static_cast<std::uint64_t>(n + 1));
  }
  auto none = line->wait(0);
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  EXPECT_EQ(line->stats().events_read, 100u);
  EXPECT_EQ(line->stats().full_reads, 0u);
  EXPECT_EQ(line->stats().edges_dropped, 0u);
}

// The reader, prompt for 300 edges, is late by `stall` periods (1 kHz, 30 us jitter): the kernel
// keeps 16 edges and drops the rest; every edge read afterwards carries its own number, and the
// dropped ones are counted, for stalls just past the queue up to 1000 periods (which needs the
// period to 0.05 %: the 15 intervals of the full queue alone give it to a few percent), and for
// exactly 16 (none dropped).
TEST(GpiodLine, EdgesDroppedFromAFullQueueAreCounted) {
  for (const std::int64_t stall : {16, 17, 20, 40, 100, 1000}) {
    SCOPED_TRACE("stall of " + std::to_string(stall) + " periods");
    V1EventQueue kernel;
    auto line = GpiodDataReadyLine::over(std::make_unique<V1EventSource>(kernel), "fake:3");
    EdgeTrain train(1'000'000, 50'000, 30'000, static_cast<std::uint64_t>(stall));
    std::int64_t n = 0;
    for (; n < 300; ++n) {
      kernel.edge(train.stamp(n));
      ASSERT_EQ(drain(*line).size(), 1u);
    }
    for (std::int64_t i = 0; i < stall; ++i, ++n) kernel.edge(train.stamp(n));
    const auto backlog = drain(*line);
    ASSERT_EQ(backlog.size(), std::min<std::size_t>(kGpioV1EventQueueDepth, static_cast<std::size_t>(stall)));
    for (std::size_t i = 0; i < backlog.size(); ++i) EXPECT_EQ(backlog[i].sequence, 301 + i);
    const std::uint64_t dropped = kernel.dropped;
    EXPECT_EQ(dropped, static_cast<std::uint64_t>(std::max<std::int64_t>(0, stall - 16)));
    for (std::int64_t end = n + 30; n < end; ++n) {
      kernel.edge(train.stamp(n));
      const auto got = drain(*line);
      ASSERT_EQ(got.size(), 1u);
      EXPECT_EQ(got[0].sequence, static_cast<std::uint64_t>(n + 1)) << "edge " << n;
    }
    EXPECT_EQ(line->stats().full_reads, 1u);
    EXPECT_EQ(line->stats().edges_dropped, dropped);
  }
}

// Two full reads in a row (the reader stays late), then prompt again: the gap after each full
// read is counted; a second backlog read as several partial reads counts nothing extra.
TEST(GpiodLine, BacklogsInARowAreCountedEach) {
  V1EventQueue kernel;
  auto line = GpiodDataReadyLine::over(std::make_unique<V1EventSource>(kernel), "fake:3");
  EdgeTrain train(5'000'000, 300'000, 30'000, 7);
  std::int64_t n = 0;
  auto make = [&](std::int64_t count) {
    for (std::int64_t i = 0; i < count; ++i, ++n) kernel.edge(train.stamp(n));
  };
  make(10);
  drain(*line);
  make(30);  // 16 kept, 14 dropped
  ASSERT_EQ(drain(*line).size(), 16u);
  make(25);  // 16 kept, 9 dropped
  auto second = drain(*line);
  ASSERT_EQ(second.size(), 16u);
  EXPECT_EQ(second.front().sequence, 41u);  // the first edge after the first stall's drops
  EXPECT_EQ(second.back().sequence, 56u);
  for (int i = 0; i < 3; ++i) {
    make(5);
    auto got = drain(*line);
    ASSERT_EQ(got.size(), 5u);
    EXPECT_EQ(got.back().sequence, static_cast<std::uint64_t>(n));
  }
  EXPECT_EQ(kernel.dropped, 23u);
  EXPECT_EQ(line->stats().edges_dropped, 23u);
  EXPECT_EQ(line->stats().full_reads, 2u);
}

// The line over the fake kernel feeding the timestamper as ImuAcquisition::service() does: at
// each read all pending edges are taken, the newest goes with the FIFO read, sequence gaps are
// missed data-ready edges (the MPU-6000 driver's rule). The chip samples at 200 Hz, edges are
// stamped 300 us late with 30 us jitter, the reader reads half a period after a sample and
// sometimes only every second sample; after 2 s it is late by 40 periods (24 edges dropped).
// With the gate loose (edge_jitter_ns 1.2 ms, as the QEMU test sets it from a skewed latency)
// and tight (30 us), every sample time stays within 100 us of the truth, nothing is counted
// lost, no gap flagged, and the 24 dropped edges are counted as missed.
TEST(GpiodLine, StallPastTheQueueKeepsSampleTimes) {
  for (const TimeNs jitter_option : {TimeNs{1'200'000}, TimeNs{30'000}}) {
    SCOPED_TRACE("edge_jitter_ns " + std::to_string(jitter_option));
    constexpr TimeNs kPeriod = 5'000'000;
    constexpr TimeNs kLatency = 300'000;
    V1EventQueue kernel;
    auto line = GpiodDataReadyLine::over(std::make_unique<V1EventSource>(kernel), "fake:3");
    EdgeTrain train(kPeriod, kLatency, 30'000, 3);
    acq::TimestamperOptions options;
    options.nominal_rate_hz = 200.0;
    options.edge_latency_ns = kLatency;
    options.edge_jitter_ns = jitter_option;
    acq::SampleTimestamper timestamper(options);
    std::mt19937_64 rng(11);

    std::int64_t made = 0;       // edges made (= samples taken)
    std::int64_t fifo_next = 0;  // oldest sample not yet read from the FIFO
    std::uint64_t last_seq = 0, missed = 0, expected_dropped = 0;
    double max_error = 0;
    std::uint32_t flags_seen = 0;
    for (std::int64_t s = 0; s < 1200;) {
      const std::int64_t step = (rng() % 3 == 0) ? 2 : 1;  // read after this sample
      if (s < 400 && s + step >= 400) {
        s += 40;  // the reader is late by 40 periods: 40 edges pending, 24 dropped
        expected_dropped = 24;
      } else {
        s += step;
      }
      const TimeNs read_t = train.sample_t(s - 1) + kPeriod / 2;
      for (; made < s; ++made) kernel.edge(train.stamp(made));
      const auto edges = drain(*line);
      ASSERT_FALSE(edges.empty());
      for (const DataReadyEdge& e : edges) {
        if (last_seq != 0 && e.sequence > last_seq + 1) missed += e.sequence - last_seq - 1;
        last_seq = e.sequence;
      }
      acq::FifoBatchTiming b;
      b.edge_t_ns = edges.back().t_ns;
      b.read_t_ns = read_t;
      b.edge_sequence = edges.back().sequence;
      b.has_edge_sequence = true;
      b.sample_count = static_cast<std::uint32_t>(s - fifo_next);
      std::vector<TimeNs> t(b.sample_count);
      std::vector<std::uint32_t> flags(b.sample_count);
      ASSERT_TRUE(timestamper.process(b, t, flags).ok());
      for (std::size_t i = 0; i < t.size(); ++i) {
        const std::int64_t index = fifo_next + static_cast<std::int64_t>(i);
        if (index >= 100) {
          max_error = std::max(max_error, std::abs(static_cast<double>(t[i] - train.sample_t(index))));
        }
        flags_seen |= flags[i];
      }
      fifo_next = s;
    }
    const acq::TimestamperStats& st = timestamper.stats();
    std::printf(
        "  edge_jitter_ns %lld: max |error| %.1f us, dropped %llu, missed %llu, rejected %llu, gaps %llu, "
        "lost %llu\n",
        static_cast<long long>(jitter_option), max_error / 1e3,
        static_cast<unsigned long long>(kernel.dropped), static_cast<unsigned long long>(missed),
        static_cast<unsigned long long>(st.edges_rejected), static_cast<unsigned long long>(st.gaps),
        static_cast<unsigned long long>(st.samples_lost));
    EXPECT_EQ(kernel.dropped, expected_dropped);
    EXPECT_EQ(missed, kernel.dropped);
    EXPECT_EQ(line->stats().edges_dropped, kernel.dropped);
    EXPECT_LT(max_error, 100'000.0);
    EXPECT_EQ(st.samples_lost, 0u);
    EXPECT_EQ(st.gaps, 0u);
    EXPECT_EQ(st.reanchors, 0u);
    EXPECT_EQ(flags_seen & kImuFlagGapBefore, 0u);
  }
}

}  // namespace
}  // namespace imucal::drivers
