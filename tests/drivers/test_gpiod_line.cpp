// GpiodDataReadyLine: what can be checked without a GPIO chip (the Debian kernel has neither
// gpio-sim nor gpio-mockup): configuration and lookup errors, the event-clock rule and the
// timestamp conversion. Edge delivery itself is not exercised here (docs/testing-devices.md).

#include <gtest/gtest.h>

#include <filesystem>

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

}  // namespace
}  // namespace imucal::drivers
