#include "drivers/gpio/gpiod_line.hpp"

#include <gpiod.h>
#include <sys/utsname.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <ctime>

namespace imucal::drivers {
namespace {

constexpr TimeNs kFutureToleranceNs = 1'000'000;        // 1 ms
constexpr TimeNs kMaxEventAgeNs = 3600 * kNsPerSecond;  // 1 h

TimeNs realtime_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

bool parse_uint(std::string_view s, unsigned& out) {
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && p == s.data() + s.size();
}

std::string chip_hint() {
  return "Check that `gpiodetect` lists the chip, that this user may open /dev/gpiochip* (usually the "
         "group gpio), and the rig configuration keys imu.data_ready.chip and imu.data_ready.line.";
}

}  // namespace

GpioEventClock gpio_event_clock_for_kernel(std::string_view release) {
  unsigned major = 0, minor = 0;
  const char* begin = release.data();
  const char* end = begin + release.size();
  auto r1 = std::from_chars(begin, end, major);
  if (r1.ec != std::errc() || r1.ptr == end || *r1.ptr != '.') return GpioEventClock::kMonotonic;
  auto r2 = std::from_chars(r1.ptr + 1, end, minor);
  if (r2.ec != std::errc()) return GpioEventClock::kMonotonic;
  if (major < 5 || (major == 5 && minor < 7)) return GpioEventClock::kRealtime;
  return GpioEventClock::kMonotonic;
}

Result<TimeNs> gpio_event_to_monotonic(TimeNs event_ns, GpioEventClock clock, TimeNs mono_now_ns,
                                       TimeNs real_now_ns) {
  const TimeNs t_ns = clock == GpioEventClock::kMonotonic ? event_ns : event_ns - (real_now_ns - mono_now_ns);
  if (t_ns > mono_now_ns + kFutureToleranceNs || t_ns < mono_now_ns - kMaxEventAgeNs) {
    return make_error(Errc::kDevice,
                      "GPIO event timestamp " + std::to_string(event_ns) + " ns is not on " +
                          (clock == GpioEventClock::kMonotonic ? "CLOCK_MONOTONIC" : "CLOCK_REALTIME") +
                          " as expected for this kernel (CLOCK_MONOTONIC now " + std::to_string(mono_now_ns) +
                          " ns); data-ready timestamps cannot be trusted on this kernel");
  }
  return t_ns;
}

Result<std::unique_ptr<GpiodDataReadyLine>> GpiodDataReadyLine::open(const GpiodLineOptions& options) {
  if (options.chip.empty() || options.line.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "data-ready GPIO not configured: set imu.data_ready.chip (e.g. gpiochip0) and "
                      "imu.data_ready.line (offset or name) in the rig configuration");
  }
  gpiod_chip* chip = gpiod_chip_open_lookup(options.chip.c_str());
  if (chip == nullptr) {
    const int err = errno;
    const Errc code = (err == EACCES || err == EPERM) ? Errc::kIo : Errc::kNotFound;
    return make_error(
        code, "cannot open GPIO chip '" + options.chip + "': " + std::strerror(err) + ". " + chip_hint());
  }
  const std::string chip_name = gpiod_chip_name(chip);

  gpiod_line* line = nullptr;
  unsigned offset = 0;
  if (parse_uint(options.line, offset)) {
    const unsigned n = gpiod_chip_num_lines(chip);
    if (offset >= n) {
      gpiod_chip_close(chip);
      return make_error(Errc::kNotFound, "GPIO line " + options.line + " does not exist on " + chip_name +
                                             " (it has " + std::to_string(n) + " lines, 0.." +
                                             std::to_string(n == 0 ? 0 : n - 1) + "). " + chip_hint());
    }
    line = gpiod_chip_get_line(chip, offset);
  } else {
    line = gpiod_chip_find_line(chip, options.line.c_str());
  }
  if (line == nullptr) {
    const int err = errno;
    gpiod_chip_close(chip);
    return make_error(Errc::kNotFound, "GPIO line '" + options.line + "' not found on " + chip_name + ": " +
                                           std::strerror(err) + ". " + chip_hint());
  }
  offset = gpiod_line_offset(line);
  if (gpiod_line_request_rising_edge_events(line, options.consumer.c_str()) != 0) {
    const int err = errno;
    std::string msg = "cannot request rising-edge events on " + chip_name + " line " +
                      std::to_string(offset) + ": " + std::strerror(err);
    if (err == EBUSY && gpiod_line_update(line) == 0 && gpiod_line_consumer(line) != nullptr) {
      msg += std::string(" (held by '") + gpiod_line_consumer(line) + "'; stop it first)";
    }
    gpiod_chip_close(chip);
    return make_error(Errc::kDevice, msg);
  }
  utsname uts{};
  const GpioEventClock clock =
      uname(&uts) == 0 ? gpio_event_clock_for_kernel(uts.release) : GpioEventClock::kMonotonic;
  return std::unique_ptr<GpiodDataReadyLine>(
      new GpiodDataReadyLine(chip, line, chip_name + ":" + std::to_string(offset), clock));
}

GpiodDataReadyLine::GpiodDataReadyLine(gpiod_chip* chip, gpiod_line* line, std::string name,
                                       GpioEventClock clock)
    : chip_(chip), line_(line), name_(std::move(name)), clock_(clock) {}

GpiodDataReadyLine::~GpiodDataReadyLine() {
  gpiod_line_release(line_);
  gpiod_chip_close(chip_);
}

int GpiodDataReadyLine::fd() const { return gpiod_line_event_get_fd(line_); }

Result<std::optional<DataReadyEdge>> GpiodDataReadyLine::wait(TimeNs timeout_ns) {
  if (timeout_ns < 0) {
    return make_error(Errc::kInvalidArgument,
                      name_ + ": negative wait timeout " + std::to_string(timeout_ns));
  }
  timespec timeout{};
  timeout.tv_sec = static_cast<time_t>(timeout_ns / kNsPerSecond);
  timeout.tv_nsec = static_cast<long>(timeout_ns % kNsPerSecond);
  const int r = gpiod_line_event_wait(line_, &timeout);
  if (r < 0)
    return make_error(Errc::kIo, name_ + ": waiting for a data-ready edge failed: " + std::strerror(errno));
  if (r == 0) return std::optional<DataReadyEdge>{};

  gpiod_line_event event{};
  if (gpiod_line_event_read(line_, &event) != 0) {
    return make_error(Errc::kIo, name_ + ": reading a data-ready edge failed: " + std::strerror(errno));
  }
  const TimeNs mono_now_ns = monotonic_now_ns();
  const TimeNs real_now_ns = clock_ == GpioEventClock::kRealtime ? realtime_now_ns() : 0;
  const TimeNs event_ns = static_cast<TimeNs>(event.ts.tv_sec) * kNsPerSecond + event.ts.tv_nsec;
  auto t_ns = gpio_event_to_monotonic(event_ns, clock_, mono_now_ns, real_now_ns);
  if (!t_ns.ok()) return t_ns.error().context(name_);
  DataReadyEdge edge;
  edge.t_ns = *t_ns;
  edge.sequence = ++edges_;
  return std::optional<DataReadyEdge>{edge};
}

}  // namespace imucal::drivers
