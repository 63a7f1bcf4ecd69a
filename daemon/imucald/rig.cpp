// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/imucald/rig.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <set>
#include <thread>

#include "acquisition/asio_acquisition.hpp"
#include "app/module_loader.hpp"
#include "app/rig/cameras.hpp"
#include "app/rig/rig.hpp"
#include "sim/service_rig.hpp"

namespace imucal::imucald {

namespace {

/// The preflight's self-test line when the kernel's inv-mpu6050 driver reads the chip.
constexpr const char* kNoSelfTestThroughIio =
    "self-test not available (the kernel's inv-mpu6050 driver owns the chip and has none)";

/// The chip's self-test through imucal's driver; `pause` lets the test's time pass.
SelfTest driver_self_test(drivers::mpu6000::Mpu6000& driver, const std::function<void(TimeNs)>& pause) {
  using Outcome = SelfTest::Outcome;
  // The chip's self-test runs outside streaming; the driver reconfigures and streams again after it.
  auto result = driver.self_test(pause);
  if (!result.ok()) return {Outcome::kCouldNotRun, "self-test could not run: " + result.error().message};
  return {
      result->pass() ? Outcome::kPassed : Outcome::kFailed,
      std::string(result->pass() ? "self-test passed" : "SELF-TEST FAILED") + " (" + result->summary() + ")"};
}

SelfTest not_open() {
  return {SelfTest::Outcome::kCouldNotRun, "self-test could not run: the IMU is not open"};
}

Error imu_not_open() { return make_error(Errc::kDevice, "the IMU is not open"); }

/// The rig's own hardware: the IMU through app::ImuRig (imucal's driver or the kernel's), its
/// acquisition on the event loop, the cameras through their backends, each watched on its
/// descriptor.
class HardwareRig final : public Rig {
 public:
  HardwareRig(const RigConfig& config, boost::asio::io_context& io, RigEvents events)
      : config_(config), io_(io), events_(std::move(events)) {}
  ~HardwareRig() override { close_imu(); }

  bool simulated() const override { return false; }

  Status open_imu() override {
    close_imu();
    auto rig = app::open_imu_rig(config_);
    if (!rig.ok()) return rig.error();
    rig_ = std::move(*rig);
    acquisition_ =
        std::make_unique<acq::AsioAcquisition>(io_, rig_->source(), [this](std::span<const ImuSample> s) {
          events_.samples(s);
          return !stopped_;
        });
    io_.stop();  // run() restarts the loop with the acquisition on it
    return {};
  }

  void close_imu() override {
    unwatch_cameras();
    acquisition_.reset();
    rig_.reset();
  }

  bool imu_open() const override { return rig_ != nullptr; }
  const ImuStreamInfo& stream_info() const override { return rig_ ? rig_->stream_info() : no_stream_; }

  std::string describe_imu() const override {
    if (!rig_) return "not open";
    // Through the kernel's driver, the chip's identity is the kernel's to check.
    return rig_->describe() + (rig_->iio() ? "" : ", WHO_AM_I answered");
  }

  SelfTest self_test() override {
    if (!rig_) return not_open();
    // The kernel's driver owns the chip's registers and offers no self-test.
    if (rig_->iio()) return {SelfTest::Outcome::kNotAvailable, kNoSelfTestThroughIio};
    return driver_self_test(*rig_->driver(),
                            [](TimeNs d) { std::this_thread::sleep_for(std::chrono::nanoseconds(d)); });
  }

  Result<drivers::mpu6000::OffsetRegisters> read_offsets() override {
    if (!rig_) return imu_not_open();
    return rig_->read_offsets();
  }
  Status write_offsets(const drivers::mpu6000::OffsetRegisters& regs) override {
    if (!rig_) return imu_not_open();
    return rig_->write_offsets(regs);
  }

  session_msg::PreflightReport::Device check_camera(std::size_t index) override {
    const CameraConfig& cc = config_.cameras.at(index);
    auto camera = app::open_camera(cc);
    return {cc.name,
            camera.ok(),
            camera.ok()
                ? std::string((*camera)->backend()) + " " + cc.device + " opened, " +
                      std::to_string(cc.width) + "x" + std::to_string(cc.height) + " " + cc.pixel_format
                : camera.error().message,
            {}};
  }

