// SPDX-License-Identifier: BSD-3-Clause
// The camera path of acquisition: frames copied out of the device's buffers into a bounded pool,
// encoded off the acquisition thread into the session log, drops counted; and whole recordings of
// the simulated IMU with the virtual camera, including the camera failing or stalling while the
// IMU goes on, and a disk too slow for the frames.

#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <nlohmann/json.hpp>
#include <thread>

#include "acquisition/camera_stream.hpp"
#include "acquisition/recorder.hpp"
#include "drivers/camera/fake/virtual_camera.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "sim/rig.hpp"
#include "tests/support/emulator_accounting.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::acq {
namespace {

namespace cam = drivers::camera;

/// A device buffer the test owns; release() marks it returned.
struct FakeBuffer {
  std::vector<std::uint8_t> bytes;
  bool released = false;
};

cam::Frame frame_over(FakeBuffer& b, int w, int h, const char* fmt, std::uint32_t seq, TimeNs t,
                      TimeNs exposure = 0, std::size_t stride = 0) {
  cam::Frame f;
  f.t_ns = t;
  f.exposure_ns = exposure;
  f.sequence = seq;
  f.width = w;
  f.height = h;
  f.pixel_format = fmt;
  f.stride = stride;
  f.data = b.bytes;
  b.released = false;
  f.set_release([&b] { b.released = true; });
  return f;
}

std::unique_ptr<log::SessionLogWriter> new_log(const std::string& path) {
  auto w = log::SessionLogWriter::create(path);
  EXPECT_TRUE(w.ok());
  return w.ok() ? std::move(*w) : nullptr;
}

std::vector<CameraFrame> read_frames(const std::string& path) {
  std::vector<CameraFrame> out;
  auto r = log::SessionLogReader::open(path);
  EXPECT_TRUE(r.ok());
  if (!r.ok()) return out;
  auto id = (*r)->find_camera_stream();
  EXPECT_TRUE(id.ok());
  EXPECT_TRUE((*r)->for_each_frame(*id, log::kTimeMin, log::kTimeMax,
                                   [&](const CameraFrame& f) {
                                     out.push_back(f);
                                     return true;
                                   })
                  .ok());
  return out;
}

TEST(CameraStream, RecordsGreyAndTheLumaOfYuyvLosslesslyAndReleasesBuffersAtOnce) {
  const std::string path = test::scratch_dir() + "/frames.imulog";
  auto writer = new_log(path);
  ASSERT_TRUE(writer);
  const int w = 6, h = 4;
  auto grey = CameraStream::create({w, h, "GREY", 30.0}, cam::TimestampMeaning::kStartOfExposure);
  auto yuyv = CameraStream::create({w, h, "YUYV", 30.0}, cam::TimestampMeaning::kEndOfFrame);
  ASSERT_TRUE(grey.ok() && yuyv.ok());
  EXPECT_EQ((*grey)->timestamp_source(), "mid-exposure");
  EXPECT_EQ((*yuyv)->timestamp_source(), "end-of-frame");
  CameraStreamInfo gi;
  gi.name = "grey";
  CameraStreamInfo yi;
  yi.name = "yuyv";
  auto gid = writer->add_camera_stream(gi);
  auto yid = writer->add_camera_stream(yi);
  ASSERT_TRUE(gid.ok() && yid.ok());
  auto shared = log::synchronized_writer(*writer);
  ASSERT_TRUE((*grey)->start_log(*shared, *gid).ok());
  ASSERT_TRUE((*yuyv)->start_log(*shared, *yid).ok());

  FakeBuffer g{std::vector<std::uint8_t>(8 * h)};  // stride 8 > width 6
  for (std::size_t i = 0; i < g.bytes.size(); ++i) g.bytes[i] = static_cast<std::uint8_t>(i);
  auto gf = frame_over(g, w, h, "GREY", 7, 1'000'000, 400'000, 8);
  EXPECT_TRUE((*grey)->publish(gf));
  EXPECT_TRUE(g.released);

  FakeBuffer y{std::vector<std::uint8_t>(2 * w * h)};
  for (std::size_t i = 0; i < y.bytes.size(); ++i) y.bytes[i] = static_cast<std::uint8_t>(i % 2 ? 128 : i);
  auto yf = frame_over(y, w, h, "YUYV", 0, 5'000'000, 400'000);
  EXPECT_TRUE((*yuyv)->publish(yf));
  EXPECT_TRUE(y.released);
  ASSERT_TRUE((*grey)->stop().ok());
  ASSERT_TRUE((*yuyv)->stop().ok());
  ASSERT_TRUE(writer->close().ok());

  auto reader = log::SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  std::vector<CameraFrame> got;
  for (int id : {*gid, *yid}) {
    ASSERT_TRUE((*reader)
                    ->for_each_frame(id, log::kTimeMin, log::kTimeMax,
                                     [&](const CameraFrame& f) {
                                       got.push_back(f);
                                       return true;
                                     })
                    .ok());
  }
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].t_ns, 1'200'000);  // start of exposure + half the exposure
  EXPECT_EQ(got[0].sequence, 7u);
  EXPECT_EQ(got[1].t_ns, 5'000'000);  // end-of-frame stamps are kept as they are
  auto gi_img = log::decode_image(got[0].data, log::ReadMode::kGray8);
  auto yi_img = log::decode_image(got[1].data, log::ReadMode::kGray8);
  ASSERT_TRUE(gi_img.ok() && yi_img.ok());
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      EXPECT_EQ(gi_img->data[static_cast<std::size_t>(r * w + c)],
                g.bytes[static_cast<std::size_t>(r * 8 + c)]);
      EXPECT_EQ(yi_img->data[static_cast<std::size_t>(r * w + c)],
                y.bytes[static_cast<std::size_t>(2 * (r * w + c))]);
    }
  }
}

