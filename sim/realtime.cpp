#include "sim/realtime.hpp"

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>

#include "sim/rig.hpp"

namespace imucal::sim {

namespace mpu = drivers::mpu6000;

Result<std::unique_ptr<RealtimeDataReadyLine>> RealtimeDataReadyLine::create(fake::DataReadyTiming timing) {
  const int fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK | EFD_SEMAPHORE);
  if (fd < 0) {
    return make_error(Errc::kIo,
                      std::string("simulated data-ready line: eventfd failed: ") + std::strerror(errno));
  }
  return std::unique_ptr<RealtimeDataReadyLine>(new RealtimeDataReadyLine(fd, timing));
}

RealtimeDataReadyLine::RealtimeDataReadyLine(int fd, fake::DataReadyTiming timing)
    : fd_(fd), timing_(timing), rng_(timing.seed) {}

RealtimeDataReadyLine::~RealtimeDataReadyLine() { ::close(fd_); }

void RealtimeDataReadyLine::raise(TimeNs true_t_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++sequence_;
  const double jitter = timing_.sigma_ns > 0 ? normal_(rng_) * static_cast<double>(timing_.sigma_ns) : 0.0;
  const TimeNs latency = std::max<TimeNs>(0, timing_.latency_ns + static_cast<TimeNs>(std::llround(jitter)));
  TimeNs t_ns = true_t_ns + latency;
  // The kernel timestamps events in the order it services them.
  if (t_ns <= last_edge_t_ns_) t_ns = last_edge_t_ns_ + 1;
  last_edge_t_ns_ = t_ns;
  scheduled_.push_back({t_ns, sequence_});
}

TimeNs RealtimeDataReadyLine::release(TimeNs now_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t n = 0;
  while (!scheduled_.empty() && scheduled_.front().t_ns <= now_ns) {
    ready_.push_back(scheduled_.front());
    scheduled_.pop_front();
    ++n;
  }
  if (n > 0) {
    // Cannot fail: the count stays far below the eventfd's limit.
    const ssize_t written = ::write(fd_, &n, sizeof n);
    (void)written;
  }
  return scheduled_.empty() ? fake::SimTimeSource::kNever : scheduled_.front().t_ns;
}

Result<std::optional<drivers::DataReadyEdge>> RealtimeDataReadyLine::wait(TimeNs timeout_ns) {
  if (timeout_ns < 0) return make_error(Errc::kInvalidArgument, name() + ": negative wait timeout");
  if (timeout_ns > 0) {
    pollfd p{fd_, POLLIN, 0};
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(timeout_ns / kNsPerSecond);
    ts.tv_nsec = static_cast<long>(timeout_ns % kNsPerSecond);
    if (::ppoll(&p, 1, &ts, nullptr) < 0 && errno != EINTR) {
      return make_error(Errc::kIo, name() + ": waiting for an edge failed: " + std::strerror(errno));
    }
  }
  if (catch_up_) {
    catch_up_();
    release(monotonic_now_ns());
  }
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t one = 0;
  if (::read(fd_, &one, sizeof one) < 0) {
    if (errno == EAGAIN) return std::optional<drivers::DataReadyEdge>();
    return make_error(Errc::kIo, name() + ": reading an edge failed: " + std::strerror(errno));
  }
  if (ready_.empty()) return make_error(Errc::kInternal, name() + ": eventfd count and edge queue disagree");
  const drivers::DataReadyEdge edge = ready_.front();
  ready_.pop_front();
  return std::optional<drivers::DataReadyEdge>(edge);
}

std::uint64_t RealtimeDataReadyLine::raised() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return sequence_;
}

/// The emulator as the driver's bus: each transfer first brings the chip to CLOCK_MONOTONIC.
class RealtimeSimRig::Bus final : public drivers::RegisterBus {
 public:
  explicit Bus(RealtimeSimRig& rig) : rig_(rig) {}

  Status read(std::uint8_t reg, std::span<std::uint8_t> out) override {
    std::lock_guard<std::mutex> lock(rig_.mutex_);
    rig_.emulator_.advance_to(monotonic_now_ns());
    return rig_.emulator_.read(reg, out);
  }
  Status write(std::uint8_t reg, std::uint8_t value) override {
    std::lock_guard<std::mutex> lock(rig_.mutex_);
    rig_.emulator_.advance_to(monotonic_now_ns());
    return rig_.emulator_.write(reg, value);
  }
  void set_speed_hz(std::uint32_t hz) override {
    std::lock_guard<std::mutex> lock(rig_.mutex_);
    rig_.emulator_.set_speed_hz(hz);
  }
  std::string name() const override { return rig_.emulator_.name(); }
  // Changed only by transfers, which come from the thread that asks.
  const drivers::BusCounters& counters() const override { return rig_.emulator_.counters(); }

