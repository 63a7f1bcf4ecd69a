// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "log/dataset_io.hpp"
#include "log/rosbag.hpp"
#include "log/rosbag2.hpp"
#include "log/rosbag_format.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::log::rosbag_tests {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr TimeNs kT0 = 1'403'636'579'758'555'392;

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

Image noise_image(int width, int height, int channels, int depth, std::uint32_t seed) {
  Image image = Image::zeros(width, height, channels, depth);
  std::mt19937 rng(seed);
  for (auto& b : image.data) b = static_cast<std::uint8_t>(rng());
  return image;
}

struct LogData {
  std::vector<ImuSample> imu;
  std::map<std::string, std::vector<std::pair<TimeNs, Image>>> frames;  // per camera
};

/// A log with imu0 (SI, 300 samples of long digit strings), cam0 (8-bit gray), cam1 (16-bit
/// gray) and cam2 (BGR), frames as PNG.
LogData write_log(const std::string& path) {
  LogData d;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0.0, 1.0);
  auto w = SessionLogWriter::create(path);
  EXPECT_TRUE(w.ok());
  ImuStreamInfo info;
  info.rate_hz = 200;
  auto id = (*w)->add_imu_stream(info);
  for (int i = 0; i < 300; ++i) {
    ImuSample s;
    s.t_ns = kT0 + i * 5'000'000 + (i % 7);
    for (int k = 0; k < 3; ++k) {
      s.gyro[k] = 0.1 * noise(rng);
      s.accel[k] = 3.0 * noise(rng) + (k == 2 ? 9.81 : 0.0);
    }
    d.imu.push_back(s);
  }
  EXPECT_TRUE((*w)->append_imu(*id, d.imu).ok());
  const std::vector<std::tuple<std::string, int, int>> cams = {
      {"cam0", 1, 8}, {"cam1", 1, 16}, {"cam2", 3, 8}};
  for (const auto& [name, channels, depth] : cams) {
    CameraStreamInfo cam;
    cam.name = name;
    cam.width = 10;
    cam.height = 6;
    cam.rate_hz = 20;
    auto cid = (*w)->add_camera_stream(cam);
    for (int k = 0; k < 4; ++k) {
      CameraFrame f;
      f.t_ns = kT0 + k * 50'000'000 + 123;
      f.width = 10;
      f.height = 6;
      Image image =
          noise_image(10, 6, channels, depth, static_cast<std::uint32_t>(k + 10 * depth + channels));
      f.data = *encode_png(image);
      EXPECT_TRUE((*w)->append_frame(*cid, f).ok());
      d.frames[name].emplace_back(f.t_ns, std::move(image));
    }
  }
  EXPECT_TRUE((*w)->close().ok());
  return d;
}

