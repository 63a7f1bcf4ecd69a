// SPDX-License-Identifier: BSD-3-Clause
// The Aravis backend against Aravis's own fakes: the in-process fake camera ("Fake_1") and a
// GigE Vision fake camera served on the loopback interface in this process, reached through the
// normal GigE Vision discovery, control and stream path.

#include <arv.h>
#include <gtest/gtest.h>
#include <poll.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "drivers/camera/aravis/aravis_camera.hpp"

namespace imucal::drivers::camera {
namespace {

AravisOptions fake_options() {
  AravisOptions o;
  o.fake_interface = true;
  return o;
}

/// Waits on fd() and dequeues until a frame, an error, or `timeout_ns` passes (then an invalid
/// frame). This is how an event loop drives a camera.
Result<Frame> wait_frame(Camera& camera, TimeNs timeout_ns) {
  const TimeNs deadline = monotonic_now_ns() + timeout_ns;
  while (true) {
    auto frame = camera.dequeue();
    if (!frame.ok() || frame->valid()) return frame;
    const TimeNs left = deadline - monotonic_now_ns();
    if (left <= 0) return Frame{};
    pollfd p{camera.fd(), POLLIN, 0};
    (void)::poll(&p, 1, static_cast<int>(left / 1'000'000) + 1);
  }
}

std::uint32_t next_block_id(std::uint32_t id) { return id >= 0xFFFF ? 1 : id + 1; }  // 16 bit, 0 skipped

TEST(AravisFake, StreamsFramesOnTheMonotonicClock) {
  auto cam = open_aravis_camera("Fake_1", fake_options());
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  AravisCamera& camera = **cam;
  EXPECT_STREQ(camera.backend(), "aravis");
  EXPECT_EQ(camera.id(), "Fake_1");
  EXPECT_FALSE(camera.is_gige());
  EXPECT_EQ(camera.timestamp_meaning(), TimestampMeaning::kStartOfExposure);
  ASSERT_GE(camera.fd(), 0);
  ASSERT_TRUE(camera.set_format({640, 480, "Mono8", 50.0}).ok());
  EXPECT_EQ(camera.format().width, 640);
  EXPECT_EQ(camera.format().height, 480);
  EXPECT_EQ(camera.format().pixel_format, "Mono8");
  EXPECT_NEAR(camera.format().rate_hz, 50.0, 1e-6);
  ASSERT_TRUE(camera.start().ok());

  std::vector<TimeNs> stamps;
  std::uint32_t last_sequence = 0;
  for (int i = 0; i < 12; ++i) {
    auto frame = wait_frame(camera, 5 * kNsPerSecond);
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    ASSERT_TRUE(frame->valid()) << "no frame within 5 s (frame " << i << ")";
    const TimeNs now = monotonic_now_ns();
    EXPECT_EQ(frame->width, 640);
    EXPECT_EQ(frame->height, 480);
    EXPECT_EQ(frame->pixel_format, "Mono8");
    EXPECT_EQ(frame->stride, 640u);
    EXPECT_GE(frame->data.size(), 640u * 480u);
    EXPECT_EQ(frame->exposure_ns, 10'000'000);  // the fake's ExposureTime, 10000 us
    // On CLOCK_MONOTONIC, never after its own arrival (the envelope lies under every pair).
    EXPECT_LE(frame->t_ns, now);
    EXPECT_LT(now - frame->t_ns, kNsPerSecond);
    if (i > 0) {
      EXPECT_GT(frame->t_ns, stamps.back());
      EXPECT_EQ(frame->sequence, next_block_id(last_sequence));
    }
    stamps.push_back(frame->t_ns);
    last_sequence = frame->sequence;
  }
  const CameraCounters c = camera.counters();
  EXPECT_EQ(c.frames, 12u);
  EXPECT_EQ(c.incomplete, 0u);
  EXPECT_EQ(c.packets_lost, 0u);
  const ClockSyncState clock = camera.clock_state();
  EXPECT_TRUE(clock.valid);
  EXPECT_EQ(clock.samples, 12u);
  EXPECT_EQ(clock.resets, 0u);
  // The fake stamps with wall-clock time: the offset is CLOCK_MONOTONIC - CLOCK_REALTIME.
  timespec real{};
  clock_gettime(CLOCK_REALTIME, &real);
  const TimeNs realtime = static_cast<TimeNs>(real.tv_sec) * kNsPerSecond + real.tv_nsec;
  EXPECT_NEAR(static_cast<double>(clock.offset_ns), static_cast<double>(monotonic_now_ns() - realtime),
              0.1e9);
  std::printf("fake camera: %zu pairs, offset %lld ns, delay above envelope median %.3f ms, max %.3f ms\n",
              clock.samples, static_cast<long long>(clock.offset_ns), clock.residual_median_ns / 1e6,
              clock.residual_max_ns / 1e6);
  EXPECT_TRUE(camera.stop().ok());
  EXPECT_TRUE(camera.stop().ok());  // idempotent
}

TEST(AravisFake, RefusesWhatTheDeviceDoesNotAcceptAndSaysWhatItOffers) {
  auto cam = open_aravis_camera("Fake_1", fake_options());
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  AravisCamera& camera = **cam;
  auto formats = camera.formats();
  ASSERT_TRUE(formats.ok()) << formats.error().message;
  ASSERT_FALSE(formats->empty());
  EXPECT_TRUE(std::any_of(formats->begin(), formats->end(), [](const FrameFormat& f) {
    return f.pixel_format == "Mono8" && f.width == 2048 && f.height == 2048 && f.rate_hz == 1000.0;
  }));
  const FrameFormat before = camera.format();

  Status s = camera.set_format({640, 480, "YUV422_8", 0.0});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kUnsupported);
  EXPECT_NE(s.error().message.find("Mono8"), std::string::npos) << s.error().message;

