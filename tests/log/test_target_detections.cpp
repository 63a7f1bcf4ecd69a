// SPDX-License-Identifier: BSD-3-Clause
// Stored target detections in a session log: round trip, replacement, what they leave alone, and
// logs they must not write into.

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "log/session_log.hpp"
#include "log/target_detections.hpp"
#include "tests/support/session_log_util.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::log {
namespace {

using test::scratch_dir;

/// A closed log with one IMU stream (id 1) and one camera stream (id 2) of three frames.
std::string make_log(const std::string& dir) {
  const std::string path = dir + "/cam.imulog";
  auto w = SessionLogWriter::create(path);
  EXPECT_TRUE(w.ok());
  EXPECT_TRUE((*w)->add_imu_stream(test::test_raw_imu_info()).ok());
  CameraStreamInfo cam;
  cam.name = "cam0";
  cam.width = 4;
  cam.height = 2;
  auto id = (*w)->add_camera_stream(cam);
  EXPECT_TRUE(id.ok());
  EXPECT_TRUE((*w)->append_imu(1, test::make_raw_samples(100, 0)).ok());
  for (int i = 0; i < 3; ++i) {
    CameraFrame f;
    f.t_ns = i * 50'000'000;
    f.width = 4;
    f.height = 2;
    f.encoding = "gray8";
    f.data.assign(8, static_cast<std::uint8_t>(i));
    EXPECT_TRUE((*w)->append_frame(*id, f).ok());
  }
  EXPECT_TRUE((*w)->close().ok());
  return path;
}

DetectionSet sample_set(const std::string& key) {
  DetectionSet set;
  set.target_key = key;
  set.description = "target_type: checkerboard";
  set.frames = 3;
  set.detections = {{0, R"({"a":1})"}, {100'000'000, R"({"a":2,"text":"\u00e9"})"}};
  return set;
}

std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// The schema SQL of the tables a recording writes, as a fingerprint of what must not change.
std::string recorded_schema(const std::string& path) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db,
                     "SELECT group_concat(sql, ';') FROM (SELECT sql FROM sqlite_schema WHERE name NOT LIKE "
                     "'target_detection%' ORDER BY name)",
                     -1, &stmt, nullptr);
  std::string out;
  if (sqlite3_step(stmt) == SQLITE_ROW) out = reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0));
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return out;
}

TEST(TargetDetections, RoundTripLeavesTheRecordingAlone) {
  const std::string path = make_log(scratch_dir());
  const std::string schema_before = recorded_schema(path);
  auto none = read_target_detections(path, 2, "k1");
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_FALSE(none->has_value());  // a log from before the tables existed

  ASSERT_TRUE(write_target_detections(path, 2, sample_set("k1")).ok());
  auto got = read_target_detections(path, 2, "k1");
  ASSERT_TRUE(got.ok()) << got.error().message;
  ASSERT_TRUE(got->has_value());
  const DetectionSet& set = **got;
  EXPECT_EQ(set.frames, 3);
  EXPECT_EQ(set.description, "target_type: checkerboard");
  EXPECT_FALSE(set.created_utc.empty());
  ASSERT_EQ(set.detections.size(), 2u);
  EXPECT_EQ(set.detections[1].t_ns, 100'000'000);
  EXPECT_EQ(set.detections[1].data, sample_set("k1").detections[1].data);

  // Other keys and streams have nothing; the recorded tables and the reader are unchanged.
  EXPECT_FALSE(read_target_detections(path, 2, "k2")->has_value());
  EXPECT_FALSE(read_target_detections(path, 1, "k1")->has_value());
  EXPECT_EQ(recorded_schema(path), schema_before);
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  EXPECT_TRUE((*reader)->health().complete);
  EXPECT_EQ(*(*reader)->frame_count(2), 3);
  EXPECT_EQ(*(*reader)->imu_count(1), 100);
  // A closed log stays one self-contained file.
  EXPECT_FALSE(std::filesystem::exists(path + "-wal"));
  EXPECT_FALSE(std::filesystem::exists(path + "-journal"));
}