void expect_log_holds(const std::string& path, const LogData& d) {
  auto r = SessionLogReader::open(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto imu = (*r)->read_imu(*(*r)->find_imu_stream("imu0"));
  ASSERT_TRUE(imu.ok());
  ASSERT_EQ(imu->size(), d.imu.size());
  for (std::size_t i = 0; i < imu->size(); ++i) {
    ASSERT_EQ((*imu)[i].t_ns, d.imu[i].t_ns) << i;
    for (int k = 0; k < 3; ++k) {
      ASSERT_TRUE(same_bits((*imu)[i].accel[k], d.imu[i].accel[k])) << i;
      ASSERT_TRUE(same_bits((*imu)[i].gyro[k], d.imu[i].gyro[k])) << i;
    }
  }
  for (const auto& [name, frames] : d.frames) {
    auto cid = (*r)->find_camera_stream(name);
    ASSERT_TRUE(cid.ok()) << name;
    EXPECT_EQ((*r)->camera_streams().at(*cid).width, 10);
    std::size_t n = 0;
    ASSERT_TRUE((*r)->for_each_frame(*cid, kTimeMin, kTimeMax,
                                     [&](const CameraFrame& f) {
                                       EXPECT_LT(n, frames.size());
                                       if (n >= frames.size()) return false;
                                       EXPECT_EQ(f.t_ns, frames[n].first);
                                       auto image = decode_png(f.data);
                                       EXPECT_TRUE(image.ok());
                                       EXPECT_EQ(image->channels, frames[n].second.channels) << name;
                                       EXPECT_EQ(image->depth, frames[n].second.depth) << name;
                                       EXPECT_EQ(image->data, frames[n].second.data)
                                           << name << " frame " << n;
                                       ++n;
                                       return true;
                                     })
                    .ok());
    EXPECT_EQ(n, frames.size()) << name;
  }
}

TEST(RosbagRoundTrip, ExportAndImportGiveTheSameSamplesAndPixelsWithEveryCompression) {
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "in.imulog").string();
  const LogData d = write_log(log);
  for (auto c : {BagCompression::kNone, BagCompression::kBz2, BagCompression::kLz4}) {
    const std::string bag = (dir / ("out" + std::to_string(static_cast<int>(c)) + ".bag")).string();
    auto e = export_bag(log, bag, {}, false, c);
    ASSERT_TRUE(e.ok()) << e.error().message;
    EXPECT_EQ(e->imu_samples, 300);
    EXPECT_EQ(e->frames, 12);
    BagImport in;
    in.path = bag;
    const std::string back = bag + ".imulog";
    auto i = import_bag(in, back, {});
    ASSERT_TRUE(i.ok()) << i.error().message;
    EXPECT_EQ(i->imu_samples, 300);
    EXPECT_EQ(i->frames, 12);
    EXPECT_EQ(i->camera_streams, 3);
    EXPECT_NEAR(i->rate_hz, 200.0, 1e-3);  // from the median interval (5 ms and 1 ns)
    expect_log_holds(back, d);
  }
}

TEST(RosbagExport, WritesTheStreamsInterleavedInTimeOrderAcrossAGap) {
  // An IMU at 200 Hz and a camera at 20 Hz, each 2 s long, with 10 min of nothing between their
  // first and second second: the bag holds them in time order, as rosbag record writes them.
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "gap.imulog").string();
  {
    auto w = SessionLogWriter::create(log);
    ASSERT_TRUE(w.ok());
    ImuStreamInfo info;
    info.rate_hz = 200;
    auto id = (*w)->add_imu_stream(info);
    CameraStreamInfo cam;
    cam.name = "cam0";
    cam.width = 8;
    cam.height = 4;
    cam.rate_hz = 20;
    auto cid = (*w)->add_camera_stream(cam);
    const TimeNs gap = 600'000'000'000;
    std::vector<ImuSample> imu;
    for (int i = 0; i < 400; ++i) {
      ImuSample s;
      s.t_ns = kT0 + i * 5'000'000 + (i >= 200 ? gap : 0);
      s.accel = {0, 0, 9.81};
      imu.push_back(s);
    }
    ASSERT_TRUE((*w)->append_imu(*id, imu).ok());
    for (int k = 0; k < 40; ++k) {
      CameraFrame f;
      f.t_ns = kT0 + 2'000'000 + k * 50'000'000 + (k >= 20 ? gap : 0);
      f.width = 8;
      f.height = 4;
      f.data = *encode_png(noise_image(8, 4, 1, 8, static_cast<std::uint32_t>(k)));
      ASSERT_TRUE((*w)->append_frame(*cid, f).ok());
    }
    ASSERT_TRUE((*w)->close().ok());
  }
  const std::string bag = (dir / "gap.bag").string();
  auto e = export_bag(log, bag, {}, false, BagCompression::kNone);
  ASSERT_TRUE(e.ok()) << e.error().message;
  EXPECT_EQ(e->imu_samples, 400);
  EXPECT_EQ(e->frames, 40);
  auto reader = rosbag::BagReader::open(bag);
  ASSERT_TRUE(reader.ok());
  rosbag::BagDamage damage;
  std::vector<std::pair<TimeNs, std::string>> order;
  ASSERT_TRUE((*reader)
                  ->for_each_message(
                      [&](const rosbag::MessageView& m) -> Status {
                        order.emplace_back(m.receive_ns, m.connection->topic);
                        return {};
                      },
                      damage)
                  .ok());
  EXPECT_FALSE(damage.damaged);
  ASSERT_EQ(order.size(), 440u);
  for (std::size_t i = 1; i < order.size(); ++i) {
    ASSERT_LE(order[i - 1].first, order[i].first) << "message " << i << " of " << order[i].second;
  }
  // The first frame (2 ms after the first sample) comes right after the sample before it.
  EXPECT_EQ(order[0].second, "/imu0");
  EXPECT_EQ(order[1].second, "/cam0/image_raw");
}

