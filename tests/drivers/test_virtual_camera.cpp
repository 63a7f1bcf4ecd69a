// SPDX-License-Identifier: BSD-3-Clause
// The virtual camera (drivers/camera/fake): frames at their times on the simulated clock and in
// real time, buffer ownership, drops when the consumer holds every buffer, and the faults it can
// play (a stall, an unplugged camera).

#include <gtest/gtest.h>
#include <poll.h>

#include <cstring>
#include <ctime>
#include <vector>

#include "drivers/camera/fake/virtual_camera.hpp"

namespace imucal::drivers::camera::fake {
namespace {

/// Fills the image with the frame's sequence number, so a test can tell frames apart.
Status fill_sequence(TimeNs, std::uint32_t k, std::span<std::uint8_t> px) {
  std::memset(px.data(), static_cast<int>(k & 0xFF), px.size());
  return {};
}

struct SimClock {
  TimeNs now = 0;
};

std::unique_ptr<VirtualCamera> make_camera(SimClock& clock, VirtualCameraOptions o = {}) {
  o.width = 16;
  o.height = 8;
  o.rate_hz = 10.0;
  o.exposure_ns = 2'000'000;
  o.first_frame_ns = 1'000'000'000;
  o.clock = [&clock] { return clock.now; };
  auto c = VirtualCamera::create(o, fill_sequence);
  EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
  return c.ok() ? std::move(*c) : nullptr;
}

TEST(VirtualCamera, FramesAppearAtTheEndOfTheirExposureStampedAtMidExposure) {
  SimClock clock;
  auto cam = make_camera(clock);
  ASSERT_TRUE(cam);
  ASSERT_TRUE(cam->start().ok());
  clock.now = 1'000'999'999;  // frame 0 ends its exposure at 1.001 s
  auto f = cam->dequeue();
  ASSERT_TRUE(f.ok());
  EXPECT_FALSE(f->valid());
  clock.now = 1'001'000'000;
  f = cam->dequeue();
  ASSERT_TRUE(f.ok() && f->valid());
  EXPECT_EQ(f->t_ns, 1'000'000'000);
  EXPECT_EQ(f->sequence, 0u);
  EXPECT_EQ(f->exposure_ns, 2'000'000);
  EXPECT_EQ(f->data.size(), 16u * 8u);
  EXPECT_EQ(cam->timestamp_meaning(), TimestampMeaning::kMidExposure);
  f->release();
  clock.now = 1'301'000'000;  // frames 1, 2 and 3 are due
  for (std::uint32_t k = 1; k <= 3; ++k) {
    auto g = cam->dequeue();
    ASSERT_TRUE(g.ok() && g->valid());
    EXPECT_EQ(g->sequence, k);
    EXPECT_EQ(g->t_ns, 1'000'000'000 + static_cast<TimeNs>(k) * 100'000'000);
    EXPECT_EQ(g->data[0], k);
  }
  EXPECT_EQ(cam->counters().frames, 4u);
  EXPECT_EQ(cam->counters().dropped, 0u);
}

TEST(VirtualCamera, AConsumerHoldingEveryBufferMakesItDropAndCount) {
  SimClock clock;
  VirtualCameraOptions o;
  o.buffers = 2;
  auto cam = make_camera(clock, o);
  ASSERT_TRUE(cam);
  ASSERT_TRUE(cam->start().ok());
  clock.now = 1'101'000'000;  // frames 0 and 1 due
  auto a = cam->dequeue();
  auto b = cam->dequeue();
  ASSERT_TRUE(a.ok() && a->valid() && b.ok() && b->valid());
  clock.now = 1'301'000'000;  // frames 2 and 3: both buffers are held
  auto c = cam->dequeue();
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(c->valid());
  EXPECT_EQ(cam->counters().dropped, 2u);
  a->release();
  clock.now = 1'401'000'000;
  auto d = cam->dequeue();
  ASSERT_TRUE(d.ok() && d->valid());
  EXPECT_EQ(d->sequence, 4u);  // the gap tells the consumer what was lost
  Frame moved = std::move(*d);
  EXPECT_FALSE(d->valid());
  EXPECT_TRUE(moved.valid());
}

TEST(VirtualCamera, StallAndDisconnectFaults) {
  SimClock clock;
  VirtualCameraOptions stall;
  stall.stall_after = 2;
  auto cam = make_camera(clock, stall);
  ASSERT_TRUE(cam && cam->start().ok());
  clock.now = 5'000'000'000;
  int got = 0;
  while (true) {
    auto f = cam->dequeue();
    ASSERT_TRUE(f.ok());
    if (!f->valid()) break;
    ++got;
  }
  EXPECT_EQ(got, 2);

  SimClock clock2;
  VirtualCameraOptions gone;
  gone.disconnect_after = 3;
  auto cam2 = make_camera(clock2, gone);
  ASSERT_TRUE(cam2 && cam2->start().ok());
  clock2.now = 5'000'000'000;
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(cam2->dequeue().ok());
  auto f = cam2->dequeue();
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.error().code, Errc::kNotFound);
  EXPECT_NE(f.error().message.find("disconnected"), std::string::npos);
}

TEST(VirtualCamera, RefusesAFormatItDoesNotOffer) {
  SimClock clock;
  auto cam = make_camera(clock);
  ASSERT_TRUE(cam);
  EXPECT_TRUE(cam->set_format({16, 8, "GREY", 10.0}).ok());
  auto st = cam->set_format({32, 8, "GREY", 10.0});
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, Errc::kUnsupported);
  EXPECT_NE(st.error().message.find("16x8 GREY"), std::string::npos);
  EXPECT_FALSE(cam->set_format({16, 8, "YUYV", 10.0}).ok());
  auto formats = cam->formats();
  ASSERT_TRUE(formats.ok());
  ASSERT_EQ(formats->size(), 1u);
  VirtualCameraOptions bad;
  bad.exposure_ns = 200'000'000;  // longer than the 100 ms frame period
  bad.rate_hz = 10.0;
  EXPECT_FALSE(VirtualCamera::create(bad, fill_sequence).ok());
}

TEST(VirtualCamera, RealTimeFramesWakeTheDescriptor) {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  const TimeNs now = static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
  VirtualCameraOptions o;
  o.width = 32;
  o.height = 16;
  o.rate_hz = 50.0;
  o.exposure_ns = 1'000'000;
  o.first_frame_ns = now + 20'000'000;
  auto created = VirtualCamera::create(o, fill_sequence);
  ASSERT_TRUE(created.ok());
  VirtualCamera& cam = **created;
  ASSERT_GE(cam.fd(), 0);
  ASSERT_TRUE(cam.start().ok());
  std::vector<TimeNs> stamps;
  for (int waits = 0; waits < 200 && stamps.size() < 5; ++waits) {
    pollfd p{cam.fd(), POLLIN, 0};
    ASSERT_GE(::poll(&p, 1, 2000), 0);
    while (true) {
      auto f = cam.dequeue();
      ASSERT_TRUE(f.ok());
      if (!f->valid()) break;
      stamps.push_back(f->t_ns);
    }
  }
  ASSERT_GE(stamps.size(), 5u);
  for (std::size_t i = 1; i < stamps.size(); ++i) EXPECT_GT(stamps[i], stamps[i - 1]);
  EXPECT_EQ((stamps[0] - o.first_frame_ns) % 20'000'000, 0);
  ASSERT_TRUE(cam.stop().ok());
}

}  // namespace
}  // namespace imucal::drivers::camera::fake
