// SPDX-License-Identifier: BSD-3-Clause
// The V4L2 camera backend: open errors on real nodes, then a fake kernel (formats that adjust
// like a driver does, an mmap queue whose buffers the test completes with chosen sequence
// numbers, flags and stamps) for format refusal, the timestamp-clock policy, sequence gaps,
// damaged frames, buffer ownership across stop() and destruction, and the disconnect error.
// The real kernel path (vivid) runs in tests/qemu.

#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <vector>

#include "drivers/camera/v4l2/v4l2_camera.hpp"

namespace imucal::drivers::camera {
namespace {

constexpr std::uint32_t kGrey = V4L2_PIX_FMT_GREY;
constexpr std::uint32_t kYuyv = V4L2_PIX_FMT_YUYV;
constexpr std::uint32_t kPage = 1u << 20;  // buffer offsets for mmap: index * kPage
constexpr TimeNs kNow = 1000 * kNsPerSecond;

struct FakeSize {
  std::uint32_t width, height;
};

// A capture driver: GREY in two discrete sizes at 15/30 fps, YUYV as a stepwise size range at
// a continuous rate range. Like most drivers, S_FMT adjusts what it cannot do to the nearest
// size (and an unknown pixel format to its first one) instead of failing.
struct FakeV4l2 final : V4l2Io {
  int open_errno = 0;
  std::uint32_t caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
  std::uint32_t timestamp_flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_EOF;
  bool has_exposure = false;
  int exposure_100us = 0;
  int dqbuf_errno = 0;  // set: every DQBUF fails so (a disconnect)
  std::uint32_t max_buffers = 8;
  TimeNs now_ns = kNow;

  std::uint32_t width = 640, height = 480, fourcc = kGrey;
  v4l2_fract interval{1, 30};
  bool streaming = false;
  std::vector<std::vector<std::uint8_t>> buffers;
  std::vector<std::vector<std::uint8_t>> orphans;
  std::deque<std::uint32_t> queued;
  std::deque<v4l2_buffer> done;
  int qbufs = 0;
  int mapped = 0;
  int munmaps = 0;
  int frees = 0;  // REQBUFS with count 0
  bool closed = false;

  int open(const std::string& path) override {
    if (path != "/dev/video7") return -ENOENT;
    return open_errno != 0 ? -open_errno : 3;
  }
  void close(int fd) override {
    EXPECT_EQ(fd, 3);
    closed = true;
  }
  void* mmap(std::size_t length, int fd, off_t offset) override {
    EXPECT_EQ(fd, 3);
    const auto index = static_cast<std::size_t>(offset) / kPage;
    EXPECT_LT(index, buffers.size());
    EXPECT_EQ(length, buffers[index].size());
    ++mapped;
    return buffers[index].data();
  }
  void munmap(void* address, std::size_t) override {
    EXPECT_NE(address, nullptr);
    ++munmaps;
  }
  TimeNs monotonic_now_ns() override { return now_ns; }

  // The driver fills the oldest queued buffer.
  void complete(std::uint32_t sequence, TimeNs t_ns, std::uint32_t extra_flags = 0,
                std::uint32_t bytesused = 0) {
    ASSERT_FALSE(queued.empty()) << "no buffer queued";
    v4l2_buffer b{};
    b.index = queued.front();
    queued.pop_front();
    b.sequence = sequence;
    b.flags = timestamp_flags | extra_flags;
    b.bytesused = bytesused != 0 ? bytesused : width * height;
    b.timestamp.tv_sec = t_ns / kNsPerSecond;
    b.timestamp.tv_usec = (t_ns % kNsPerSecond) / 1000;
    buffers[b.index][0] = static_cast<std::uint8_t>(sequence);
    done.push_back(b);
  }