/// A bag of `n` Imu messages on /imu0 in chunks of about `chunk_bytes`.
std::vector<rosbag::ImuMessage> write_imu_bag(const std::string& path, int n, std::size_t chunk_bytes,
                                              rosbag::ChunkCompression c = rosbag::ChunkCompression::kNone,
                                              TimeNs lag_ns = 0) {
  auto bag = rosbag::BagWriter::create(path, c, chunk_bytes);
  EXPECT_TRUE(bag.ok());
  auto conn = (*bag)->add_connection("/imu0", rosbag::kImuType);
  std::vector<rosbag::ImuMessage> out;
  for (int i = 0; i < n; ++i) {
    rosbag::ImuMessage m;
    m.stamp_ns = kT0 + i * 1'000'000;
    m.gyro = Eigen::Vector3d(0.01 * i, -0.5, 1.0 / (i + 1));
    m.accel = Eigen::Vector3d(0.1, 9.81, -0.001 * i);
    EXPECT_TRUE(
        (*bag)->write(*conn, m.stamp_ns + lag_ns, rosbag::encode_imu(m, static_cast<std::uint32_t>(i))).ok());
    out.push_back(m);
  }
  EXPECT_TRUE((*bag)->close().ok());
  return out;
}

struct ChunkPlace {
  std::uint64_t start = 0;  // where the chunk record begins
  std::uint64_t data = 0;   // where its (compressed) data begin
  std::uint64_t end = 0;    // where it ends
  int messages = 0;         // in the chunks up to it
};

/// Where each chunk record is and how many messages the chunks up to it hold.
std::vector<ChunkPlace> chunk_places(const std::string& bytes) {
  std::vector<ChunkPlace> out;
  const auto* p = reinterpret_cast<const std::uint8_t*>(bytes.data());
  std::uint64_t at = rosbag::format::kMagic.size();
  int messages = 0;
  while (at < bytes.size()) {
    const std::uint32_t hl = rosbag::format::le32(p + at);
    auto fields = rosbag::format::Fields::parse({p + at + 4, hl});
    const std::uint32_t dl = rosbag::format::le32(p + at + 4 + hl);
    const std::uint64_t next = at + 8 + hl + dl;
    if (*fields->op() == rosbag::format::kOpIndex) messages += static_cast<int>(*fields->u32("count"));
    if (*fields->op() == rosbag::format::kOpChunk) out.push_back({at, at + 8 + hl, next, 0});
    if (*fields->op() == rosbag::format::kOpConnection && !out.empty()) break;  // the index
    if (!out.empty()) out.back().messages = messages;
    at = next;
  }
  return out;
}

