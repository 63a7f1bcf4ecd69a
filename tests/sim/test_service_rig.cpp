// The service's virtual rig (sim/service_rig.hpp): its clock's pace against the wall clock, the
// wait while the service's worker is busy, the injected IMU fault, its cameras on the rig's clock
// and the result beside its truth.

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "drivers/mpu6000/output_settings.hpp"
#include "sim/service_rig.hpp"

namespace imucal::sim {
namespace {

namespace mpu = drivers::mpu6000;

ServiceRigOptions options(double time_scale, bool camera) {
  mpu::OutputRequest req;
  req.rate_hz = 200.0;
  auto settings = mpu::settings_for(req);
  EXPECT_TRUE(settings.ok());
  ServiceRigOptions o;
  o.settings = *settings;
  o.time_scale = time_scale;
  o.seed = 3;
  if (camera) {
    CameraConfig cc;
    cc.name = "cam0";
    cc.width = 320;
    cc.height = 240;
    cc.rate_hz = 20.0;
    cc.pixel_format = "GREY";
    o.cameras.push_back(cc);
    TargetDescription t;
    t.cols = 6;
    t.rows = 5;
    t.col_spacing_m = t.row_spacing_m = 0.04;
    o.target = t;
  }
  return o;
}

std::unique_ptr<ServiceRig> make(const ServiceRigOptions& o) {
  auto rig = make_service_rig(o);
  EXPECT_TRUE(rig.ok()) << (rig.ok() ? "" : rig.error().message);
  return rig.ok() ? std::move(*rig) : nullptr;
}

TEST(ServiceRig, EachTickIsTwentyMillisecondsOfSamplesAndAsFastAsItComputesAtScaleZero) {
  auto rig = make(options(0.0, false));
  ASSERT_TRUE(rig);
  const TimeNs t0 = rig->now_ns();
  std::size_t samples = 0;
  for (int i = 0; i < 50; ++i) {
    const TimeNs before = rig->now_ns();
    auto tick = rig->tick(false, [&](std::span<const ImuSample> s) { samples += s.size(); });
    ASSERT_TRUE(tick.ok());
    EXPECT_TRUE(tick->advanced);
    EXPECT_FALSE(tick->next.has_value());  // at once
    EXPECT_GE(rig->now_ns() - before, 20'000'000);
  }
  // At least a second of rig time, and the samples of most of it (the chip starts up first).
  EXPECT_GE(rig->now_ns() - t0, 1'000'000'000);
  EXPECT_GT(samples, 150u);
}

TEST(ServiceRig, OnAcceleratedTimeItWaitsForTheWorkerAndTheWaitIsNoRigTime) {
  auto rig = make(options(100.0, false));
  ASSERT_TRUE(rig);
  auto none = [](std::span<const ImuSample>) {};
  ASSERT_TRUE(rig->tick(false, none).ok());
  const TimeNs before = rig->now_ns();
  for (int i = 0; i < 3; ++i) {
    auto tick = rig->tick(true, none);
    ASSERT_TRUE(tick.ok());
    EXPECT_FALSE(tick->advanced);
    ASSERT_TRUE(tick->next.has_value());
  }
  EXPECT_EQ(rig->now_ns(), before);  // no rig time while the worker runs
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  // After the wait the next tick is due 20 ms / 100 of wall time on, not in the past by the
  // 200 ms waited (which would make it catch up at full speed).
  const auto now = std::chrono::steady_clock::now();
  auto tick = rig->tick(false, none);
  ASSERT_TRUE(tick.ok());
  ASSERT_TRUE(tick->advanced);
  ASSERT_TRUE(tick->next.has_value());
  EXPECT_GT(*tick->next, now + std::chrono::microseconds(100));
  EXPECT_LT(*tick->next, now + std::chrono::milliseconds(100));
}

TEST(ServiceRig, AtRealTimeTheWorkerDoesNotStopTheClock) {
  auto rig = make(options(1.0, false));
  ASSERT_TRUE(rig);
  const TimeNs before = rig->now_ns();
  auto tick = rig->tick(true, [](std::span<const ImuSample>) {});
  ASSERT_TRUE(tick.ok());
  EXPECT_TRUE(tick->advanced);
  EXPECT_GE(rig->now_ns() - before, 20'000'000);
}

TEST(ServiceRig, AnUnpluggedImuFailsTheTickAfterItsTime) {
  auto rig = make(options(0.0, false));
  ASSERT_TRUE(rig);
  rig->unplug_imu_after(0.1);
  auto none = [](std::span<const ImuSample>) {};
  int ok_ticks = 0;
  Status failed;
  for (int i = 0; i < 500; ++i) {
    auto tick = rig->tick(false, none);
    if (!tick.ok()) {
      failed = tick.error();
      break;
    }
    ++ok_ticks;
  }
  ASSERT_FALSE(failed.ok()) << "the IMU answered 10 s after it was unplugged";
  EXPECT_GE(ok_ticks, 5);    // 0.1 s of rig time first
  EXPECT_LE(ok_ticks, 100);  // then the driver's resets, and it gives up
  EXPECT_NE(failed.error().message.find("MPU-6000"), std::string::npos) << failed.error().message;
}

TEST(ServiceRig, ItsCameraStampsOnTheRigsClockAndVanishesWhenAsked) {
  auto rig = make(options(0.0, true));
  ASSERT_TRUE(rig);
  EXPECT_TRUE(rig->cameras_ready());
  EXPECT_FALSE(rig->open_camera(1, 0).ok());  // one camera configured
  const TimeNs opened = rig->now_ns();
  auto camera = rig->open_camera(0, 3);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  ASSERT_TRUE((*camera)->start().ok());
  auto none = [](std::span<const ImuSample>) {};
  int frames = 0;
  TimeNs last = 0;
  Status gone;
  for (int i = 0; i < 30 && gone.ok(); ++i) {
    ASSERT_TRUE(rig->tick(false, none).ok());
    for (;;) {
      auto f = (*camera)->dequeue();
      if (!f.ok()) {
        gone = f.error();
        break;
      }
      if (!f->valid()) break;
      EXPECT_LE(f->t_ns, rig->now_ns());
      if (frames > 0) {
        EXPECT_EQ(f->t_ns - last, 50'000'000);  // 20 Hz on the rig's clock
      }
      last = f->t_ns;
      EXPECT_EQ(f->width, 320);
      ++frames;
      f->release();
    }
  }
  EXPECT_EQ(frames, 3);
  EXPECT_GE(last, opened + 150'000'000);  // the first frame a period after opening
  EXPECT_EQ(gone.error().code, Errc::kNotFound);
}

TEST(ServiceRig, TheTruthReportComparesAResultWithTheRigsErrors) {
  auto rig = make(options(0.0, false));
  ASSERT_TRUE(rig);
  EXPECT_EQ(rig->truth_report(nlohmann::json{{"type", "result"}}), "");
  const nlohmann::json I = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const nlohmann::json zero = {0, 0, 0};
  const nlohmann::json result = {
      {"imu", {{"A_a", I}, {"A_g", I}, {"G", {zero, zero, zero}}, {"b_a", zero}, {"b_g", zero}}}};
  const std::string text = rig->truth_report(result);
  EXPECT_NE(text.find("accel scale diag(A_a)"), std::string::npos) << text;
  EXPECT_NE(text.find("gyro bias b_g (counts)"), std::string::npos) << text;
  EXPECT_NE(text.find("largest error"), std::string::npos) << text;
}

}  // namespace
}  // namespace imucal::sim
