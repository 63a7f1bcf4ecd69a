// SPDX-License-Identifier: BSD-3-Clause
// Session log: round trips of every field, time-range reads, writer rules.

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>
#include <utility>

#include "log/session_log.hpp"
#include "tests/support/session_log_util.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::log {
namespace {

using namespace imucal::test;  // shared session-log helpers (tests/support)

using test::scratch_dir;

TEST(SessionLog, RoundTripsEveryField) {
  const std::string path = scratch_dir() + "/all.imulog";
  ImuStreamInfo raw_info = test_raw_imu_info();
  ImuStreamInfo si_info;
  si_info.name = "imu_si";
  si_info.units = ImuUnits::kSi;
  si_info.rate_hz = 200.5;
  si_info.device = "euroc:imu0";
  CameraStreamInfo cam_info;
  cam_info.name = "cam0";
  cam_info.width = 640;
  cam_info.height = 480;
  cam_info.rate_hz = 20.0;
  cam_info.backend = "v4l2";
  cam_info.device = "/dev/video0";
  cam_info.timestamp_source = "end-of-frame";

  std::vector<ImuSample> raw_samples, si_samples;
  for (int i = 0; i < 50; ++i) {
    ImuSample s;
    s.t_ns = 1'000'000'000 + TimeNs{i} * 1'000'000;
    s.accel = {-32768.0 + i, 32767.0 - i, 65535.0 * (i % 2)};  // signed and unsigned ADC counts
    s.gyro = {static_cast<double>(i), static_cast<double>(-i), 0.0};
    s.temperature = i == 3 ? std::numeric_limits<double>::quiet_NaN() : -521.0 + i;
    s.flags = static_cast<std::uint32_t>(i % 32);
    raw_samples.push_back(s);
    ImuSample q;
    q.t_ns = 2'000'000'000 + TimeNs{i} * 5'000'000;
    q.accel = {0.1 * i, -9.80665 + 1e-17 * i, std::nextafter(1.0, 2.0)};
    q.gyro = {1.0 / 3.0, -std::numeric_limits<double>::min(), std::numeric_limits<double>::max()};
    q.temperature = i == 7 ? std::numeric_limits<double>::quiet_NaN() : 25.0 + i / 7.0;
    q.flags = kImuFlagGapBefore | kImuFlagTimeEstimated;
    si_samples.push_back(q);
  }
  CameraFrame frame;
  frame.t_ns = 1'500'000'000;
  frame.width = 4;
  frame.height = 2;
  frame.encoding = "gray8";
  frame.data = {0, 1, 2, 3, 250, 251, 0, 255};
  frame.exposure_ns = 4'000'000;
  frame.sequence = 4'000'000'000u;
  frame.flags = 1;
  CameraFrame empty_frame = frame;
  empty_frame.t_ns += 50'000'000;
  empty_frame.encoding = "png";
  empty_frame.data.clear();

  int raw_id = 0, si_id = 0, cam_id = 0;
  {
    auto writer = SessionLogWriter::create(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    auto& w = **writer;
    ASSERT_TRUE(w.set_metadata("rig", "{\"serial\": \"A-17\"}").ok());
    ASSERT_TRUE(w.set_metadata("note", "").ok());
    auto r = w.add_imu_stream(raw_info);
    ASSERT_TRUE(r.ok()) << r.error().message;
    raw_id = *r;
    auto s = w.add_imu_stream(si_info);
    ASSERT_TRUE(s.ok()) << s.error().message;
    si_id = *s;
    auto c = w.add_camera_stream(cam_info);
    ASSERT_TRUE(c.ok()) << c.error().message;
    cam_id = *c;
    EXPECT_NE(raw_id, si_id);
    EXPECT_NE(raw_id, cam_id);
    EXPECT_NE(si_id, cam_id);
    ASSERT_TRUE(w.append_imu(raw_id, raw_samples).ok());
    ASSERT_TRUE(w.append_imu(si_id, si_samples).ok());
    ASSERT_TRUE(w.append_frame(cam_id, frame).ok());
    ASSERT_TRUE(w.append_frame(cam_id, empty_frame).ok());
    ASSERT_TRUE(w.append_event({1'200'000'000, "pose_begin", "{\"pose\": 1}"}).ok());
    ASSERT_TRUE(w.append_event({1'100'000'000, "prompt", "Hold still"}).ok());
    ASSERT_TRUE(w.close().ok());
  }
  EXPECT_FALSE(std::filesystem::exists(path + "-wal"));
  EXPECT_FALSE(std::filesystem::exists(path + "-shm"));

  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  const auto& r = **reader;
  EXPECT_TRUE(r.health().complete);
  EXPECT_FALSE(r.health().damaged) << r.health().damage_message;
  EXPECT_EQ(r.metadata().at("rig"), "{\"serial\": \"A-17\"}");
  EXPECT_EQ(r.metadata().at("note"), "");
  EXPECT_EQ(r.metadata().at("schema_version"), std::to_string(kSessionLogSchemaVersion));
  EXPECT_FALSE(r.metadata().at("software_version").empty());
  EXPECT_EQ(r.metadata().at("created_utc").size(), 20u);
  EXPECT_EQ(r.metadata().at("complete"), "1");

  ASSERT_EQ(r.imu_streams().size(), 2u);
  expect_same_info(r.imu_streams().at(raw_id), raw_info);
  expect_same_info(r.imu_streams().at(si_id), si_info);
  ASSERT_EQ(r.camera_streams().size(), 1u);
  const auto& cam = r.camera_streams().at(cam_id);
  EXPECT_EQ(cam.name, cam_info.name);
  EXPECT_EQ(cam.width, cam_info.width);
  EXPECT_EQ(cam.height, cam_info.height);
  EXPECT_EQ(cam.rate_hz, cam_info.rate_hz);
  EXPECT_EQ(cam.backend, cam_info.backend);
  EXPECT_EQ(cam.device, cam_info.device);
  EXPECT_EQ(cam.timestamp_source, cam_info.timestamp_source);

  EXPECT_EQ(*r.find_imu_stream(), raw_id);
  EXPECT_EQ(*r.find_imu_stream("imu_si"), si_id);
  EXPECT_EQ(*r.find_camera_stream("cam0"), cam_id);
  auto missing = r.find_imu_stream("nope");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("imu_si"), std::string::npos) << missing.error().message;

  auto raw_back = r.read_imu(raw_id);
  ASSERT_TRUE(raw_back.ok()) << raw_back.error().message;
  expect_same_samples(*raw_back, raw_samples);
  auto si_back = r.read_imu(si_id);
  ASSERT_TRUE(si_back.ok()) << si_back.error().message;
  expect_same_samples(*si_back, si_samples);
  EXPECT_EQ(*r.imu_count(raw_id), 50);
  EXPECT_EQ(*r.imu_count(si_id), 50);

  std::vector<CameraFrame> frames;
  ASSERT_TRUE(r.for_each_frame(cam_id, kTimeMin, kTimeMax, [&](const CameraFrame& f) {
                 frames.push_back(f);
                 return true;
               }).ok());
  ASSERT_EQ(frames.size(), 2u);
  for (const auto& [got, want] : {std::pair{frames[0], frame}, std::pair{frames[1], empty_frame}}) {
    EXPECT_EQ(got.t_ns, want.t_ns);
    EXPECT_EQ(got.width, want.width);
    EXPECT_EQ(got.height, want.height);
    EXPECT_EQ(got.encoding, want.encoding);
    EXPECT_EQ(got.data, want.data);
    EXPECT_EQ(got.exposure_ns, want.exposure_ns);
    EXPECT_EQ(got.sequence, want.sequence);
    EXPECT_EQ(got.flags, want.flags);
  }
  EXPECT_EQ(*r.frame_count(cam_id), 2);
  EXPECT_EQ(*r.frame_times(cam_id), (std::vector<TimeNs>{frame.t_ns, empty_frame.t_ns}));

  auto events = r.events();
  ASSERT_TRUE(events.ok());
  ASSERT_EQ(events->size(), 2u);
  EXPECT_EQ((*events)[0].t_ns, 1'100'000'000);  // in time order
  EXPECT_EQ((*events)[0].kind, "prompt");
  EXPECT_EQ((*events)[0].message, "Hold still");
  EXPECT_EQ((*events)[1].kind, "pose_begin");
  EXPECT_EQ((*events)[1].message, "{\"pose\": 1}");
}

// The file is inspectable: raw counts are INTEGER columns, SI values REAL, NaN is NULL.
TEST(SessionLog, StoresPlainTypedColumns) {
  const std::string path = scratch_dir() + "/types.imulog";
  {
    auto writer = SessionLogWriter::create(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    const int raw_id = *(*writer)->add_imu_stream(test_raw_imu_info());
    ImuStreamInfo si;
    si.name = "si";
    const int si_id = *(*writer)->add_imu_stream(si);
    ImuSample s;
    s.t_ns = 10;
    s.accel = {-5.0, 7.0, 16384.0};
    s.gyro = {1.0, 2.0, 3.0};
    ASSERT_TRUE((*writer)->append_imu(raw_id, s).ok());
    s.accel = {0.5, 1.0, 9.81};
    ASSERT_TRUE((*writer)->append_imu(si_id, s).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  ASSERT_EQ(
      sqlite3_prepare_v2(db,
                         "SELECT typeof(ax), typeof(gz), typeof(temperature), typeof(t_ns), typeof(flags) "
                         "FROM imu_samples ORDER BY rowid",
                         -1, &stmt, nullptr),
      SQLITE_OK);
  ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0)), "integer");
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 1)), "integer");
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 2)), "null");
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 3)), "integer");
  ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0)), "real");
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 1)), "real");
  sqlite3_finalize(stmt);
  ASSERT_EQ(sqlite3_prepare_v2(db, "PRAGMA journal_mode", -1, &stmt, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0)), "delete");
  sqlite3_finalize(stmt);
  sqlite3_close(db);
}