TEST(Rosbag, ACutBagIsRefusedNamingTheByteAndItsWholeChunksImportWithAllowDamaged) {
  const fs::path dir = test::scratch_dir();
  const std::string bag = (dir / "whole.bag").string();
  write_imu_bag(bag, 400, 3000);
  const std::string bytes = test::read_file(bag);
  const auto chunks = chunk_places(bytes);
  ASSERT_GE(chunks.size(), 20u);
  ASSERT_EQ(chunks.back().messages, 400);
  // Cut at every chunk's end, inside its index records and inside the next chunk.
  std::vector<std::uint64_t> cuts;
  for (std::size_t k = 0; k + 1 < chunks.size(); ++k) {
    cuts.push_back(chunks[k].end);
    cuts.push_back(chunks[k].end + 20);
    cuts.push_back(chunks[k + 1].data + 700);
  }
  for (std::uint64_t cut : cuts) {
    const std::string cut_bag = (dir / "cut.bag").string();
    test::write_file(cut_bag, bytes.substr(0, cut));
    int whole = 0;
    for (const auto& c : chunks) {
      if (c.end <= cut) whole = c.messages;
    }
    BagImport in;
    in.path = cut_bag;
    const std::string out = (dir / ("cut" + std::to_string(cut) + ".imulog")).string();
    auto refused = import_bag(in, out, {});
    ASSERT_FALSE(refused.ok()) << cut;
    EXPECT_EQ(refused.error().code, Errc::kCorrupt);
    EXPECT_THAT(refused.error().message, HasSubstr("of " + std::to_string(cut) + ", after"));
    ASSERT_EQ(refused.error().remedies.size(), 1u);
    EXPECT_EQ(refused.error().remedies[0].option, "allow_damaged");
    EXPECT_FALSE(fs::exists(out));
    in.allow_damaged = true;
    auto partial = import_bag(in, out, {});
    if (whole == 0) {
      EXPECT_FALSE(partial.ok()) << cut;  // nothing whole: no message
      continue;
    }
    ASSERT_TRUE(partial.ok()) << cut << ": " << partial.error().message;
    EXPECT_EQ(partial->imu_samples, whole) << "cut at " << cut;
    EXPECT_THAT(partial->notes[0], HasSubstr("imported what comes before it"));
  }
}