  int ioctl(int fd, unsigned long request, void* arg) override {
    EXPECT_EQ(fd, 3);
    EXPECT_FALSE(closed);
    switch (request) {
      case VIDIOC_QUERYCAP: {
        auto* c = static_cast<v4l2_capability*>(arg);
        std::snprintf(reinterpret_cast<char*>(c->driver), sizeof c->driver, "fake");
        std::snprintf(reinterpret_cast<char*>(c->card), sizeof c->card, "Fake camera");
        c->capabilities = caps | V4L2_CAP_DEVICE_CAPS;
        c->device_caps = caps;
        return 0;
      }
      case VIDIOC_G_FMT:
      case VIDIOC_S_FMT:
        return format(request, *static_cast<v4l2_format*>(arg));
      case VIDIOC_G_PARM:
      case VIDIOC_S_PARM:
        return parm(request, *static_cast<v4l2_streamparm*>(arg));
      case VIDIOC_ENUM_FMT:
      case VIDIOC_ENUM_FRAMESIZES:
      case VIDIOC_ENUM_FRAMEINTERVALS:
        return enumerate(request, arg);
      case VIDIOC_QUERYCTRL:
        return has_exposure && static_cast<v4l2_queryctrl*>(arg)->id == V4L2_CID_EXPOSURE_ABSOLUTE ? 0
                                                                                                   : -EINVAL;
      case VIDIOC_G_CTRL:
        static_cast<v4l2_control*>(arg)->value = exposure_100us;
        return has_exposure ? 0 : -EINVAL;
      default:
        return queue(request, arg);
    }
  }