 private:
  RealtimeSimRig& rig_;
};

namespace {

fake::EmulatorOptions emulator_options(const RealtimeSimRigOptions& o) {
  fake::EmulatorOptions eo;
  eo.bus = o.settings.bus;
  eo.timing = o.settings.bus == mpu::BusKind::kSpi ? fake::BusTiming::spi() : fake::BusTiming::i2c();
  eo.timing.enabled = false;  // transfers take real time instead
  eo.clock_ppm = o.clock_ppm;
  eo.start_ns = o.start_ns;
  eo.record_truth = o.record_truth;
  return eo;
}

}  // namespace

RealtimeSimRig::RealtimeSimRig(fake::SensorSource source, const RealtimeSimRigOptions& options,
                               std::unique_ptr<RealtimeDataReadyLine> line)
    : options_(options), emulator_(std::move(source), emulator_options(options)), line_(std::move(line)) {
  if (line_) {
    emulator_.set_interrupt_sink([line = line_.get()](TimeNs t_ns) { line->raise(t_ns); });
    line_->set_catch_up([this] {
      std::lock_guard<std::mutex> lock(mutex_);
      emulator_.advance_to(monotonic_now_ns());
    });
  }
  bus_ = std::make_unique<Bus>(*this);
  driver_ = std::make_unique<mpu::Mpu6000>(*bus_, options.settings);
  acq::AcquisitionOptions ao = options.acquisition;
  ao.timestamps.edge_latency_ns =
      clipped_latency_mean_ns(options.data_ready.latency_ns, options.data_ready.sigma_ns);
  ao.timestamps.edge_jitter_ns = std::max<TimeNs>(1, options.data_ready.sigma_ns);
  acquisition_ = std::make_unique<acq::ImuAcquisition>(*driver_, line_.get(), clock_, options.mounting, ao);
}

Result<std::unique_ptr<RealtimeSimRig>> RealtimeSimRig::create(fake::SensorSource source,
                                                               const RealtimeSimRigOptions& options) {
  if (auto valid = options.settings.validate(); !valid.ok())
    return valid.error().context("simulated MPU-6000 settings");
  if (options.tick_ns <= 0)
    return make_error(Errc::kInvalidArgument, "real-time simulated rig: tick_ns must be > 0");
  RealtimeSimRigOptions o = options;
  if (o.start_ns == 0) o.start_ns = monotonic_now_ns();
  std::unique_ptr<RealtimeDataReadyLine> line;
  if (o.with_line) {
    auto created = RealtimeDataReadyLine::create(o.data_ready);
    if (!created.ok()) return created.error();
    line = std::move(created).value();
  }
  std::unique_ptr<RealtimeSimRig> rig(new RealtimeSimRig(std::move(source), o, std::move(line)));
  if (auto st = rig->driver_->probe(); !st.ok()) return st.error().context("simulated MPU-6000");
  rig->ticker_ = std::thread([r = rig.get()] { r->tick_loop(); });
  return rig;
}

RealtimeSimRig::~RealtimeSimRig() { stop_ticker(); }

void RealtimeSimRig::stop_ticker() {
  stop_.store(true, std::memory_order_release);
  if (ticker_.joinable()) ticker_.join();
}

void RealtimeSimRig::tick_loop() {
  while (!stop_.load(std::memory_order_acquire)) {
    const TimeNs now_ns = monotonic_now_ns();
    TimeNs next_sample_ns = fake::SimTimeSource::kNever;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      emulator_.advance_to(now_ns);
      next_sample_ns = emulator_.next_event_ns();
    }
    const TimeNs next_edge_ns = line_ ? line_->release(now_ns) : fake::SimTimeSource::kNever;
    // Samples are taken, and their edges made readable, when they are due, not a tick later.
    const TimeNs wake_ns = std::min({now_ns + options_.tick_ns, next_sample_ns, next_edge_ns});
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(wake_ns / kNsPerSecond);
    ts.tv_nsec = static_cast<long>(wake_ns % kNsPerSecond);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
  }
}

}  // namespace imucal::sim