TEST(Rosbag, AFlippedByteIsFoundByBz2sChecksumOrWhereItBreaksARecord) {
  const fs::path dir = test::scratch_dir();
  const std::string bag = (dir / "bz2.bag").string();
  write_imu_bag(bag, 300, 4000, rosbag::ChunkCompression::kBz2);
  std::string bytes = test::read_file(bag);
  const auto chunks = chunk_places(bytes);
  ASSERT_GE(chunks.size(), 3u);
  // Inside the second chunk's compressed data.
  const std::uint64_t flip = chunks[1].data + 400;
  ASSERT_LT(flip, chunks[1].end);
  bytes[flip] = static_cast<char>(bytes[flip] ^ 0x10);
  test::write_file(bag, bytes);
  BagImport in;
  in.path = bag;
  auto r = import_bag(in, (dir / "bz2.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("the chunk at byte"));
  EXPECT_THAT(r.error().message, HasSubstr("bz2"));

  // A plain chunk has no checksum: a record length that runs past its chunk is found.
  const std::string plain = (dir / "plain.bag").string();
  write_imu_bag(plain, 300, 4000);
  bytes = test::read_file(plain);
  // The second chunk's first record (its connection or a message): its header length's top byte.
  const std::uint64_t record = chunk_places(bytes)[1].data;
  bytes[record + 3] = static_cast<char>(0x7f);
  test::write_file(plain, bytes);
  in.path = plain;
  r = import_bag(in, (dir / "plain.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("runs past the chunk's end"));
}

TEST(Rosbag, TopicsChooseAndOrderTheStreamsAndAMissingOneListsTheBagsTopics) {
  const fs::path dir = test::scratch_dir();
  const std::string bag = (dir / "topics.bag").string();
  {
    auto w = rosbag::BagWriter::create(bag);
    ASSERT_TRUE(w.ok());
    auto a = (*w)->add_connection("/cam_left/image_raw", rosbag::kImageType);
    auto b = (*w)->add_connection("/cam_right/image_raw", rosbag::kImageType);
    auto imu = (*w)->add_connection("/imu0", rosbag::kImuType);
    for (int k = 0; k < 5; ++k) {
      rosbag::ImageMessage m;
      m.stamp_ns = kT0 + k * 50'000'000;
      m.image = noise_image(4, 2, 1, 8, static_cast<std::uint32_t>(k));
      ASSERT_TRUE((*w)->write(*a, m.stamp_ns, rosbag::encode_image(m, 0)).ok());
      m.image = noise_image(6, 2, 1, 8, static_cast<std::uint32_t>(k));
      ASSERT_TRUE((*w)->write(*b, m.stamp_ns, rosbag::encode_image(m, 0)).ok());
    }
    rosbag::ImuMessage m;
    m.stamp_ns = kT0;
    ASSERT_TRUE((*w)->write(*imu, kT0, rosbag::encode_imu(m, 0)).ok());
    ASSERT_TRUE((*w)->close().ok());
  }
  BagImport in;
  in.path = bag;
  in.topics = {"/cam_right/image_raw", "/cam_left/image_raw"};
  const std::string out = (dir / "topics.imulog").string();
  auto r = import_bag(in, out, {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->imu_streams, 0);
  EXPECT_THAT(r->notes.back(), HasSubstr("no sensor_msgs/Imu topic was imported"));
  EXPECT_THAT(r->notes.back(), HasSubstr("/imu0 (sensor_msgs/Imu)"));
  auto log = SessionLogReader::open(out);
  ASSERT_TRUE(log.ok());
  EXPECT_EQ((*log)->camera_streams().at(*(*log)->find_camera_stream("cam0")).width, 6);  // the right camera
  EXPECT_EQ((*log)->camera_streams().at(*(*log)->find_camera_stream("cam1")).width, 4);
  EXPECT_THAT((*log)->metadata().at("import"), HasSubstr("\"cam0\":\"/cam_right/image_raw\""));

  in.topics = {"/cam0/image_raw"};
  r = import_bag(in, (dir / "none.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kInvalidArgument);
  EXPECT_THAT(r.error().message, HasSubstr("has no topic /cam0/image_raw; its topics: /cam_left/image_raw "
                                           "(sensor_msgs/Image), /cam_right/image_raw (sensor_msgs/Image), "
                                           "/imu0 (sensor_msgs/Imu)"));
}

TEST(Rosbag, HeaderStampsAreUsedAndAReceiveTimeMoreThanAFrameLateIsNoted) {
  const fs::path dir = test::scratch_dir();
  const std::string bag = (dir / "late.bag").string();
  const auto sent = write_imu_bag(bag, 50, 1 << 20, rosbag::ChunkCompression::kLz4, 30'000'000);
  BagImport in;
  in.path = bag;
  auto r = import_bag(in, (dir / "header.imulog").string(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->t_first_ns, sent.front().stamp_ns);
  EXPECT_THAT(r->notes.back(),
              HasSubstr("received its messages 30 ms (median) after their header stamps, more "
                        "than a sample (1 ms): the stamps used are the headers'"));
  in.receive_time = true;
  r = import_bag(in, (dir / "receive.imulog").string(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->t_first_ns, sent.front().stamp_ns + 30'000'000);
}

TEST(Rosbag, MessagesWithoutStampsAskForTheReceiveTimes) {
  const fs::path dir = test::scratch_dir();
  const std::string bag = (dir / "zero.bag").string();
  {
    auto w = rosbag::BagWriter::create(bag);
    auto imu = (*w)->add_connection("/imu", rosbag::kImuType);
    for (int i = 0; i < 10; ++i) {
      rosbag::ImuMessage m;  // stamp 0
      ASSERT_TRUE((*w)->write(*imu, kT0 + i * 1'000'000, rosbag::encode_imu(m, 0)).ok());
    }
    ASSERT_TRUE((*w)->close().ok());
  }
  BagImport in;
  in.path = bag;
  auto r = import_bag(in, (dir / "zero.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("carry no header stamp"));
  ASSERT_EQ(r.error().remedies.size(), 1u);
  EXPECT_EQ(r.error().remedies[0].option, "receive_time");
}

std::vector<std::uint8_t> image_message(std::uint32_t width, std::uint32_t height,
                                        const std::string& encoding, bool big_endian, std::uint32_t step,
                                        const std::vector<std::uint8_t>& pixels) {
  std::vector<std::uint8_t> out;
  rosbag::format::put32(out, 0);
  rosbag::format::put64(out, rosbag::format::ros_time(kT0));
  rosbag::format::put32(out, 0);  // frame_id ""
  rosbag::format::put32(out, height);
  rosbag::format::put32(out, width);
  rosbag::format::put32(out, static_cast<std::uint32_t>(encoding.size()));
  out.insert(out.end(), encoding.begin(), encoding.end());
  out.push_back(big_endian ? 1 : 0);
  rosbag::format::put32(out, step);
  rosbag::format::put32(out, static_cast<std::uint32_t>(pixels.size()));
  out.insert(out.end(), pixels.begin(), pixels.end());
  return out;
}

TEST(RosbagMessages, ImageEncodingsDecodeToTheirPixels) {
  // mono8 with a padded step: the padding is left out.
  auto m = rosbag::decode_image(image_message(2, 2, "mono8", false, 4, {1, 2, 99, 99, 3, 4, 99, 99}));
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_EQ(m->stamp_ns, kT0);
  EXPECT_EQ(m->image.data, (std::vector<std::uint8_t>{1, 2, 3, 4}));
  // mono16, big-endian: 0x0102 and 0xA0B0.
  m = rosbag::decode_image(image_message(2, 1, "mono16", true, 4, {0x01, 0x02, 0xA0, 0xB0}));
  ASSERT_TRUE(m.ok());
  std::uint16_t v[2];
  std::memcpy(v, m->image.data.data(), 4);
  EXPECT_EQ(v[0], 0x0102);
  EXPECT_EQ(v[1], 0xA0B0);
  // rgb8 becomes BGR.
  m = rosbag::decode_image(image_message(1, 1, "rgb8", false, 3, {10, 20, 30}));
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->image.data, (std::vector<std::uint8_t>{30, 20, 10}));
  // yuv422 (UYVY): white and black, video range.
  m = rosbag::decode_image(image_message(2, 1, "yuv422", false, 4, {128, 235, 128, 16}));
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->image.data, (std::vector<std::uint8_t>{255, 255, 255, 0, 0, 0}));

  auto bad = rosbag::decode_image(image_message(2, 2, "bayer_rggb8", false, 2, {1, 2, 3, 4}));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, Errc::kUnsupported);
  EXPECT_THAT(bad.error().message, HasSubstr("'bayer_rggb8'"));
  bad = rosbag::decode_image(image_message(4, 2, "mono8", false, 4, {1, 2, 3, 4}));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, Errc::kCorrupt);
  auto cut = image_message(1, 1, "mono8", false, 1, {7});
  cut.pop_back();
  EXPECT_EQ(rosbag::decode_image(cut).error().code, Errc::kCorrupt);
}

TEST(RosbagMessages, ImuEncodesAndDecodesBitForBit) {
  rosbag::ImuMessage m;
  m.stamp_ns = kT0;
  m.frame_id = "imu0";
  m.gyro = Eigen::Vector3d(0.1, -1.0 / 3.0, 1e-300);
  m.accel = Eigen::Vector3d(9.80665, -0.0, 12345.678);
  const auto bytes = rosbag::encode_imu(m, 5);
  EXPECT_EQ(bytes.size(), 4u + 8 + 4 + 4 + 8 * (4 + 9 + 3 + 9 + 3 + 9));
  auto back = rosbag::decode_imu(bytes);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->stamp_ns, kT0);
  EXPECT_EQ(back->frame_id, "imu0");
  for (int k = 0; k < 3; ++k) {
    EXPECT_TRUE(same_bits(back->gyro[k], m.gyro[k]));
    EXPECT_TRUE(same_bits(back->accel[k], m.accel[k]));
  }
  auto longer = bytes;
  longer.push_back(0);
  EXPECT_THAT(rosbag::decode_imu(longer).error().message, HasSubstr("1 bytes after its fields"));
}

TEST(Rosbag, WhatIsNotAROS1BagIsNamed) {
  const fs::path dir = test::scratch_dir();
  test::write_file(dir / "old.bag", "#ROSBAG V1.2\nxxxxxxxxxxxxxxxxxxxxxxxx");
  test::write_file(dir / "text.bag", "hello, this is not a bag at all");
  fs::create_directories(dir / "ros2");
  test::write_file(dir / "ros2/metadata.yaml", "rosbag2_bagfile_information:\n");
  test::write_file(dir / "ros2.db3", std::string("SQLite format 3\0", 16) + "xxxx");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"old.bag", "format 1.2"},
      {"text.bag", "is not a ROS 1 bag"},
      {"ros2", "holds no rosbag2 storage file"},
      {"ros2.db3", "is not a rosbag2 sqlite3 file"},
      {"missing.bag", "No such file"}};
  for (const auto& [name, says] : cases) {
    BagImport in;
    in.path = (dir / name).string();
    auto r = import_bag(in, (dir / (name + ".imulog")).string(), {});
    ASSERT_FALSE(r.ok()) << name;
    EXPECT_THAT(r.error().message, HasSubstr(says)) << name;
    // A form imucal does not read is refused as malformed input (exit 3), not as unsupported.
    if (name == "old.bag" || name == "text.bag" || name == "ros2.db3") {
      EXPECT_EQ(r.error().code, Errc::kCorrupt) << name;
    }
    EXPECT_FALSE(fs::exists(dir / (name + ".imulog")));
  }
}

TEST(Rosbag2Messages, CdrImuAndImageDecodeBitForBitWithTheirAlignment) {
  rosbag::ImuMessage m;
  m.stamp_ns = kT0;
  m.frame_id = "imu";  // 4 bytes with its NUL: the doubles then start 4 bytes on, at offset 16
  m.gyro = Eigen::Vector3d(0.1, -1.0 / 3.0, 1e-300);
  m.accel = Eigen::Vector3d(9.80665, -0.0, 12345.678);
  const auto bytes = rosbag2::encode_imu_cdr(m);
  EXPECT_EQ(bytes.size(), 4u + 8 + 4 + 4 + 8 * (4 + 9 + 3 + 9 + 3 + 9));
  auto back = rosbag2::decode_imu_cdr(bytes);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->stamp_ns, kT0);
  EXPECT_EQ(back->frame_id, "imu");
  for (int k = 0; k < 3; ++k) {
    EXPECT_TRUE(same_bits(back->gyro[k], m.gyro[k]));
    EXPECT_TRUE(same_bits(back->accel[k], m.accel[k]));
  }
  rosbag::ImageMessage im;
  im.stamp_ns = kT0;
  im.frame_id = "cam0_optical";
  im.image = noise_image(5, 3, 1, 16, 9);
  auto image = rosbag2::decode_image_cdr(rosbag2::encode_image_cdr(im));
  ASSERT_TRUE(image.ok()) << image.error().message;
  EXPECT_EQ(image->encoding, "mono16");
  EXPECT_EQ(image->image.data, im.image.data);
  // A stamp written as (1 s, 1.5e9 ns), as a bag of ROS 2's own tests holds (0 s, 1e9 ns), is the
  // time it adds up to.
  auto late = bytes;
  const std::uint32_t nsec = 1'500'000'000U, sec = 1;
  std::memcpy(late.data() + 4, &sec, 4);
  std::memcpy(late.data() + 8, &nsec, 4);
  EXPECT_EQ(*rosbag2::header_stamp_cdr(late), 2'500'000'000);
  // Big-endian CDR is named, a message cut short is damage.
  auto big = bytes;
  big[1] = 0x00;
  EXPECT_EQ(rosbag2::decode_imu_cdr(big).error().code, Errc::kUnsupported);
  auto cut = bytes;
  cut.resize(cut.size() - 8);
  EXPECT_EQ(rosbag2::decode_imu_cdr(cut).error().code, Errc::kCorrupt);
}

TEST(Rosbag2, ASessionLogIsNotTakenForAROS2Bag) {
  // Both are SQLite files: only a .db3 (or a folder with metadata.yaml, or an mcap) is a rosbag2.
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "in.imulog").string();
  write_log(log);
  EXPECT_FALSE(rosbag2::is_rosbag2(log));
  BagImport in;
  in.path = log;
  auto r = import_bag(in, (dir / "out.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("is not a ROS 1 bag"));
}

}  // namespace
}  // namespace imucal::log::rosbag_tests