  int format(unsigned long request, v4l2_format& f) {
    if (f.type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
    if (request == VIDIOC_S_FMT) {
      if (!buffers.empty()) return -EBUSY;
      fourcc = f.fmt.pix.pixelformat == kYuyv ? kYuyv : kGrey;
      if (fourcc == kGrey) {
        // The nearest of the two sizes.
        const bool small = f.fmt.pix.width * f.fmt.pix.height <= 320 * 240;
        width = small ? 320 : 640;
        height = small ? 240 : 480;
      } else {
        width = std::clamp(f.fmt.pix.width, 16u, 1920u) / 16 * 16;
        height = std::clamp(f.fmt.pix.height, 16u, 1080u) / 2 * 2;
      }
    }
    f.fmt.pix.width = width;
    f.fmt.pix.height = height;
    f.fmt.pix.pixelformat = fourcc;
    f.fmt.pix.field = V4L2_FIELD_NONE;
    f.fmt.pix.bytesperline = fourcc == kYuyv ? 2 * width : width;
    f.fmt.pix.sizeimage = f.fmt.pix.bytesperline * height;
    return 0;
  }

  int parm(unsigned long request, v4l2_streamparm& p) {
    if (request == VIDIOC_S_PARM) {
      const v4l2_fract asked = p.parm.capture.timeperframe;
      // GREY: 1/15 or 1/30, the nearer; YUYV: any rate from 1 to 60 fps.
      const double rate = asked.numerator == 0 ? 30.0 : double(asked.denominator) / asked.numerator;
      if (fourcc == kGrey) {
        interval = rate > 22.5 ? v4l2_fract{1, 30} : v4l2_fract{1, 15};
      } else {
        interval = asked;
      }
    }
    p.parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
    p.parm.capture.timeperframe = interval;
    return 0;
  }

  int enumerate(unsigned long request, void* arg) {
    if (request == VIDIOC_ENUM_FMT) {
      auto* d = static_cast<v4l2_fmtdesc*>(arg);
      if (d->index > 1) return -EINVAL;
      d->pixelformat = d->index == 0 ? kGrey : kYuyv;
      return 0;
    }
    if (request == VIDIOC_ENUM_FRAMESIZES) {
      auto* s = static_cast<v4l2_frmsizeenum*>(arg);
      if (s->pixel_format == kGrey) {
        if (s->index > 1) return -EINVAL;
        s->type = V4L2_FRMSIZE_TYPE_DISCRETE;
        s->discrete = s->index == 0 ? v4l2_frmsize_discrete{320, 240} : v4l2_frmsize_discrete{640, 480};
        return 0;
      }
      if (s->index > 0) return -EINVAL;
      s->type = V4L2_FRMSIZE_TYPE_STEPWISE;
      s->stepwise = {16, 1920, 16, 16, 1080, 2};
      return 0;
    }
    auto* i = static_cast<v4l2_frmivalenum*>(arg);
    if (i->pixel_format == kGrey) {
      if (i->index > 1) return -EINVAL;
      i->type = V4L2_FRMIVAL_TYPE_DISCRETE;
      i->discrete = i->index == 0 ? v4l2_fract{1, 30} : v4l2_fract{1, 15};
      return 0;
    }
    if (i->index > 0) return -EINVAL;
    i->type = V4L2_FRMIVAL_TYPE_CONTINUOUS;
    i->stepwise = {{1, 60}, {1, 1}, {1, 1}};
    return 0;
  }

  int queue(unsigned long request, void* arg) {
    switch (request) {
      case VIDIOC_REQBUFS: {
        auto* r = static_cast<v4l2_requestbuffers*>(arg);
        EXPECT_EQ(r->memory, V4L2_MEMORY_MMAP);
        EXPECT_FALSE(streaming);
        if (r->count == 0) ++frees;
        r->count = std::min(r->count, max_buffers);
        // Freed buffers that are still mapped stay alive, as the kernel keeps their pages.
        for (auto& b : buffers) orphans.push_back(std::move(b));
        buffers.assign(r->count, std::vector<std::uint8_t>(std::size_t{width} * height * 2));
        queued.clear();
        done.clear();
        return 0;
      }
      case VIDIOC_QUERYBUF: {
        auto* b = static_cast<v4l2_buffer*>(arg);
        if (b->index >= buffers.size()) return -EINVAL;
        b->length = static_cast<std::uint32_t>(buffers[b->index].size());
        b->m.offset = b->index * kPage;
        b->flags = timestamp_flags;
        return 0;
      }
      case VIDIOC_QBUF: {
        auto* b = static_cast<v4l2_buffer*>(arg);
        ++qbufs;  // every attempt, also those refused
        if (b->index >= buffers.size()) return -EINVAL;
        EXPECT_EQ(std::count(queued.begin(), queued.end(), b->index), 0) << "buffer queued twice";
        queued.push_back(b->index);
        return 0;
      }
      case VIDIOC_DQBUF: {
        if (dqbuf_errno != 0) return -dqbuf_errno;
        if (done.empty()) return -EAGAIN;
        *static_cast<v4l2_buffer*>(arg) = done.front();
        done.pop_front();
        return 0;
      }
      case VIDIOC_STREAMON:
        streaming = true;
        return 0;
      case VIDIOC_STREAMOFF:
        streaming = false;
        queued.clear();
        done.clear();
        return dqbuf_errno == ENODEV ? -ENODEV : 0;
      default:
        return -ENOTTY;
    }
  }
};

struct Opened {
  std::shared_ptr<FakeV4l2> fake = std::make_shared<FakeV4l2>();
  std::unique_ptr<Camera> camera;
};

Opened open_fake(V4l2Options options = {}, const std::function<void(FakeV4l2&)>& setup = {}) {
  Opened o;
  if (setup) setup(*o.fake);
  options.io = o.fake;
  auto r = open_v4l2_camera("/dev/video7", options);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  if (r.ok()) o.camera = std::move(*r);
  return o;
}

V4l2Options options(int buffers, bool stamp_at_dequeue = false) {
  V4l2Options o;
  o.buffers = buffers;
  o.stamp_at_dequeue = stamp_at_dequeue;
  return o;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(V4l2Camera, MissingNodeIsNotFound) {
  auto r = open_v4l2_camera("/dev/video-imucal-missing");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kNotFound);
  EXPECT_TRUE(contains(r.error().message, "/dev/video-imucal-missing")) << r.error().message;
}

TEST(V4l2Camera, DevNullIsNotAV4l2Device) {
  auto r = open_v4l2_camera("/dev/null");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kUnsupported);
  EXPECT_TRUE(contains(r.error().message, "/dev/null is not a V4L2 device")) << r.error().message;
}

TEST(V4l2Camera, OpenErrors) {
  auto fake = std::make_shared<FakeV4l2>();
  fake->open_errno = EACCES;
  auto denied = open_v4l2_camera("/dev/video7", {.io = fake});
  ASSERT_FALSE(denied.ok());
  EXPECT_TRUE(contains(denied.error().message, "group video")) << denied.error().message;

  fake = std::make_shared<FakeV4l2>();
  fake->caps = V4L2_CAP_VIDEO_OUTPUT | V4L2_CAP_STREAMING;
  auto output = open_v4l2_camera("/dev/video7", {.io = fake});
  ASSERT_FALSE(output.ok());
  EXPECT_EQ(output.error().code, Errc::kUnsupported);
  EXPECT_TRUE(contains(output.error().message, "not a video capture device")) << output.error().message;
  EXPECT_TRUE(fake->closed);

  fake = std::make_shared<FakeV4l2>();
  fake->caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE;
  auto no_streaming = open_v4l2_camera("/dev/video7", {.io = fake});
  ASSERT_FALSE(no_streaming.ok());
  EXPECT_TRUE(contains(no_streaming.error().message, "no streaming I/O")) << no_streaming.error().message;

  auto buffers = open_v4l2_camera("/dev/video7", {.buffers = 0, .io = std::make_shared<FakeV4l2>()});
  ASSERT_FALSE(buffers.ok());
  EXPECT_EQ(buffers.error().code, Errc::kInvalidArgument);
}

TEST(V4l2Camera, FormatsListDiscreteAndRangeEnds) {
  auto o = open_fake();
  ASSERT_TRUE(o.camera);
  EXPECT_STREQ(o.camera->backend(), "v4l2");
  EXPECT_EQ(o.camera->id(), "/dev/video7");
  const FrameFormat current = o.camera->format();
  EXPECT_EQ(current.pixel_format, "GREY");
  EXPECT_EQ(current.width, 640);
  EXPECT_DOUBLE_EQ(current.rate_hz, 30.0);

  auto list = o.camera->formats();
  ASSERT_TRUE(list.ok());
  std::vector<std::string> got;
  for (const auto& f : *list) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s %dx%d@%g", f.pixel_format.c_str(), f.width, f.height, f.rate_hz);
    got.emplace_back(buf);
  }
  const std::vector<std::string> expected{"GREY 320x240@30",   "GREY 320x240@15", "GREY 640x480@30",
                                          "GREY 640x480@15",   "YUYV 16x16@60",   "YUYV 16x16@1",
                                          "YUYV 1920x1080@60", "YUYV 1920x1080@1"};
  EXPECT_EQ(got, expected);
}

TEST(V4l2Camera, SetFormatAcceptsExactAndRefusesAdjusted) {
  auto o = open_fake();
  ASSERT_TRUE(o.camera);
  Camera& cam = *o.camera;
  ASSERT_TRUE(cam.set_format({320, 240, "GREY", 15.0}).ok());
  EXPECT_EQ(cam.format().width, 320);
  EXPECT_DOUBLE_EQ(cam.format().rate_hz, 15.0);
  EXPECT_EQ(o.fake->interval.denominator, 15u);

  // The driver picks 640x480 for a size it does not have: refused, naming both and the list.
  auto adjusted = cam.set_format({800, 600, "GREY", 30.0});
  ASSERT_FALSE(adjusted.ok());
  EXPECT_EQ(adjusted.error().code, Errc::kUnsupported);
  const std::string& m = adjusted.error().message;
  EXPECT_TRUE(contains(m, "GREY 800x600 at 30 fps")) << m;
  EXPECT_TRUE(contains(m, "offered GREY 640x480")) << m;
  EXPECT_TRUE(contains(m, "pixel formats GREY, YUYV")) << m;
  EXPECT_TRUE(contains(m, "320x240 at 30 15; 640x480 at 30 15")) << m;
  EXPECT_EQ(cam.format().width, 320) << "a refused format leaves the configured one";

  // An unknown pixel format comes back as GREY.
  auto pixel = cam.set_format({640, 480, "BA81", 0.0});
  ASSERT_FALSE(pixel.ok());
  EXPECT_TRUE(contains(pixel.error().message, "BA81 is not among them")) << pixel.error().message;

  // A rate the driver rounds is refused like a size.
  auto rate = cam.set_format({640, 480, "GREY", 25.0});
  ASSERT_FALSE(rate.ok());
  EXPECT_TRUE(contains(rate.error().message, "offered GREY 640x480 at 30 fps")) << rate.error().message;

  ASSERT_TRUE(cam.set_format({1280, 720, "YUYV", 29.97}).ok());
  EXPECT_NEAR(cam.format().rate_hz, 29.97, 1e-9);
  EXPECT_EQ(o.fake->interval.numerator, 100u);
  EXPECT_EQ(o.fake->interval.denominator, 2997u);

  EXPECT_EQ(cam.set_format({640, 480, "TOOLONG", 0.0}).error().code, Errc::kInvalidArgument);
  EXPECT_EQ(cam.set_format({0, 480, "GREY", 0.0}).error().code, Errc::kInvalidArgument);
}

TEST(V4l2Camera, StreamsFramesAndRequeuesOnRelease) {
  auto o = open_fake(options(3), [](FakeV4l2& f) {
    f.has_exposure = true;
    f.exposure_100us = 50;  // 5 ms
  });
  ASSERT_TRUE(o.camera);
  Camera& cam = *o.camera;
  FakeV4l2& fake = *o.fake;
  {
    auto none = cam.dequeue();
    ASSERT_FALSE(none.ok()) << "dequeue before start";
  }
  ASSERT_TRUE(cam.start().ok());
  EXPECT_EQ(cam.fd(), 3);
  EXPECT_EQ(fake.buffers.size(), 3u);
  EXPECT_EQ(fake.queued.size(), 3u);
  EXPECT_TRUE(fake.streaming);
  EXPECT_EQ(cam.timestamp_meaning(), TimestampMeaning::kEndOfFrame);

  auto empty = cam.dequeue();
  ASSERT_TRUE(empty.ok());
  EXPECT_FALSE(empty->valid()) << "EAGAIN gives an invalid frame";

  fake.complete(0, kNow - 5'000'000);
  auto f = cam.dequeue();
  ASSERT_TRUE(f.ok()) << f.error().message;
  ASSERT_TRUE(f->valid());
  EXPECT_EQ(f->t_ns, kNow - 5'000'000);
  EXPECT_EQ(f->sequence, 0u);
  EXPECT_EQ(f->exposure_ns, 5'000'000);
  EXPECT_EQ(f->width, 640);
  EXPECT_EQ(f->stride, 640u);
  EXPECT_EQ(f->pixel_format, "GREY");
  EXPECT_EQ(f->data.size(), 640u * 480u);
  EXPECT_EQ(fake.queued.size(), 2u);
  const int qbufs = fake.qbufs;
  f->release();
  EXPECT_EQ(fake.qbufs, qbufs + 1);
  EXPECT_EQ(fake.queued.size(), 3u);
  EXPECT_EQ(cam.counters().frames, 1u);
}

TEST(V4l2Camera, SequenceGapsCountDroppedAndDamagedFramesIncomplete) {
  auto o = open_fake();
  ASSERT_TRUE(o.camera);
  Camera& cam = *o.camera;
  FakeV4l2& fake = *o.fake;
  ASSERT_TRUE(cam.start().ok());
  auto take = [&](std::uint32_t seq, std::uint32_t flags = 0, std::uint32_t bytesused = 0) {
    fake.complete(seq, kNow - 1'000'000, flags, bytesused);
    auto r = cam.dequeue();
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() && r->valid();  // the frame is released here
  };
  EXPECT_TRUE(take(0));
  EXPECT_TRUE(take(1));
  EXPECT_TRUE(take(4));  // 2 and 3 never reached us
  EXPECT_EQ(cam.counters().dropped, 2u);
  EXPECT_FALSE(take(5, V4L2_BUF_FLAG_ERROR));
  EXPECT_FALSE(take(6, 0, 1000));  // shorter than 640 x 480
  EXPECT_EQ(cam.counters().incomplete, 2u);
  EXPECT_EQ(fake.queued.size(), 4u) << "damaged buffers go straight back";
  EXPECT_TRUE(take(7));
  const auto c = cam.counters();
  EXPECT_EQ(c.dropped, 2u) << "damaged frames are not counted as dropped too";
  EXPECT_EQ(c.frames, 4u);
  EXPECT_EQ(c.errors, 0u);
}

TEST(V4l2Camera, TimestampPolicy) {
  for (std::uint32_t type : {V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN, V4L2_BUF_FLAG_TIMESTAMP_COPY}) {
    auto o = open_fake({}, [&](FakeV4l2& f) { f.timestamp_flags = type; });
    ASSERT_TRUE(o.camera);
    auto s = o.camera->start();
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, Errc::kUnsupported);
    EXPECT_TRUE(contains(s.error().message, "does not stamp frames on CLOCK_MONOTONIC")) << s.error().message;
    ASSERT_EQ(s.error().remedies.size(), 1u);
    EXPECT_EQ(s.error().remedies[0].option, "stamp_at_dequeue");
    EXPECT_FALSE(o.fake->streaming);
    EXPECT_EQ(o.fake->munmaps, o.fake->mapped) << "a refused start unmaps its buffers";
    EXPECT_EQ(o.fake->frees, 1);
  }
  // Allowed: the frame gets CLOCK_MONOTONIC at dequeue, meaning end of frame.
  auto o = open_fake(options(4, true), [](FakeV4l2& f) {
    f.timestamp_flags = V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN | V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
  });
  ASSERT_TRUE(o.camera->start().ok());
  EXPECT_EQ(o.camera->timestamp_meaning(), TimestampMeaning::kEndOfFrame);
  o.fake->complete(0, 12345);
  o.fake->now_ns = kNow + 777;
  auto f = o.camera->dequeue();
  ASSERT_TRUE(f.ok() && f->valid());
  EXPECT_EQ(f->t_ns, kNow + 777);