// Colour cameras (libcamera's processed streams, V4L2 RGB3/BGR3, GenICam RGB8/BGR8) are recorded
// as their BT.601 luma; each library's name for the byte order is honoured (libcamera's BGR888
// holds R, G, B in memory, its RGB888 B, G, R).
TEST(CameraStream, RecordsTheLumaOfColourFramesInEachLibrarysByteOrder) {
  const std::string path = test::scratch_dir() + "/colour.imulog";
  auto writer = new_log(path);
  ASSERT_TRUE(writer);
  const int w = 4, h = 2;
  // Per pixel (R, G, B): white, pure red, pure green, pure blue; the second row 75 % grey.
  const std::uint8_t px[8][3] = {{255, 255, 255}, {255, 0, 0},     {0, 255, 0},     {0, 0, 255},
                                 {191, 191, 191}, {191, 191, 191}, {191, 191, 191}, {191, 191, 191}};
  // (77 R + 150 G + 29 B + 128) / 256: BT.601's weights in 1/256.
  const std::uint8_t want[8] = {255, 77, 149, 29, 191, 191, 191, 191};
  const std::vector<std::pair<const char*, bool>> formats = {
      {"BGR888", true}, {"RGB3", true}, {"RGB8", true}, {"RGB888", false}, {"BGR3", false}, {"BGR8", false}};
  auto shared = log::synchronized_writer(*writer);
  std::vector<std::unique_ptr<CameraStream>> streams;
  std::vector<int> ids;
  for (const auto& [fmt, rgb_in_memory] : formats) {
    auto s = CameraStream::create({w, h, fmt, 30.0}, cam::TimestampMeaning::kEndOfFrame);
    ASSERT_TRUE(s.ok()) << fmt << ": " << s.error().message;
    CameraStreamInfo info;
    info.name = fmt;
    auto id = writer->add_camera_stream(info);
    ASSERT_TRUE(id.ok());
    ASSERT_TRUE((*s)->start_log(*shared, *id).ok());
    FakeBuffer b{std::vector<std::uint8_t>(16 * h, 0)};  // stride 16 > 3 * width
    for (int i = 0; i < w * h; ++i) {
      std::uint8_t* dst = b.bytes.data() + 16 * (i / w) + 3 * (i % w);
      for (int c = 0; c < 3; ++c) dst[c] = px[i][rgb_in_memory ? c : 2 - c];
    }
    auto f = frame_over(b, w, h, fmt, 0, 1'000'000, 0, 16);
    EXPECT_TRUE((*s)->publish(f)) << fmt;
    EXPECT_TRUE(b.released);
    ASSERT_TRUE((*s)->stop().ok());
    streams.push_back(std::move(*s));
    ids.push_back(*id);
  }
  ASSERT_TRUE(writer->close().ok());
  auto reader = log::SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  for (std::size_t k = 0; k < ids.size(); ++k) {
    std::vector<CameraFrame> got;
    ASSERT_TRUE((*reader)
                    ->for_each_frame(ids[k], log::kTimeMin, log::kTimeMax,
                                     [&](const CameraFrame& f) {
                                       got.push_back(f);
                                       return true;
                                     })
                    .ok());
    ASSERT_EQ(got.size(), 1u) << formats[k].first;
    auto img = log::decode_image(got[0].data, log::ReadMode::kGray8);
    ASSERT_TRUE(img.ok());
    for (int i = 0; i < w * h; ++i)
      EXPECT_EQ(img->data[static_cast<std::size_t>(i)], want[i]) << formats[k].first << " pixel " << i;
  }
}