TEST(SessionLog, TimeRangeReadsAreHalfOpenAndOrdered) {
  const std::string path = scratch_dir() + "/range.imulog";
  int imu_id = 0, cam_id = 0;
  {
    auto writer = SessionLogWriter::create(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    imu_id = *(*writer)->add_imu_stream(test_raw_imu_info());
    CameraStreamInfo cam;
    cam_id = *(*writer)->add_camera_stream(cam);
    // Out of order on purpose (a late-arriving batch): reads must come back sorted.
    std::vector<ImuSample> samples;
    for (int i : {5, 6, 7, 8, 9, 0, 1, 2, 3, 4}) {
      ImuSample s;
      s.t_ns = i * 100;
      s.accel.x() = i;
      samples.push_back(s);
    }
    ASSERT_TRUE((*writer)->append_imu(imu_id, samples).ok());
    for (int i : {3, 1, 2, 0}) {
      CameraFrame f;
      f.t_ns = i * 1000;
      f.sequence = static_cast<std::uint32_t>(i);
      f.data = {static_cast<std::uint8_t>(i)};
      ASSERT_TRUE((*writer)->append_frame(cam_id, f).ok());
    }
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  std::vector<TimeNs> times;
  ASSERT_TRUE((*reader)
                  ->for_each_imu(imu_id, 200, 700,
                                 [&](const ImuSample& s) {
                                   times.push_back(s.t_ns);
                                   EXPECT_EQ(s.accel.x() * 100, s.t_ns);
                                   return true;
                                 })
                  .ok());
  EXPECT_EQ(times, (std::vector<TimeNs>{200, 300, 400, 500, 600}));
  times.clear();
  ASSERT_TRUE((*reader)
                  ->for_each_imu(imu_id, 0, 1000,
                                 [&](const ImuSample& s) {
                                   times.push_back(s.t_ns);
                                   return times.size() < 3;  // stop early
                                 })
                  .ok());
  EXPECT_EQ(times, (std::vector<TimeNs>{0, 100, 200}));
  times.clear();
  ASSERT_TRUE((*reader)
                  ->for_each_imu(imu_id, 450, 450,
                                 [&](const ImuSample& s) {
                                   times.push_back(s.t_ns);
                                   return true;
                                 })
                  .ok());
  EXPECT_TRUE(times.empty());
  std::vector<std::uint32_t> sequences;
  ASSERT_TRUE((*reader)
                  ->for_each_frame(
                      cam_id, 1000, 3000,
                      [&](const CameraFrame& f) {
                        sequences.push_back(f.sequence);
                        EXPECT_EQ(f.data, std::vector<std::uint8_t>{static_cast<std::uint8_t>(f.sequence)});
                        return true;
                      })
                  .ok());
  EXPECT_EQ(sequences, (std::vector<std::uint32_t>{1, 2}));
  EXPECT_EQ(*(*reader)->frame_times(cam_id), (std::vector<TimeNs>{0, 1000, 2000, 3000}));
  EXPECT_FALSE((*reader)->for_each_imu(cam_id, 0, 1, [](const ImuSample&) { return true; }).ok());
  EXPECT_FALSE((*reader)->imu_count(99).ok());
}

/// Every sample of a stream, as read_imu returns them: (time, accel x) pairs.
// The times of a stream's samples in [t0, t1).
std::vector<TimeNs> range_times(const SessionLogReader& reader, int id, TimeNs t0, TimeNs t1) {
  std::vector<TimeNs> times;
  const Status status = reader.for_each_imu(id, t0, t1, [&](const ImuSample& s) {
    times.push_back(s.t_ns);
    return true;
  });
  EXPECT_TRUE(status.ok()) << status.error().message;
  return times;
}

/// Adds two raw IMU streams named `first` and `second`; their ids (-1 when refused).
std::pair<int, int> add_two_streams(SessionLogWriter& writer, const std::string& first,
                                    const std::string& second) {
  ImuStreamInfo a = test_raw_imu_info(), b = test_raw_imu_info();
  a.name = first;
  b.name = second;
  const auto id_a = writer.add_imu_stream(a);
  const auto id_b = writer.add_imu_stream(b);
  EXPECT_TRUE(id_a.ok() && id_b.ok());
  return {id_a.ok() ? *id_a : -1, id_b.ok() ? *id_b : -1};
}

std::vector<std::pair<TimeNs, double>> whole_stream(const SessionLogReader& reader, int id) {
  auto samples = reader.read_imu(id);
  EXPECT_TRUE(samples.ok()) << samples.error().message;
  std::vector<std::pair<TimeNs, double>> out;
  if (samples.ok())
    for (const auto& s : *samples) out.emplace_back(s.t_ns, s.accel.x());
  return out;
}

// A whole stream is read in storage order when the table holds it in time order, and through
// the time index when it does not: both give time order, equal times in the order written.
// A staged writer (imports: no journal, one sync at close) leaves the same log.
TEST(SessionLog, WholeStreamReadsAreInTimeOrderWhateverTheStorageOrder) {
  for (const bool staged : {false, true}) {
    const std::string path = scratch_dir() + (staged ? "/staged.imulog" : "/direct.imulog");
    int in_order = 0, shuffled = 0;
    {
      SessionLogWriterOptions options;
      options.staged = staged;
      auto writer = SessionLogWriter::create(path, options);
      ASSERT_TRUE(writer.ok()) << writer.error().message;
      std::tie(in_order, shuffled) = add_two_streams(**writer, "a", "b");
      // Interleaved batches; stream a has equal times, b a late batch.
      const std::vector<std::pair<int, std::vector<TimeNs>>> batches = {
          {in_order, {0, 100, 100}}, {shuffled, {500, 600}}, {in_order, {100, 200}}, {shuffled, {300, 400}}};
      double mark = 0.0;
      for (const auto& [id, times] : batches) {
        for (const TimeNs t : times) {
          ImuSample s;
          s.t_ns = t;
          s.accel.x() = mark++;
          ASSERT_TRUE((*writer)->append_imu(id, s).ok());
        }
      }
      ASSERT_TRUE((*writer)->close().ok());
    }
    auto reader = SessionLogReader::open(path);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    EXPECT_TRUE((*reader)->health().complete);
    EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
    using Row = std::pair<TimeNs, double>;
    EXPECT_EQ(whole_stream(**reader, in_order),
              (std::vector<Row>{{0, 0}, {100, 1}, {100, 2}, {100, 5}, {200, 6}}))
        << (staged ? "staged" : "direct");
    EXPECT_EQ(whole_stream(**reader, shuffled), (std::vector<Row>{{300, 7}, {400, 8}, {500, 3}, {600, 4}}))
        << (staged ? "staged" : "direct");
    // A reader that keeps the samples of its table check serves the same reads from them, hands
    // them over once, and then reads the file again.
    SessionLogReaderOptions preload;
    preload.preload_imu = true;
    auto held = SessionLogReader::open(path, preload);
    ASSERT_TRUE(held.ok()) << held.error().message;
    EXPECT_FALSE((*held)->health().damaged) << (*held)->health().damage_message;
    for (const int id : {in_order, shuffled}) {
      SCOPED_TRACE(std::string(staged ? "staged" : "direct") + ", stream " + std::to_string(id));
      const auto want = (*reader)->read_imu(id);
      ASSERT_TRUE(want.ok()) << want.error().message;
      EXPECT_EQ(whole_stream(**held, id), whole_stream(**reader, id));
      EXPECT_EQ(range_times(**held, id, 100, 500), range_times(**reader, id, 100, 500));
      for (int take = 0; take < 2; ++take) {
        const auto taken = (*held)->take_imu(id);
        ASSERT_TRUE(taken.ok()) << taken.error().message;
        expect_same_samples(*taken, *want);
      }
    }
    // The time index exists in both, and is what a time-range read uses.
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
    sqlite3_stmt* stmt = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT count(*) FROM sqlite_schema WHERE name='imu_samples_by_time'",
                                 -1, &stmt, nullptr),
              SQLITE_OK);
    ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
    EXPECT_EQ(sqlite3_column_int(stmt, 0), 1) << (staged ? "staged" : "direct");
    sqlite3_finalize(stmt);
    sqlite3_close(db);
  }
}