  s = camera.set_format({4096, 480, "Mono8", 0.0});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kUnsupported);
  EXPECT_NE(s.error().message.find("widths 1 to 2048"), std::string::npos) << s.error().message;

  s = camera.set_format({640, 480, "Mono8", 5000.0});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kUnsupported);
  EXPECT_NE(s.error().message.find("1000 Hz"), std::string::npos) << s.error().message;

  // A refusal leaves the device as it was (the rate is checked once the size is set, as its
  // bounds depend on it; the size is then put back).
  EXPECT_EQ(camera.format().pixel_format, before.pixel_format);
  EXPECT_EQ(camera.format().width, before.width);
  EXPECT_EQ(camera.format().height, before.height);

  s = camera.set_features("NoSuchFeature=1");
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kInvalidArgument);
}

TEST(AravisFake, AnUnknownIdIsNotFoundAndTheMessageListsTheCameras) {
  auto cam = open_aravis_camera("NoSuchCamera-0000", fake_options());
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.error().code, Errc::kNotFound);
  EXPECT_NE(cam.error().message.find("Fake_1"), std::string::npos) << cam.error().message;
  const auto ids = list_aravis_cameras(true);
  EXPECT_NE(std::find(ids.begin(), ids.end(), "Fake_1"), ids.end());
}

TEST(AravisFake, AConsumerHoldingEveryBufferStallsTheCameraAndNothingHangs) {
  AravisOptions options = fake_options();
  options.buffers = 3;
  auto cam = open_aravis_camera("Fake_1", options);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  AravisCamera& camera = **cam;
  ASSERT_TRUE(camera.set_format({320, 240, "Mono8", 100.0}).ok());
  ASSERT_TRUE(camera.start().ok());
  std::vector<Frame> held;
  for (int i = 0; i < 3; ++i) {
    auto frame = wait_frame(camera, 5 * kNsPerSecond);
    ASSERT_TRUE(frame.ok() && frame->valid());
    held.push_back(std::move(*frame));
  }
  // No buffer left: nothing is delivered, dequeue returns at once with no frame.
  auto none = wait_frame(camera, 300'000'000);
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_FALSE(none->valid());
  const std::uint64_t dropped = camera.counters().dropped;
  EXPECT_GT(dropped, 0u) << "frames the fake could not deliver for want of a buffer";
  // One buffer back: frames flow again.
  held.front().release();
  auto frame = wait_frame(camera, 5 * kNsPerSecond);
  ASSERT_TRUE(frame.ok() && frame->valid());
  // Stop with frames still held: they stay readable and are released afterwards.
  ASSERT_TRUE(camera.stop().ok());
  EXPECT_EQ(held.back().data.size(), 320u * 240u);
  held.clear();
  frame->release();
  EXPECT_EQ(camera.counters().frames, 4u);
  // And it starts again.
  ASSERT_TRUE(camera.start().ok());
  auto again = wait_frame(camera, 5 * kNsPerSecond);
  ASSERT_TRUE(again.ok() && again->valid());
}

TEST(AravisFake, FramesAreNotHandedOutBeforeStart) {
  auto cam = open_aravis_camera("Fake_1", fake_options());
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  auto frame = (*cam)->dequeue();
  ASSERT_TRUE(frame.ok());
  EXPECT_FALSE(frame->valid());
}

/// A GigE Vision fake camera on the loopback interface, served by this process's threads.
class GvFakeCamera {
 public:
  explicit GvFakeCamera(const char* serial) : fake_(arv_gv_fake_camera_new("lo", serial)) {}
  ~GvFakeCamera() { destroy(); }
  bool running() const { return fake_ != nullptr && arv_gv_fake_camera_is_running(fake_); }
  void destroy() {
    if (fake_ != nullptr) g_object_unref(fake_);
    fake_ = nullptr;
  }