  // Monotonic start-of-exposure stamps are used as they are.
  auto soe = open_fake({}, [](FakeV4l2& f) {
    f.timestamp_flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
  });
  ASSERT_TRUE(soe.camera->start().ok());
  EXPECT_EQ(soe.camera->timestamp_meaning(), TimestampMeaning::kStartOfExposure);

  // A driver that changes its clock after start is refused at that frame.
  auto changed = open_fake();
  ASSERT_TRUE(changed.camera->start().ok());
  changed.fake->timestamp_flags = V4L2_BUF_FLAG_TIMESTAMP_COPY;
  changed.fake->complete(0, kNow);
  auto c = changed.camera->dequeue();
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.error().code, Errc::kUnsupported);
}

TEST(V4l2Camera, StampsOnAnotherClockAreAnError) {
  auto o = open_fake();
  ASSERT_TRUE(o.camera->start().ok());
  o.fake->complete(0, kNow + 10 * kNsPerSecond);  // "monotonic", but ahead of the clock
  auto ahead = o.camera->dequeue();
  ASSERT_FALSE(ahead.ok());
  EXPECT_EQ(ahead.error().code, Errc::kDevice);
  EXPECT_TRUE(contains(ahead.error().message, "+10.000 s from CLOCK_MONOTONIC")) << ahead.error().message;
  o.fake->complete(1, kNow - 2 * 3600 * kNsPerSecond);  // two hours old: realtime or a counter
  EXPECT_FALSE(o.camera->dequeue().ok());
  EXPECT_EQ(o.fake->queued.size(), 4u) << "the buffers went back";
  o.fake->complete(2, kNow - kNsPerSecond);  // waited a second in the queue: fine
  auto late = o.camera->dequeue();
  ASSERT_TRUE(late.ok());
  EXPECT_TRUE(late->valid());
}