TEST(CameraStream, RefusesFormatsItCannotRecordAndFramesOfAnotherSize) {
  auto bayer = CameraStream::create({8, 8, "BA81", 30.0}, cam::TimestampMeaning::kEndOfFrame);
  ASSERT_FALSE(bayer.ok());
  EXPECT_EQ(bayer.error().code, Errc::kUnsupported);
  EXPECT_NE(bayer.error().message.find("GREY"), std::string::npos);

  auto s = CameraStream::create({8, 8, "GREY", 30.0}, cam::TimestampMeaning::kMidExposure);
  ASSERT_TRUE(s.ok());
  FakeBuffer b{std::vector<std::uint8_t>(64)};
  auto wrong = frame_over(b, 4, 16, "GREY", 0, 0);
  EXPECT_FALSE((*s)->publish(wrong));
  EXPECT_TRUE(b.released);
  FakeBuffer shortb{std::vector<std::uint8_t>(10)};
  auto truncated = frame_over(shortb, 8, 8, "GREY", 1, 0);
  EXPECT_FALSE((*s)->publish(truncated));
  EXPECT_EQ((*s)->stats().wrong_size, 2u);
}

TEST(CameraStream, AFullPoolDropsAndCountsAndMarksTheNextFrame) {
  const std::string path = test::scratch_dir() + "/drops.imulog";
  auto writer = new_log(path);
  ASSERT_TRUE(writer);
  CameraStreamOptions o;
  o.queue_frames = 2;
  auto s = CameraStream::create({8, 8, "GREY", 30.0}, cam::TimestampMeaning::kMidExposure, o);
  ASSERT_TRUE(s.ok());
  CameraStreamInfo info;
  auto id = writer->add_camera_stream(info);
  ASSERT_TRUE(id.ok());
  // No encoder yet: the pool fills after two frames.
  FakeBuffer b{std::vector<std::uint8_t>(64, 9)};
  for (std::uint32_t k = 0; k < 5; ++k) {
    auto f = frame_over(b, 8, 8, "GREY", k, k * 1000);
    EXPECT_EQ((*s)->publish(f), k < 2) << k;
    EXPECT_TRUE(b.released);
  }
  EXPECT_EQ((*s)->stats().queue_dropped, 3u);
  auto shared = log::synchronized_writer(*writer);
  ASSERT_TRUE((*s)->start_log(*shared, *id).ok());
  for (int i = 0; i < 200 && (*s)->stats().written < 2; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  auto f = frame_over(b, 8, 8, "GREY", 9, 9000);  // sequence 5..8 missing as well
  EXPECT_TRUE((*s)->publish(f));
  ASSERT_TRUE((*s)->stop().ok());
  // 2..4 were dropped here (counted as queue drops); 5..8 never came from the device.
  EXPECT_EQ((*s)->stats().device_dropped, 4u);
  ASSERT_TRUE(writer->close().ok());
  const auto frames = read_frames(path);
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[0].flags, 0u);
  EXPECT_EQ(frames[1].flags, 0u);
  EXPECT_EQ(frames[2].flags & 1u, 1u);
}

/// A log writer whose frame appends take `delay` (a slow card): frames must drop, samples not.
class SlowFrameWriter final : public log::SessionLogWriter {
 public:
  SlowFrameWriter(log::SessionLogWriter& inner, std::chrono::milliseconds delay)
      : inner_(inner), delay_(delay) {}
  Status set_metadata(const std::string& k, const std::string& v) override {
    return inner_.set_metadata(k, v);
  }
  Result<int> add_imu_stream(const ImuStreamInfo& i) override { return inner_.add_imu_stream(i); }
  Result<int> add_camera_stream(const CameraStreamInfo& i) override { return inner_.add_camera_stream(i); }
  Status append_imu(int id, std::span<const ImuSample> s) override { return inner_.append_imu(id, s); }
  Status append_frame(int id, const CameraFrame& f) override {
    std::this_thread::sleep_for(delay_);
    return inner_.append_frame(id, f);
  }
  Status append_event(const log::Event& e) override { return inner_.append_event(e); }
  Status flush() override { return inner_.flush(); }
  Status close() override { return inner_.close(); }

