// SPDX-License-Identifier: BSD-3-Clause
#include "sim/realtime.hpp"

#include <algorithm>
#include <cerrno>
#include <ctime>

namespace imucal::sim {

namespace mpu = drivers::mpu6000;

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

fake::EmulatorOptions realtime_emulator_options(const RealtimeSimRigOptions& o) {
  fake::EmulatorOptions eo = emulator_options(o);
  eo.timing.enabled = false;  // transfers take real time instead
  return eo;
}

}  // namespace

RealtimeSimRig::RealtimeSimRig(fake::SensorSource source, const RealtimeSimRigOptions& options,
                               std::unique_ptr<fake::RealtimeDataReadyLine> line)
    : options_(options),
      emulator_(std::move(source), realtime_emulator_options(options)),
      line_(std::move(line)) {
  if (line_) {
    emulator_.set_interrupt_sink([line = line_.get()](TimeNs t_ns) { line->raise(t_ns); });
    line_->set_catch_up([this] {
      std::lock_guard<std::mutex> lock(mutex_);
      emulator_.advance_to(monotonic_now_ns());
    });
  }
  bus_ = std::make_unique<Bus>(*this);
  driver_ = std::make_unique<mpu::Mpu6000>(*bus_, options.settings);
  acquisition_ = std::make_unique<acq::ImuAcquisition>(*driver_, line_.get(), clock_, options.mounting,
                                                       acquisition_options(options));
}

Result<std::unique_ptr<RealtimeSimRig>> RealtimeSimRig::create(fake::SensorSource source,
                                                               const RealtimeSimRigOptions& options) {
  if (auto valid = options.settings.validate(); !valid.ok())
    return valid.error().context("simulated MPU-6000 settings");
  if (options.tick_ns <= 0)
    return make_error(Errc::kInvalidArgument, "real-time simulated rig: tick_ns must be > 0");
  RealtimeSimRigOptions o = options;
  if (o.start_ns == 0) o.start_ns = monotonic_now_ns();
  std::unique_ptr<fake::RealtimeDataReadyLine> line;
  if (o.with_line) {
    auto created = fake::RealtimeDataReadyLine::create(o.data_ready);
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