// A reader that keeps the samples walks a large table in two parts at once (the second after the
// index, on a connection of its own) and joins them: a stream whose only step back in time falls
// between the parts is still found out of order, and every read gives time order, with or
// without the samples kept.
TEST(SessionLog, ATableWalkedInTwoPartsIsOneWalk) {
  const std::string path = scratch_dir() + "/two-parts.imulog";
  int x = 0, y = 0;
  {
    auto writer = SessionLogWriter::create(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    std::tie(x, y) = add_two_streams(**writer, "x", "y");
    // 6000 rows of x late in time, 6000 of y, then 10 of x early: the table's first half holds
    // x in order, its second half too, and x steps back only between them.
    const auto append = [&](int id, TimeNs from, int count) {
      std::vector<ImuSample> batch(static_cast<std::size_t>(count));
      for (int i = 0; i < count; ++i) {
        batch[static_cast<std::size_t>(i)].t_ns = from + i;
        batch[static_cast<std::size_t>(i)].accel.x() = static_cast<double>(from + i);
      }
      ASSERT_TRUE((*writer)->append_imu(id, batch).ok());
    };
    append(x, 100000, 6000);
    append(y, 0, 6000);
    append(x, 0, 10);
    ASSERT_TRUE((*writer)->close().ok());
  }
  std::vector<std::pair<TimeNs, double>> want_x;
  for (TimeNs t = 0; t < 10; ++t) want_x.emplace_back(t, static_cast<double>(t));
  for (TimeNs t = 100000; t < 106000; ++t) want_x.emplace_back(t, static_cast<double>(t));
  for (const bool preload : {false, true}) {
    SCOPED_TRACE(preload ? "preloaded" : "plain");
    SessionLogReaderOptions options;
    options.preload_imu = preload;
    auto reader = SessionLogReader::open(path, options);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
    EXPECT_EQ(whole_stream(**reader, x), want_x);
    const auto ys = whole_stream(**reader, y);
    ASSERT_EQ(ys.size(), 6000u);
    for (std::size_t i = 0; i < ys.size(); ++i) ASSERT_EQ(ys[i].first, static_cast<TimeNs>(i));
    const auto taken = (*reader)->take_imu(x);
    ASSERT_TRUE(taken.ok()) << taken.error().message;
    ASSERT_EQ(taken->size(), want_x.size());
    for (std::size_t i = 0; i < want_x.size(); ++i) ASSERT_EQ((*taken)[i].t_ns, want_x[i].first) << i;
  }
}

TEST(SessionLog, RefusesToOverwriteUnlessAsked) {
  const std::string path = scratch_dir() + "/exists.imulog";
  {
    auto writer = SessionLogWriter::create(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    (void)(*writer)->add_imu_stream(test_raw_imu_info());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto again = SessionLogWriter::create(path);
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, Errc::kAlreadyExists);
  EXPECT_NE(again.error().message.find("already exists"), std::string::npos) << again.error().message;
  ASSERT_TRUE(SessionLogReader::open(path).ok());  // untouched
  EXPECT_EQ((*SessionLogReader::open(path))->imu_streams().size(), 1u);

  SessionLogWriterOptions options;
  options.overwrite = true;
  auto replaced = SessionLogWriter::create(path, options);
  ASSERT_TRUE(replaced.ok()) << replaced.error().message;
  ASSERT_TRUE((*replaced)->close().ok());
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->imu_streams().empty());
}

TEST(SessionLog, WriterRejectsMisuse) {
  const std::string path = scratch_dir() + "/misuse.imulog";
  auto writer = SessionLogWriter::create(path);
  ASSERT_TRUE(writer.ok()) << writer.error().message;
  auto& w = **writer;
  const int id = *w.add_imu_stream(test_raw_imu_info());
  EXPECT_FALSE(w.add_imu_stream(test_raw_imu_info()).ok());  // duplicate name
  EXPECT_FALSE(w.set_metadata("complete", "1").ok());
  EXPECT_FALSE(w.set_metadata("schema_version", "9").ok());
  EXPECT_FALSE(w.append_imu(id + 7, ImuSample{}).ok());
  EXPECT_FALSE(w.append_frame(id, CameraFrame{}).ok());  // an IMU id is not a camera
  ASSERT_TRUE(w.close().ok());
  EXPECT_FALSE(w.append_imu(id, ImuSample{}).ok());
  EXPECT_FALSE(w.close().ok());
  EXPECT_FALSE(SessionLogWriter::create(scratch_dir() + "/no/such/dir/x.imulog").ok());
}

// One writer per log: while a writer has it, a second one is refused (replacing it or not) with
// the holder named, and the first's data stays; once closed, --force may replace it.
TEST(SessionLog, ASecondWriterIsRefusedWhileTheFirstWrites) {
  const std::string path = scratch_dir() + "/busy.imulog";
  auto first = SessionLogWriter::create(path);
  ASSERT_TRUE(first.ok()) << first.error().message;
  const int id = *(*first)->add_imu_stream(test_raw_imu_info());
  ASSERT_TRUE((*first)->append_imu(id, make_raw_samples(50, 0)).ok());

  EXPECT_EQ(SessionLogWriter::create(path).error().code, Errc::kAlreadyExists);
  SessionLogWriterOptions force;
  force.overwrite = true;
  auto second = SessionLogWriter::create(path, force);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.error().code, Errc::kIo);
  const std::string pid = std::to_string(::getpid());
  EXPECT_NE(second.error().message.find("is being written by process " + pid), std::string::npos)
      << second.error().message;

  ASSERT_TRUE((*first)->append_imu(id, make_raw_samples(50, 50'000'000, 50)).ok());
  ASSERT_TRUE((*first)->close().ok());
  {
    auto reader = SessionLogReader::open(path);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    EXPECT_TRUE((*reader)->health().complete);
    EXPECT_EQ(*(*reader)->imu_count(id), 100);
  }
  auto replaced = SessionLogWriter::create(path, force);
  ASSERT_TRUE(replaced.ok()) << replaced.error().message;
  ASSERT_TRUE((*replaced)->close().ok());
}