TEST(TargetDetections, ASecondSetWithTheSameKeyReplacesTheFirst) {
  const std::string path = make_log(scratch_dir());
  ASSERT_TRUE(write_target_detections(path, 2, sample_set("k1")).ok());
  ASSERT_TRUE(write_target_detections(path, 2, sample_set("k2")).ok());
  DetectionSet again = sample_set("k1");
  again.detections.resize(1);
  again.frames = 7;
  ASSERT_TRUE(write_target_detections(path, 2, again).ok());
  auto k1 = read_target_detections(path, 2, "k1");
  ASSERT_TRUE(k1.ok() && k1->has_value());
  EXPECT_EQ((**k1).frames, 7);
  EXPECT_EQ((**k1).detections.size(), 1u);
  auto k2 = read_target_detections(path, 2, "k2");
  ASSERT_TRUE(k2.ok() && k2->has_value());
  EXPECT_EQ((**k2).detections.size(), 2u);
}

TEST(TargetDetections, WritesWhileAReaderHasTheLogOpen) {
  const std::string path = make_log(scratch_dir());
  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  ASSERT_TRUE(write_target_detections(path, 2, sample_set("k1")).ok());
  int frames = 0;
  ASSERT_TRUE((*reader)
                  ->for_each_frame(2, kTimeMin, kTimeMax, [&](const CameraFrame&) { return ++frames > 0; })
                  .ok());
  EXPECT_EQ(frames, 3);
}

TEST(TargetDetections, ARefusedWriteLeavesAReadOnlyLogAsItWas) {
  const std::string dir = scratch_dir();
  const std::string path = make_log(dir);
  ASSERT_EQ(chmod(path.c_str(), 0444), 0);
  const std::string before = file_bytes(path);
  // Root writes read-only files: the write runs in a child process as an unprivileged user.
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (geteuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0)) _exit(20);
    const Status s = write_target_detections(path, 2, sample_set("k1"));
    if (s.ok()) _exit(1);
    if (s.error().code != Errc::kIo || s.error().message.find("read-only") == std::string::npos) _exit(2);
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  if (WEXITSTATUS(status) == 20)
    GTEST_SKIP() << "cannot drop to an unprivileged user to make the log read-only";
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: the write succeeded, 2: wrong error";
  EXPECT_EQ(file_bytes(path), before);
  EXPECT_FALSE(std::filesystem::exists(path + "-journal"));
}

TEST(TargetDetections, RefusesFilesThatAreNotLogs) {
  const std::string dir = scratch_dir();
  const std::string other = dir + "/other.db";
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(other.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "CREATE TABLE t(x)", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  const std::string before = file_bytes(other);
  const Status s = write_target_detections(other, 2, sample_set("k1"));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kCorrupt);
  EXPECT_EQ(file_bytes(other), before);
  auto missing = read_target_detections(dir + "/missing.imulog", 2, "k1");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::kNotFound);
  EXPECT_FALSE(std::filesystem::exists(dir + "/missing.imulog"));
  EXPECT_FALSE(write_target_detections(make_log(dir), 2, sample_set("")).ok());
}

// The cache file: created with its folder on the first write, read back exactly, a missing one
// reads as "none"; a log is not taken for a cache nor a cache for a log.
TEST(DetectionCache, RoundTripAndFileKinds) {
  const std::string dir = scratch_dir();
  const std::string cache = dir + "/cache/detections/0123456789abcdef.sqlite";
  auto none = read_detection_cache(cache, "k1");
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_FALSE(none->has_value());
  EXPECT_FALSE(std::filesystem::exists(cache));
  ASSERT_TRUE(write_detection_cache(cache, sample_set("k1")).ok());
  auto back = read_detection_cache(cache, "k1");
  ASSERT_TRUE(back.ok() && back->has_value());
  EXPECT_EQ((*back)->frames, 3);
  ASSERT_EQ((*back)->detections.size(), 2u);
  EXPECT_EQ((*back)->detections[1].data, sample_set("k1").detections[1].data);
  EXPECT_FALSE(read_detection_cache(cache, "k2")->has_value());

  const std::string log = make_log(dir);
  const std::string before = file_bytes(log);
  const Status s = write_detection_cache(log, sample_set("k1"));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kCorrupt);
  EXPECT_EQ(file_bytes(log), before);
  EXPECT_FALSE(read_detection_cache(log, "k1").ok());
  const Status t = write_target_detections(cache, 0, sample_set("k3"));
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.error().code, Errc::kCorrupt);
}