TEST(V4l2Camera, DisconnectIsAnError) {
  auto o = open_fake();
  ASSERT_TRUE(o.camera->start().ok());
  o.fake->dqbuf_errno = ENODEV;
  auto gone = o.camera->dequeue();
  ASSERT_FALSE(gone.ok());
  EXPECT_EQ(gone.error().code, Errc::kNotFound);
  EXPECT_TRUE(contains(gone.error().message, "camera /dev/video7 disconnected")) << gone.error().message;
  EXPECT_EQ(o.camera->counters().errors, 1u);
  EXPECT_TRUE(o.camera->stop().ok()) << "stopping a camera that is gone is not an error";

  auto eio = open_fake();
  ASSERT_TRUE(eio.camera->start().ok());
  eio.fake->dqbuf_errno = EIO;
  auto broken = eio.camera->dequeue();
  ASSERT_FALSE(broken.ok());
  EXPECT_EQ(broken.error().code, Errc::kDevice);
  EXPECT_TRUE(contains(broken.error().message, "camera /dev/video7 disconnected")) << broken.error().message;
}

TEST(V4l2Camera, FramesHeldAcrossStopAndDestructionStayMapped) {
  auto o = open_fake(options(2));
  FakeV4l2& fake = *o.fake;
  ASSERT_TRUE(o.camera->start().ok());
  fake.complete(0, kNow - 1000);
  fake.complete(1, kNow - 500);
  auto a = o.camera->dequeue();
  auto b = o.camera->dequeue();
  ASSERT_TRUE(a.ok() && a->valid() && b.ok() && b->valid());
  Frame held_a = std::move(*a);
  Frame held_b = std::move(*b);

  ASSERT_TRUE(o.camera->stop().ok());
  EXPECT_FALSE(fake.streaming);
  EXPECT_EQ(fake.munmaps, 0) << "held frames keep the mappings";
  EXPECT_EQ(held_a.data[0], 0);
  EXPECT_EQ(held_b.data[0], 1);
  const int qbufs = fake.qbufs;
  held_a.release();
  EXPECT_EQ(fake.qbufs, qbufs) << "no requeue after stop";
  EXPECT_EQ(fake.munmaps, 0);

  // Restart with b still held from the old stream, then destroy the camera.
  ASSERT_TRUE(o.camera->start().ok());
  EXPECT_EQ(fake.mapped, 4);
  o.camera.reset();
  EXPECT_TRUE(fake.closed);
  EXPECT_EQ(fake.munmaps, 2) << "the new stream's buffers go with the camera";
  EXPECT_EQ(held_b.data[0], 1);
  held_b.release();
  EXPECT_EQ(fake.munmaps, 4) << "the old stream's buffers go with the last frame";
}

TEST(V4l2Camera, FourccNames) {
  EXPECT_EQ(fourcc_name(V4L2_PIX_FMT_GREY), "GREY");
  EXPECT_EQ(fourcc_name(V4L2_PIX_FMT_Y16), "Y16 ");
  EXPECT_EQ(fourcc_name(V4L2_PIX_FMT_Y16_BE), "Y16 -BE");
  EXPECT_EQ(fourcc_from_name("GREY"), V4L2_PIX_FMT_GREY);
  EXPECT_EQ(fourcc_from_name("Y16"), V4L2_PIX_FMT_Y16);
  EXPECT_EQ(fourcc_from_name("Y16 -BE"), V4L2_PIX_FMT_Y16_BE);
  EXPECT_EQ(fourcc_from_name(""), 0u);
  EXPECT_EQ(fourcc_from_name("GREYS"), 0u);
}

}  // namespace
}  // namespace imucal::drivers::camera