// Readers of a log being written, in another process (which tests the writer's lock with a
// shared one for an instant) and in this one (which must not open and close the file beside
// SQLite), see every commit so far and leave the writer undisturbed.
TEST(SessionLog, ReadersOfALiveLogLeaveItsWriterUndisturbed) {
  const std::string path = scratch_dir() + "/live.imulog";
  auto writer = SessionLogWriter::create(path);
  ASSERT_TRUE(writer.ok()) << writer.error().message;
  const int id = *(*writer)->add_imu_stream(test_raw_imu_info());
  for (int round = 0; round < 4; ++round) {
    ASSERT_TRUE((*writer)->append_imu(id, make_raw_samples(100, round * 100'000'000, round * 100)).ok());
    ASSERT_TRUE((*writer)->flush().ok());
    const auto info = test::run_cli({"info", path, "--json"}, 60);
    ASSERT_EQ(info.exit_code, 0) << info.err;
    const auto json = nlohmann::json::parse(info.out);
    EXPECT_FALSE(json["complete"].get<bool>());
    EXPECT_FALSE(json["damaged"].get<bool>()) << json["damage_message"];
    EXPECT_EQ(json["imu_streams"][0]["count"].get<std::int64_t>(), 100 * (round + 1));
    auto here = SessionLogReader::open(path);
    ASSERT_TRUE(here.ok()) << here.error().message;
    EXPECT_EQ(*(*here)->imu_count(id), 100 * (round + 1));
  }
  // Still the only writer: a second one is refused, and this one closes a complete log.
  EXPECT_EQ(SessionLogWriter::create(path).error().code, Errc::kAlreadyExists);
  ASSERT_TRUE((*writer)->close().ok());
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  EXPECT_EQ(*(*reader)->imu_count(id), 400);
}