  Result<std::unique_ptr<drivers::camera::Camera>> open_camera(std::size_t index) override {
    return app::open_camera(config_.cameras.at(index));
  }

  Status watch_camera(std::size_t index, drivers::camera::Camera& camera) override {
    const int fd = ::dup(camera.fd());
    if (fd < 0)
      return make_error(Errc::kIo,
                        "camera " + config_.cameras.at(index).name + ": cannot wait on its descriptor");
    if (waits_.size() <= index) waits_.resize(index + 1);
    waits_[index] = std::make_unique<boost::asio::posix::stream_descriptor>(io_, fd);
    wait(index);
    return {};
  }

  void unwatch_cameras() override {
    for (auto& w : waits_) {
      if (!w) continue;
      boost::system::error_code ec;
      w->cancel(ec);
      w->close(ec);
    }
    waits_.clear();
  }

  void run() override {
    if (!acquisition_) {
      io_.run();
      return;
    }
    // Runs once: returns on stop() or on the IMU's error (then the service closes it and a redo
    // reopens it).
    const Status s = acquisition_->run();
    if (!s.ok() && !stopped_) events_.imu_failed(s.error());
  }

  void stop() override {
    stopped_ = true;
    if (acquisition_) acquisition_->stop();
  }

 private:
  void wait(std::size_t index) {
    waits_[index]->async_wait(boost::asio::posix::stream_descriptor::wait_read,
                              [this, index](const boost::system::error_code& ec) {
                                if (ec || index >= waits_.size() || !waits_[index]) return;
                                events_.camera_readable(index);
                                if (index < waits_.size() && waits_[index]) wait(index);
                              });
  }

  const RigConfig& config_;
  boost::asio::io_context& io_;
  RigEvents events_;
  std::unique_ptr<app::ImuRig> rig_;
  std::unique_ptr<acq::AsioAcquisition> acquisition_;
  std::vector<std::unique_ptr<boost::asio::posix::stream_descriptor>> waits_;  // by camera index
  bool stopped_ = false;
  ImuStreamInfo no_stream_;
};

/// The virtual rig of libimucal_virtual_rig.so: the register emulator behind the real driver,
/// ticked on a timer at the configured pace; its cameras render as its clock advances.
class VirtualRig final : public Rig {
 public:
  VirtualRig(const RigConfig& config, const ServiceOptions& options, boost::asio::io_context& io,
             RigEvents events)
      : config_(config), options_(options), io_(io), timer_(io), events_(std::move(events)) {}
  ~VirtualRig() override { close_imu(); }

  bool simulated() const override { return true; }

  Status open_imu() override {
    close_imu();
    auto rig = create();
    if (!rig.ok()) return rig.error();
    rig_ = std::move(*rig);
    boost::asio::post(io_, [this] { tick(); });
    return {};
  }

  void close_imu() override {
    unwatch_cameras();
    timer_.cancel();
    rig_.reset();
  }

  bool imu_open() const override { return rig_ != nullptr; }
  const ImuStreamInfo& stream_info() const override { return rig_ ? rig_->stream_info() : no_stream_; }
  std::string describe_imu() const override {
    return "virtual MPU-6000 (register emulator), WHO_AM_I answered";
  }

  SelfTest self_test() override {
    if (!rig_) return not_open();
    return driver_self_test(rig_->driver(), [this](TimeNs d) { rig_->stall(d); });
  }

  Result<drivers::mpu6000::OffsetRegisters> read_offsets() override {
    if (!rig_) return imu_not_open();
    return rig_->driver().read_offsets();
  }
  Status write_offsets(const drivers::mpu6000::OffsetRegisters& regs) override {
    if (!rig_) return imu_not_open();
    return rig_->driver().write_offsets(regs);
  }

  session_msg::PreflightReport::Device check_camera(std::size_t index) override {
    const CameraConfig& cc = config_.cameras.at(index);
    return {cc.name,
            rig_ && rig_->cameras_ready(),
            "virtual camera " + std::to_string(cc.width) + "x" + std::to_string(cc.height) + " at " +
                std::to_string(static_cast<int>(cc.rate_hz)) + " Hz, rendering the target",
            {}};
  }

