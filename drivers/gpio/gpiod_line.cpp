// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/gpio/gpiod_line.hpp"

#include <gpiod.h>
#include <sys/utsname.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <ctime>
#include <vector>

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

// The kernel's event queue of a requested line, through libgpiod 1.6.
class LibgpiodEventSource final : public GpioEventSource {
 public:
  LibgpiodEventSource(gpiod_chip* chip, gpiod_line* line) : chip_(chip), line_(line) {}
  ~LibgpiodEventSource() override {
    gpiod_line_release(line_);
    gpiod_chip_close(chip_);
  }
  LibgpiodEventSource(const LibgpiodEventSource&) = delete;
  LibgpiodEventSource& operator=(const LibgpiodEventSource&) = delete;

  int wait(TimeNs timeout_ns) override {
    timespec timeout{};
    timeout.tv_sec = static_cast<time_t>(timeout_ns / kNsPerSecond);
    timeout.tv_nsec = static_cast<long>(timeout_ns % kNsPerSecond);
    return gpiod_line_event_wait(line_, &timeout);
  }
  int read(std::span<TimeNs> stamps) override {
    std::array<gpiod_line_event, kGpioV1EventQueueDepth> events{};
    const auto n = static_cast<unsigned>(std::min(stamps.size(), events.size()));
    const int r = gpiod_line_event_read_multiple(line_, events.data(), n);
    for (int i = 0; i < r; ++i) {
      const timespec& ts = events[static_cast<std::size_t>(i)].ts;
      stamps[static_cast<std::size_t>(i)] = static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
    }
    return r;
  }
  int fd() const override { return gpiod_line_event_get_fd(line_); }

 private:
  gpiod_chip* chip_;
  gpiod_line* line_;
};

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
  return over(std::make_unique<LibgpiodEventSource>(chip, line), chip_name + ":" + std::to_string(offset),
              clock);
}

std::unique_ptr<GpiodDataReadyLine> GpiodDataReadyLine::over(std::unique_ptr<GpioEventSource> source,
                                                             std::string name, GpioEventClock clock) {
  return std::unique_ptr<GpiodDataReadyLine>(
      new GpiodDataReadyLine(std::move(source), std::move(name), clock));
}

GpiodDataReadyLine::GpiodDataReadyLine(std::unique_ptr<GpioEventSource> source, std::string name,
                                       GpioEventClock clock)
    : source_(std::move(source)), name_(std::move(name)), clock_(clock) {}

GpiodDataReadyLine::~GpiodDataReadyLine() = default;

int GpiodDataReadyLine::fd() const { return source_->fd(); }

Result<std::optional<DataReadyEdge>> GpiodDataReadyLine::wait(TimeNs timeout_ns) {
  if (timeout_ns < 0) {
    return make_error(Errc::kInvalidArgument,
                      name_ + ": negative wait timeout " + std::to_string(timeout_ns));
  }
  if (pending_.empty()) {
    const int r = source_->wait(timeout_ns);
    if (r < 0)
      return make_error(Errc::kIo, name_ + ": waiting for a data-ready edge failed: " + std::strerror(errno));
    if (r == 0) return std::optional<DataReadyEdge>{};
    IMUCAL_TRY(read_events());
    if (pending_.empty()) return std::optional<DataReadyEdge>{};
  }
  const DataReadyEdge edge = pending_.front();
  pending_.pop_front();
  return std::optional<DataReadyEdge>{edge};
}

Status GpiodDataReadyLine::read_events() {
  std::array<TimeNs, kGpioV1EventQueueDepth> raw{};
  const int n = source_->read(raw);
  if (n < 0) {
    return make_error(Errc::kIo, name_ + ": reading data-ready edges failed: " + std::strerror(errno));
  }
  const auto count = static_cast<std::size_t>(n);
  stats_.events_read += count;
  const TimeNs mono_now_ns = monotonic_now_ns();
  const TimeNs real_now_ns = clock_ == GpioEventClock::kRealtime ? realtime_now_ns() : 0;
  std::array<TimeNs, kGpioV1EventQueueDepth> t{};
  for (std::size_t i = 0; i < count; ++i) {
    auto t_ns = gpio_event_to_monotonic(raw[i], clock_, mono_now_ns, real_now_ns);
    if (!t_ns.ok()) {
      // The events are gone from the kernel: counted as edges (a gap in the sequence), their
      // stamps are not used.
      edges_ += count;
      have_last_ = false;
      intervals_.clear();
      drop_period_ns_ = 0.0;
      return t_ns.error().context(name_);
    }
    t[i] = *t_ns;
  }
  for (std::size_t i = 0; i < count; ++i) pending_.push_back({t[i], number(t[i])});
  if (count == kGpioV1EventQueueDepth) {
    // The queue was full: the kernel may have dropped edges after its last event.
    ++stats_.full_reads;
    drop_period_ns_ = period_estimate(std::span<const TimeNs>(t.data(), count));
  }
  return {};
}

double GpiodDataReadyLine::period_estimate(std::span<const TimeNs> queued) const {
  // The median interval between the queued events (consecutive edges) is right to a few
  // percent and follows the present rate; the mean of the recent intervals near it (up to
  // kIntervalWindow, each between consecutive edges) is right to a small fraction of the jitter
  // divided by their number, which a gap of hundreds of periods needs.
  std::vector<TimeNs> q;
  for (std::size_t i = 1; i < queued.size(); ++i) q.push_back(queued[i] - queued[i - 1]);
  std::nth_element(q.begin(), q.begin() + static_cast<std::ptrdiff_t>(q.size() / 2), q.end());
  const auto median = static_cast<double>(q[q.size() / 2]);
  double sum = 0.0;
  std::size_t n = 0;
  for (const TimeNs d : intervals_) {
    const auto x = static_cast<double>(d);
    if (x >= 0.5 * median && x <= 1.5 * median) {
      sum += x;
      ++n;
    }
  }
  return n > 0 ? sum / static_cast<double>(n) : median;
}

std::uint64_t GpiodDataReadyLine::number(TimeNs t_ns) {
  if (have_last_ && drop_period_ns_ > 0.0) {
    // The first event after a full queue: the gap to the last queued one spans the dropped edges.
    const double periods = static_cast<double>(t_ns - last_t_ns_) / drop_period_ns_;
    const auto dropped = std::max<std::int64_t>(0, std::llround(periods) - 1);
    edges_ += static_cast<std::uint64_t>(dropped);
    stats_.edges_dropped += static_cast<std::uint64_t>(dropped);
  }
  if (have_last_ && drop_period_ns_ <= 0.0) {
    intervals_.push_back(t_ns - last_t_ns_);
    if (intervals_.size() > kIntervalWindow) intervals_.pop_front();
  }
  drop_period_ns_ = 0.0;
  have_last_ = true;
  last_t_ns_ = t_ns;
  return ++edges_;
}

}  // namespace imucal::drivers