// A reader inside a read transaction when the writer closes keeps the final checkpoint from
// finishing: the log is complete all the same (its commits are in the -wal), and close() says so.
TEST(SessionLog, CloseSucceedsWhileAReaderHoldsAReadTransaction) {
  const std::string path = scratch_dir() + "/read-at-close.imulog";
  auto writer = SessionLogWriter::create(path);
  ASSERT_TRUE(writer.ok()) << writer.error().message;
  const int id = *(*writer)->add_imu_stream(test_raw_imu_info());
  ASSERT_TRUE((*writer)->append_imu(id, make_raw_samples(200, 0)).ok());
  ASSERT_TRUE((*writer)->flush().ok());
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "SELECT count(*) FROM imu_samples", nullptr, nullptr, nullptr), SQLITE_OK);
  ASSERT_TRUE((*writer)->append_imu(id, make_raw_samples(100, 200'000'000, 200)).ok());
  const Status closed = (*writer)->close();
  EXPECT_TRUE(closed.ok()) << closed.error().message;
  sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr);
  sqlite3_close(db);
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  EXPECT_EQ(*(*reader)->imu_count(id), 300);
}

// Without close(), the destructor keeps what was appended but the log stays incomplete.
TEST(SessionLog, DestructorWithoutCloseKeepsDataIncomplete) {
  const std::string path = scratch_dir() + "/unclosed.imulog";
  SessionLogWriterOptions options;
  options.commit_interval_ns = 3600 * kNsPerSecond;
  {
    auto writer = SessionLogWriter::create(path, options);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    const int id = *(*writer)->add_imu_stream(test_raw_imu_info());
    ASSERT_TRUE((*writer)->append_imu(id, make_raw_samples(123, 0)).ok());
  }
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->health().complete);
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  EXPECT_EQ(*(*reader)->imu_count(*(*reader)->find_imu_stream()), 123);
}