  Result<std::unique_ptr<drivers::camera::Camera>> open_camera(std::size_t index) override {
    if (!rig_) return imu_not_open();
    // --sim-unplug-camera: the cameras of the first motion step vanish after that many frames.
    const bool first = opened_.insert(index).second;
    return rig_->open_camera(index, first ? options_.sim_unplug_camera_after : 0);
  }

  Status watch_camera(std::size_t index, drivers::camera::Camera& /*camera*/) override {
    watched_.insert(index);
    return {};
  }
  void unwatch_cameras() override { watched_.clear(); }

  void run() override { io_.run(); }
  void stop() override {
    stopped_ = true;
    timer_.cancel();
  }

  void session_starting() override {
    if (rig_ && options_.sim_unplug_imu_after_s > 0.0 && !imu_unplug_armed_) {
      rig_->unplug_imu_after(options_.sim_unplug_imu_after_s);
      imu_unplug_armed_ = true;  // once
    }
  }
  void on_message(const session_msg::SessionMessage& message) override {
    if (rig_) rig_->on_message(message);
  }
  bool operator_presses_keys() const override { return rig_ && rig_->operator_presses_keys(); }
  std::string truth_report(const session_msg::ResultSummary& result) const override {
    return rig_ && result.imu ? rig_->truth_report(result) : std::string();
  }
  std::optional<std::vector<Eigen::Vector2d>> truth_corners(std::size_t index, TimeNs t_ns) const override {
    if (!rig_) return std::nullopt;
    return rig_->truth_corners(index, t_ns);
  }

 private:
  Result<std::unique_ptr<sim::ServiceRig>> create() {
    auto module =
        app::load_module<sim::VirtualRigModuleApi>(sim::kVirtualRigModule, sim::kVirtualRigModuleEntry);
    if (!module.ok()) return module.error().context("the virtual rig");
    auto settings = app::driver_settings(config_.imu);
    if (!settings.ok()) return settings.error();
    auto mounting = app::imu_mounting(config_.imu);
    if (!mounting.ok()) return mounting.error();
    sim::ServiceRigOptions so;
    so.settings = *settings;
    so.mounting = *mounting;
    so.cameras = config_.cameras;
    so.target = config_.target;
    so.motion_s = config_.session.motion_s;
    so.seed = options_.seed;
    so.cold_start_c = options_.sim_cold_start_c;
    so.time_scale = options_.time_scale;
    so.operator_mode = options_.sim_operator;
    so.press_key = [this](session_msg::OperatorKey k) { events_.press_key(k); };
    return (*module)->create(so);
  }

  void tick() {
    if (!rig_ || stopped_) return;
    auto done =
        rig_->tick(events_.worker_busy(), [this](std::span<const ImuSample> b) { events_.samples(b); });
    if (!done.ok()) {
      events_.imu_failed(done.error());
      return;
    }
    if (done->advanced) {
      // The cameras rendered up to the rig's new time: a copy, as reading may end the watch.
      const std::set<std::size_t> watched = watched_;
      for (const std::size_t i : watched) {
        if (watched_.count(i)) events_.camera_readable(i);
      }
    }
    if (!done->pace_notice.empty()) events_.notice(done->pace_notice);
    if (!rig_) return;  // closed by what was handed on
    if (!done->next) {
      boost::asio::post(io_, [this] { tick(); });
      return;
    }
    timer_.expires_at(*done->next);
    timer_.async_wait([this](const boost::system::error_code& ec) {
      if (!ec) tick();
    });
  }

  const RigConfig& config_;
  const ServiceOptions& options_;
  boost::asio::io_context& io_;
  boost::asio::steady_timer timer_;
  RigEvents events_;
  std::unique_ptr<sim::ServiceRig> rig_;
  std::set<std::size_t> opened_, watched_;
  bool imu_unplug_armed_ = false;
  bool stopped_ = false;
  ImuStreamInfo no_stream_;
};

}  // namespace

std::unique_ptr<Rig> make_rig(const RigConfig& config, const ServiceOptions& options,
                              boost::asio::io_context& io, RigEvents events) {
  if (options.sim) return std::make_unique<VirtualRig>(config, options, io, std::move(events));
  return std::make_unique<HardwareRig>(config, io, std::move(events));
}

}  // namespace imucal::imucald