 private:
  ArvGvFakeCamera* fake_;
};

// One test for the whole GigE Vision path: the fake binds the GVCP port on the loopback
// interface, so two of them (parallel test processes) cannot coexist.
TEST(AravisGigE, StreamsOverLoopbackStallsOnSoftwareTriggerAndReportsTheLossOfTheDevice) {
  GvFakeCamera fake("IMUCALGV");
  if (!fake.running()) {
    GTEST_SKIP() << "the GigE Vision fake camera could not serve on the loopback interface 'lo' "
                    "(arv_gv_fake_camera_new(\"lo\", ...) is not running: no loopback interface, or its "
                    "GVCP port 3956 is taken by another process)";
  }
  const auto ids = list_aravis_cameras();
  const auto it = std::find_if(
      ids.begin(), ids.end(), [](const std::string& id) { return id.find("IMUCALGV") != std::string::npos; });
  if (it == ids.end()) {
    GTEST_SKIP() << "the fake GigE Vision camera serves on 'lo' but GigE Vision discovery did not find it "
                    "(discovery broadcast not answered on loopback here)";
  }
  auto cam = open_aravis_camera(*it);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  AravisCamera& camera = **cam;
  EXPECT_TRUE(camera.is_gige());
  ASSERT_TRUE(camera.set_format({256, 128, "Mono8", 50.0}).ok());
  ASSERT_TRUE(camera.start().ok());
  std::vector<TimeNs> stamps;
  for (int i = 0; i < 10; ++i) {
    auto frame = wait_frame(camera, 5 * kNsPerSecond);
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    ASSERT_TRUE(frame->valid()) << "no frame within 5 s (frame " << i << ")";
    EXPECT_EQ(frame->width, 256);
    EXPECT_EQ(frame->height, 128);
    EXPECT_EQ(frame->data.size(), 256u * 128u);
    EXPECT_LE(frame->t_ns, monotonic_now_ns());
    EXPECT_LT(monotonic_now_ns() - frame->t_ns, kNsPerSecond);
    if (!stamps.empty()) {
      EXPECT_GT(frame->t_ns, stamps.back());
    }
    stamps.push_back(frame->t_ns);
  }
  CameraCounters c = camera.counters();
  EXPECT_EQ(c.frames, 10u);
  EXPECT_EQ(c.incomplete, 0u);
  EXPECT_EQ(c.packets_lost, 0u) << "loopback loses no packets";
  const ClockSyncState clock = camera.clock_state();
  std::printf("GigE Vision fake on lo: %zu pairs, delay above envelope median %.3f ms, max %.3f ms\n",
              clock.samples, clock.residual_median_ns / 1e6, clock.residual_max_ns / 1e6);

  // Software trigger, never triggered: the camera stops delivering; dequeue returns no frame.
  ASSERT_TRUE(camera.stop().ok());
  ASSERT_TRUE(camera.set_features("TriggerSelector=FrameStart TriggerMode=On TriggerSource=Software").ok());
  ASSERT_TRUE(camera.start().ok());
  auto none = wait_frame(camera, 500'000'000);
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_FALSE(none->valid()) << "a frame without a trigger";
  ASSERT_TRUE(camera.execute("TriggerSoftware").ok());
  auto triggered = wait_frame(camera, 5 * kNsPerSecond);
  ASSERT_TRUE(triggered.ok()) << triggered.error().message;
  EXPECT_TRUE(triggered->valid()) << "no frame after TriggerSoftware";
  triggered->release();

  // The device goes away mid-stream: its heartbeat fails and dequeue reports the loss.
  fake.destroy();
  const TimeNs lost_at = monotonic_now_ns();
  Result<Frame> result = Frame{};
  while (result.ok() && monotonic_now_ns() - lost_at < 20 * kNsPerSecond) {
    result = wait_frame(camera, 500'000'000);
    if (result.ok()) {
      EXPECT_FALSE(result->valid()) << "a frame from a destroyed camera";
    }
  }
  ASSERT_FALSE(result.ok()) << "the loss of the device was not reported within 20 s";
  const double seconds = ns_to_s(monotonic_now_ns() - lost_at);
  EXPECT_EQ(result.error().code, Errc::kDevice);
  EXPECT_NE(result.error().message.find("lost"), std::string::npos) << result.error().message;
  std::printf("device loss reported after %.2f s: %s\n", seconds, result.error().message.c_str());
  // Stays reported, and stopping and closing a lost camera return.
  EXPECT_FALSE(camera.dequeue().ok());
  EXPECT_FALSE(camera.start().ok());
  const TimeNs close_from = monotonic_now_ns();
  cam->reset();
  std::printf("closing the lost camera took %.2f s\n", ns_to_s(monotonic_now_ns() - close_from));
}

}  // namespace
}  // namespace imucal::drivers::camera