// A log without write permission is not written by root either (before: root, whom the mode does
// not stop, stored the detections in a 0444 log).
TEST(TargetDetections, ALogWithoutWritePermissionIsNotWrittenByRootEither) {
  const std::string path = make_log(scratch_dir());
  ASSERT_EQ(chmod(path.c_str(), 0444), 0);
  const std::string before = file_bytes(path);
  const Status s = write_target_detections(path, 2, sample_set("k1"));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kIo);
  EXPECT_NE(s.error().message.find("read-only"), std::string::npos) << s.error().message;
  EXPECT_EQ(file_bytes(path), before);
}

// The cache is never reached through a symbolic link (before: the link was followed and the file
// it named written), nor is anything but a regular file opened at its path.
TEST(DetectionCache, ASymbolicLinkAtTheCachePathIsNotFollowed) {
  const std::string dir = scratch_dir();
  const std::string elsewhere = dir + "/elsewhere.sqlite";
  ASSERT_TRUE(write_detection_cache(elsewhere, sample_set("k1")).ok());
  const std::string before = file_bytes(elsewhere);
  const std::string link = dir + "/cache.sqlite";
  std::filesystem::create_symlink(elsewhere, link);
  const Status s = write_detection_cache(link, sample_set("k2"));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kIo);
  EXPECT_NE(s.error().message.find("is a symbolic link"), std::string::npos) << s.error().message;
  EXPECT_EQ(file_bytes(elsewhere), before);
  EXPECT_FALSE(read_detection_cache(link, "k1").ok());
  const std::string fifo = dir + "/fifo.sqlite";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const Status f = write_detection_cache(fifo, sample_set("k2"));
  ASSERT_FALSE(f.ok());
  EXPECT_NE(f.error().message.find("not a regular file"), std::string::npos) << f.error().message;
}

// A damaged cache file (garbage, or a cache cut short) is replaced by a new one holding the set
// (before: every later write was refused as "not a detection cache", for good).
TEST(DetectionCache, ADamagedCacheIsReplaced) {
  const std::string dir = scratch_dir();
  const std::string garbage = dir + "/garbage.sqlite";
  {
    std::ofstream out(garbage, std::ios::binary);
    out << std::string(4096, 'x');
  }
  const Status g = write_detection_cache(garbage, sample_set("k1"));
  ASSERT_TRUE(g.ok()) << g.error().message;
  auto back = read_detection_cache(garbage, "k1");
  ASSERT_TRUE(back.ok() && back->has_value()) << (back.ok() ? "none" : back.error().message);
  EXPECT_EQ((*back)->detections.size(), 2u);

  const std::string cut = dir + "/cut.sqlite";
  ASSERT_TRUE(write_detection_cache(cut, sample_set("k1")).ok());
  std::filesystem::resize_file(cut, 100);
  const Status c = write_detection_cache(cut, sample_set("k2"));
  ASSERT_TRUE(c.ok()) << c.error().message;
  auto again = read_detection_cache(cut, "k2");
  ASSERT_TRUE(again.ok() && again->has_value()) << (again.ok() ? "none" : again.error().message);
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    EXPECT_EQ(entry.path().string().find(".new-"), std::string::npos) << entry.path();
}

// The stream's fingerprint names its content: equal for a copy, different once a frame changes.
TEST(DetectionCache, FrameFingerprintFollowsTheContent) {
  const std::string dir = scratch_dir();
  const std::string log = make_log(dir);
  const std::string copy = dir + "/copy.imulog";
  std::filesystem::copy_file(log, copy);
  auto fingerprint = [](const std::string& path) {
    auto r = SessionLogReader::open(path);
    EXPECT_TRUE(r.ok());
    auto f = (*r)->frame_fingerprint(2);
    EXPECT_TRUE(f.ok());
    return f.ok() ? *f : 0;
  };
  const std::uint64_t a = fingerprint(log);
  EXPECT_EQ(fingerprint(copy), a);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(copy.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE frames SET data_crc32 = data_crc32 + 1 WHERE t_ns = 50000000", nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  EXPECT_NE(fingerprint(copy), a);
  auto r = SessionLogReader::open(log);
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE((*r)->frame_fingerprint(7).ok());
}

}  // namespace
}  // namespace imucal::log