 private:
  log::SessionLogWriter& inner_;
  std::chrono::milliseconds delay_;
};

// The IMU stream and a camera share one log; the disk takes 100 ms per frame, three times the
// frame period. Frames are dropped and counted; every IMU sample is written.
TEST(CameraStream, ASlowDiskDropsFramesNeverImuSamples) {
  const std::string path = test::scratch_dir() + "/slow.imulog";
  auto writer = new_log(path);
  ASSERT_TRUE(writer);
  auto imu_id = writer->add_imu_stream(ImuStreamInfo{});
  auto cam_id = writer->add_camera_stream(CameraStreamInfo{});
  ASSERT_TRUE(imu_id.ok() && cam_id.ok());
  SlowFrameWriter slow(*writer, std::chrono::milliseconds(100));
  auto shared = log::synchronized_writer(slow);
  ImuStream imu;
  ASSERT_TRUE(imu.start_log(*shared, *imu_id).ok());
  CameraStreamOptions o;
  o.queue_frames = 4;
  auto frames = CameraStream::create({64, 48, "GREY", 30.0}, cam::TimestampMeaning::kMidExposure, o);
  ASSERT_TRUE(frames.ok());
  ASSERT_TRUE((*frames)->start_log(*shared, *cam_id).ok());
  FakeBuffer b{std::vector<std::uint8_t>(64 * 48, 100)};
  std::uint32_t published_frames = 0;
  for (int ms = 0; ms < 1500; ++ms) {
    ImuSample sample;
    sample.t_ns = ms * 1'000'000LL;
    imu.publish(std::span<const ImuSample>(&sample, 1));
    if (ms % 33 == 0) {
      auto f = frame_over(b, 64, 48, "GREY", published_frames++, sample.t_ns);
      (*frames)->publish(f);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_TRUE((*frames)->stop().ok());
  ASSERT_TRUE(imu.stop().ok());
  const CameraStreamStats fs = (*frames)->stats();
  const ImuStreamStats is = imu.stats();
  EXPECT_EQ(is.log_dropped, 0u);
  EXPECT_EQ(is.log_written, 1500u);
  EXPECT_GT(fs.queue_dropped, 0u);
  EXPECT_EQ(fs.written + fs.queue_dropped, published_frames);
  std::printf("  %u frames published, %llu written, %llu dropped; 1500 IMU samples written\n",
              published_frames, static_cast<unsigned long long>(fs.written),
              static_cast<unsigned long long>(fs.queue_dropped));
  ASSERT_TRUE(writer->close().ok());
}

/// The simulated IMU at 200 Hz and a 64x48 virtual camera at 20 Hz on the emulator's clock.
struct SimCameraRig {
  std::unique_ptr<sim::SimImuRig> rig;
  std::unique_ptr<cam::fake::VirtualCamera> camera;
};

SimCameraRig make_sim_camera_rig(cam::fake::VirtualCameraOptions vo) {
  SimCameraRig out;
  sim::SimRigOptions o;
  o.settings.dlpf_cfg = 1;
  o.settings.smplrt_div = 4;  // 200 Hz
  o.settings.read_interval_ns = 10'000'000;
  auto rig = sim::SimImuRig::create(emutest::wobble, o);
  EXPECT_TRUE(rig.ok());
  if (!rig.ok()) return out;
  out.rig = std::move(*rig);
  sim::SimImuRig* r = out.rig.get();
  vo.width = 64;
  vo.height = 48;
  vo.rate_hz = 20.0;
  vo.exposure_ns = 5'000'000;
  vo.first_frame_ns = r->clock().now_ns() + 500'000'000;
  vo.clock = [r] { return r->clock().now_ns(); };
  auto c = cam::fake::VirtualCamera::create(vo, [](TimeNs, std::uint32_t k, std::span<std::uint8_t> px) {
    for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<std::uint8_t>(i + k);
    return Status{};
  });
  EXPECT_TRUE(c.ok());
  if (c.ok()) out.camera = std::move(*c);
  return out;
}

RecordOptions camera_record_options(const std::string& path, cam::Camera& camera, double seconds) {
  RecordOptions ro;
  ro.log_path = path;
  ro.duration_s = seconds;
  ro.stream_info.name = "imu0";
  RecordCamera rc;
  rc.camera = &camera;
  rc.info.name = "cam0";
  rc.info.backend = "sim";
  rc.info.device = "sim";
  ro.cameras.push_back(rc);
  return ro;
}

std::vector<log::Event> faults_of(const std::string& path) {
  std::vector<log::Event> out;
  auto r = log::SessionLogReader::open(path);
  EXPECT_TRUE(r.ok());
  if (!r.ok()) return out;
  auto events = (*r)->events();
  EXPECT_TRUE(events.ok());
  for (const auto& e : *events)
    if (e.kind == "fault") out.push_back(e);
  return out;
}

TEST(RecordWithCamera, TheImuAndTheCameraGoIntoOneLogOnOneClock) {
  auto rig = make_sim_camera_rig({});
  ASSERT_TRUE(rig.rig && rig.camera);
  const std::string path = test::scratch_dir() + "/both.imulog";
  auto summary = record_imu_session(rig.rig->acquisition(), camera_record_options(path, *rig.camera, 5.0));
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  ASSERT_EQ(summary->cameras.size(), 1u);
  const CameraStreamStats& cs = summary->cameras[0].stats.stream;
  EXPECT_FALSE(summary->cameras[0].stats.failed);
  EXPECT_EQ(cs.queue_dropped, 0u);
  EXPECT_EQ(cs.device_dropped, 0u);
  EXPECT_EQ(summary->stream.log_dropped, 0u);

  auto reader = log::SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  auto imu = (*reader)->read_imu(*(*reader)->find_imu_stream());
  ASSERT_TRUE(imu.ok());
  const auto frames = read_frames(path);
  EXPECT_EQ(frames.size(), cs.written);
  // 5 s of samples; frames from 0.5 s after the rig powered up at 20 Hz: about 90.
  EXPECT_GE(frames.size(), 80u);
  EXPECT_LE(frames.size(), 100u);
  ASSERT_FALSE(frames.empty());
  EXPECT_GE(frames.front().t_ns, imu->front().t_ns - 100'000'000);
  EXPECT_LE(frames.back().t_ns, imu->back().t_ns + 100'000'000);
  for (std::size_t i = 1; i < frames.size(); ++i) EXPECT_EQ(frames[i].t_ns - frames[i - 1].t_ns, 50'000'000);
  EXPECT_EQ((*reader)->camera_streams().begin()->second.timestamp_source, "mid-exposure");
  auto meta = nlohmann::json::parse((*reader)->metadata().at("camera.cam0"));
  EXPECT_EQ(meta["frames_written"].get<std::uint64_t>(), frames.size());
  EXPECT_TRUE(faults_of(path).empty());
}

TEST(RecordWithCamera, AnUnpluggedCameraIsReportedAndTheImuGoesOn) {
  cam::fake::VirtualCameraOptions vo;
  vo.disconnect_after = 20;
  auto rig = make_sim_camera_rig(vo);
  ASSERT_TRUE(rig.rig && rig.camera);
  const std::string path = test::scratch_dir() + "/unplugged.imulog";
  auto summary = record_imu_session(rig.rig->acquisition(), camera_record_options(path, *rig.camera, 5.0));
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_TRUE(summary->cameras[0].stats.failed);
  EXPECT_NE(summary->cameras[0].stats.failure.find("disconnected"), std::string::npos);
  EXPECT_EQ(read_frames(path).size(), 20u);
  EXPECT_NEAR(summary->duration_s, 5.0, 0.05);  // the IMU recorded to the end
  const auto faults = faults_of(path);
  ASSERT_EQ(faults.size(), 1u);
  EXPECT_NE(faults[0].message.find("camera cam0 failed"), std::string::npos);
}

TEST(RecordWithCamera, ACameraThatStopsDeliveringIsReported) {
  cam::fake::VirtualCameraOptions vo;
  vo.stall_after = 10;
  auto rig = make_sim_camera_rig(vo);
  ASSERT_TRUE(rig.rig && rig.camera);
  const std::string path = test::scratch_dir() + "/stalled.imulog";
  auto ro = camera_record_options(path, *rig.camera, 5.0);
  ro.camera_stall_timeout_ns = kNsPerSecond;
  auto summary = record_imu_session(rig.rig->acquisition(), ro);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->cameras[0].stats.stalls, 1u);
  EXPECT_FALSE(summary->cameras[0].stats.failed);
  EXPECT_EQ(read_frames(path).size(), 10u);
  const auto faults = faults_of(path);
  ASSERT_EQ(faults.size(), 1u);
  EXPECT_NE(faults[0].message.find("delivered no frame"), std::string::npos);
  EXPECT_NEAR(summary->duration_s, 5.0, 0.05);
}

}  // namespace
}  // namespace imucal::acq