// A writer fed faster than the wall clock (the service's virtual rig at time-scale 0) and killed
// within its first commit interval: its metadata, stream and first samples were committed at
// once, and every further 0.5 s of sample time, with the default options. Before, nothing after
// the schema was committed for the first 0.5 s of wall time: the log had no stream and no sample.
TEST(SessionLog, AWriterFedFasterThanRealTimeCommitsByDataFromItsFirstSamples) {
  const std::string path = scratch_dir() + "/killed-early.imulog";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    auto writer = SessionLogWriter::create(path);
    if (!writer.ok()) _exit(10);
    if (!(*writer)->set_metadata("rig_config", "{}").ok()) _exit(11);
    auto id = (*writer)->add_imu_stream(test_raw_imu_info());
    if (!id.ok()) _exit(12);
    // 3 s of samples at 1 kHz, in batches as the acquisition hands them over: far less than
    // the 0.5 s of wall time the old writer waited for before its first commit.
    for (int batch = 0; batch < 30; ++batch) {
      if (!(*writer)->append_imu(*id, make_raw_samples(100, batch * 100'000'000LL, batch * 100)).ok())
        _exit(13);
    }
    _exit(0);  // killed: nothing closed, nothing destroyed
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0);
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->health().complete);
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  EXPECT_TRUE((*reader)->metadata().contains("rig_config"));
  auto stream = (*reader)->find_imu_stream();
  ASSERT_TRUE(stream.ok()) << stream.error().message;
  // Committed: the first batch at once, then every 0.5 s of sample time.
  EXPECT_GE(*(*reader)->imu_count(*stream), 2500);
}

}  // namespace
}  // namespace imucal::log
