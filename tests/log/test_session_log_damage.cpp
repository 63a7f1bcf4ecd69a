// SPDX-License-Identifier: BSD-3-Clause
// Session log: files that are not logs, newer schemas, truncated and overwritten files, and a
// writer that dies mid-recording.

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>

#include "log/session_log.hpp"
#include "tests/support/session_log_util.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::log {
namespace {

using namespace imucal::test;  // shared session-log helpers (tests/support)

namespace fs = std::filesystem;
using test::scratch_dir;

constexpr int kSamples = 6000;
constexpr int kFrames = 12;
constexpr TimeNs kT0 = 5'000'000'000;

// A closed log with one raw IMU stream (kSamples at 1 kHz), one camera stream whose frames
// span several pages each, and events. Returns the samples written.
std::vector<ImuSample> write_reference_log(const std::string& path) {
  auto writer = SessionLogWriter::create(path);
  EXPECT_TRUE(writer.ok()) << writer.error().message;
  auto& w = **writer;
  const int imu = *w.add_imu_stream(test_raw_imu_info());
  CameraStreamInfo cam_info;
  cam_info.width = 100;
  cam_info.height = 90;
  const int cam = *w.add_camera_stream(cam_info);
  const auto samples = make_raw_samples(kSamples, kT0);
  for (int f = 0; f < kFrames; ++f) {
    const auto begin = samples.begin() + f * (kSamples / kFrames);
    EXPECT_TRUE(w.append_imu(imu, std::span<const ImuSample>(&*begin, kSamples / kFrames)).ok());
    CameraFrame frame;
    frame.t_ns = begin->t_ns;
    frame.width = 100;
    frame.height = 90;
    frame.encoding = "gray8";
    frame.data.assign(9000, static_cast<std::uint8_t>(f));
    frame.sequence = static_cast<std::uint32_t>(f);
    EXPECT_TRUE(w.append_frame(cam, frame).ok());
    EXPECT_TRUE(w.append_event({frame.t_ns, "note", "frame " + std::to_string(f)}).ok());
  }
  EXPECT_TRUE(w.close().ok());
  return samples;
}

void copy_prefix(const std::string& from, const std::string& to, std::uintmax_t bytes) {
  fs::copy_file(from, to, fs::copy_options::overwrite_existing);
  fs::resize_file(to, bytes);
}

// Whatever a damaged log yields must be genuine: samples in time order, each equal to the one
// written at that time.
void expect_genuine(const SessionLogReader& reader, const std::vector<ImuSample>& written,
                    std::int64_t* read_count) {
  std::map<TimeNs, const ImuSample*> by_time;
  for (const auto& s : written) by_time[s.t_ns] = &s;
  *read_count = 0;
  if (reader.imu_streams().empty()) return;
  const int id = reader.imu_streams().begin()->first;
  auto samples = reader.read_imu(id);
  ASSERT_TRUE(samples.ok()) << samples.error().message;
  TimeNs last = kTimeMin;
  for (const auto& s : *samples) {
    EXPECT_GE(s.t_ns, last);
    last = s.t_ns;
    const auto it = by_time.find(s.t_ns);
    ASSERT_NE(it, by_time.end()) << "a sample that was never written, t_ns=" << s.t_ns;
    expect_same_samples({s}, {*it->second});
  }
  *read_count = static_cast<std::int64_t>(samples->size());
  // Frames that come back carry their own data.
  for (const auto& [cam, info] : reader.camera_streams()) {
    Status status = reader.for_each_frame(cam, kTimeMin, kTimeMax, [](const CameraFrame& f) {
      EXPECT_EQ(f.data, std::vector<std::uint8_t>(9000, static_cast<std::uint8_t>(f.sequence)));
      return true;
    });
    (void)status;  // damage met while reading is reported, and is allowed here
  }
}

TEST(SessionLogDamage, TruncatedAtAnyOffsetNeverCrashesAndKeepsWhatIsReadable) {
  const std::string dir = scratch_dir();
  const std::string path = dir + "/full.imulog";
  const auto written = write_reference_log(path);
  const auto size = fs::file_size(path);
  ASSERT_GT(size, 100'000u);
  std::int64_t best_partial = 0;
  for (const double fraction : {0.0, 0.00002, 0.003, 0.02, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99}) {
    const auto bytes = static_cast<std::uintmax_t>(fraction * static_cast<double>(size));
    SCOPED_TRACE("truncated to " + std::to_string(bytes) + " of " + std::to_string(size) + " bytes");
    const std::string cut = dir + "/cut.imulog";
    copy_prefix(path, cut, bytes);
    auto reader = SessionLogReader::open(cut);
    if (!reader.ok()) {
      EXPECT_EQ(reader.error().code, Errc::kCorrupt);
      EXPECT_FALSE(reader.error().message.empty());
      continue;
    }
    EXPECT_TRUE((*reader)->health().damaged);
    EXPECT_NE((*reader)->health().damage_message.find("truncated"), std::string::npos)
        << (*reader)->health().damage_message;
    std::int64_t count = 0;
    expect_genuine(**reader, written, &count);
    EXPECT_LE(count, kSamples);
    best_partial = std::max(best_partial, count);
  }
  // Cutting off the tail must not lose the head.
  EXPECT_GT(best_partial, kSamples / 2);
}

TEST(SessionLogDamage, GarbagePagesAreReportedAndNeverCrash) {
  const std::string dir = scratch_dir();
  const std::string path = dir + "/full.imulog";
  const auto written = write_reference_log(path);
  const auto size = fs::file_size(path);
  constexpr std::size_t kPage = 4096;
  const std::size_t pages = size / kPage;
  std::mt19937 rng(1234);
  for (const double fraction : {0.3, 0.5, 0.7, 0.95}) {
    const std::string bad = dir + "/bad.imulog";
    fs::copy_file(path, bad, fs::copy_options::overwrite_existing);
    const auto page = static_cast<std::size_t>(fraction * static_cast<double>(pages));
    SCOPED_TRACE("garbage over pages " + std::to_string(page) + ".." + std::to_string(page + 2) + " of " +
                 std::to_string(pages));
    {
      std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(static_cast<std::streamoff>(page * kPage));
      std::string garbage(3 * kPage, '\0');
      for (auto& c : garbage) c = static_cast<char>(rng());
      f.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
    }
    auto reader = SessionLogReader::open(bad);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    std::int64_t count = 0;
    expect_genuine(**reader, written, &count);
    EXPECT_TRUE((*reader)->health().damaged) << "read " << count << " samples";
    EXPECT_FALSE((*reader)->health().damage_message.empty());
    // Three pages hold at most about 250 samples; rows behind the damage are found again.
    EXPECT_GT(count, kSamples - 300) << (*reader)->health().damage_message;
  }
}

// What a damaged variant of the reference log gave the reader.
enum class Outcome { kRefused, kIntact, kReported };

// The reader's promise, checked after every read (a frame failing its CRC is noted as it is
// read): a log that reads as undamaged yields every sample and frame that was written.
Outcome read_variant(const std::string& path, std::int64_t* samples_read) {
  auto reader = SessionLogReader::open(path);
  *samples_read = 0;
  if (!reader.ok()) {
    EXPECT_FALSE(reader.error().message.empty());
    return Outcome::kRefused;
  }
  const SessionLogReader& r = **reader;
  std::int64_t frames = 0;
  for (const auto& [id, info] : r.imu_streams()) {
    (void)r.for_each_imu(id, kTimeMin, kTimeMax, [&](const ImuSample&) {
      ++*samples_read;
      return true;
    });
  }
  for (const auto& [id, info] : r.camera_streams()) {
    (void)r.for_each_frame(id, kTimeMin, kTimeMax, [&](const CameraFrame&) {
      ++frames;
      return true;
    });
  }
  // A reader that keeps the samples of its table check (as calibrations open logs) yields the
  // same samples from a log that reads as undamaged, and finds no damage in it either.
  SessionLogReaderOptions preload;
  preload.preload_imu = true;
  auto held = r.health().damaged ? Result<std::unique_ptr<SessionLogReader>>(nullptr)
                                 : SessionLogReader::open(path, preload);
  EXPECT_TRUE(held.ok()) << held.error().message;
  if (held.ok() && *held) {
    EXPECT_FALSE((*held)->health().damaged) << (*held)->health().damage_message;
    for (const auto& [id, info] : r.imu_streams()) {
      const auto taken = (*held)->take_imu(id);
      EXPECT_TRUE(taken.ok()) << taken.error().message;
      if (!taken.ok()) continue;
      std::vector<ImuSample> want;
      EXPECT_TRUE(r.for_each_imu(id, kTimeMin, kTimeMax, [&](const ImuSample& s) {
                     want.push_back(s);
                     return true;
                   }).ok());
      expect_same_samples(*taken, want);
    }
  }
  if (r.health().damaged) {
    EXPECT_FALSE(r.health().damage_message.empty());
    return Outcome::kReported;
  }
  EXPECT_EQ(*samples_read, kSamples) << "samples lost without a report";
  EXPECT_EQ(frames, kFrames) << "frames lost without a report";
  return Outcome::kIntact;
}

// Every page of the log overwritten with garbage in turn, and single bytes flipped at 400
// places: the reader never loses a sample or frame without saying so. The counts are in
// docs/session-log.md.
TEST(SessionLogDamage, DamageMatrixNeverLosesDataSilently) {
  const std::string dir = scratch_dir();
  const std::string path = dir + "/full.imulog";
  write_reference_log(path);
  const auto size = fs::file_size(path);
  constexpr std::size_t kPage = 4096;
  const std::size_t pages = size / kPage;
  std::mt19937 rng(77);
  std::map<Outcome, int> by_page, by_flip;
  int salvaged_pages = 0;
  const std::string bad = dir + "/bad.imulog";
  for (std::size_t page = 0; page < pages; ++page) {
    fs::copy_file(path, bad, fs::copy_options::overwrite_existing);
    {
      std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(static_cast<std::streamoff>(page * kPage));
      std::string garbage(kPage, '\0');
      for (auto& c : garbage) c = static_cast<char>(rng());
      f.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
    }
    SCOPED_TRACE("page " + std::to_string(page) + " of " + std::to_string(pages));
    std::int64_t n = 0;
    const Outcome o = read_variant(bad, &n);
    ++by_page[o];
    if (o == Outcome::kReported && n > 0) ++salvaged_pages;
  }
  for (int k = 0; k < 400; ++k) {
    fs::copy_file(path, bad, fs::copy_options::overwrite_existing);
    const auto at = static_cast<std::streamoff>(rng() % size);
    {
      std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
      f.seekg(at);
      char c = 0;
      f.get(c);
      f.seekp(at);
      f.put(static_cast<char>(c ^ (1 << (rng() % 8))));
    }
    SCOPED_TRACE("byte " + std::to_string(at) + " flipped");
    std::int64_t n = 0;
    ++by_flip[read_variant(bad, &n)];
  }
  std::printf(
      "damage matrix: %zu pages: %d refused, %d intact, %d reported (%d of them salvaged); 400 flips: "
      "%d refused, %d intact, %d reported\n",
      pages, by_page[Outcome::kRefused], by_page[Outcome::kIntact], by_page[Outcome::kReported],
      salvaged_pages, by_flip[Outcome::kRefused], by_flip[Outcome::kIntact], by_flip[Outcome::kReported]);
  // Most pages hold samples or frames: overwriting them must be seen.
  EXPECT_GT(by_page[Outcome::kReported] + by_page[Outcome::kRefused], static_cast<int>(pages) / 2);
}

TEST(SessionLogDamage, RejectsFilesThatAreNotLogs) {
  const std::string dir = scratch_dir();
  {
    std::ofstream(dir + "/text.imulog") << "t_ns,ax,ay,az\n1,2,3,4\n";
    std::ofstream(dir + "/empty.imulog");
  }
  for (const std::string name : {"text.imulog", "empty.imulog", "missing.imulog", ""}) {
    auto reader = SessionLogReader::open(dir + "/" + name);
    ASSERT_FALSE(reader.ok()) << name;
    EXPECT_FALSE(reader.error().message.empty());
    SCOPED_TRACE(reader.error().message);
    if (name == "text.imulog") {
      EXPECT_NE(reader.error().message.find("not a session log"), std::string::npos);
    }
    if (name == "empty.imulog") {
      EXPECT_NE(reader.error().message.find("empty"), std::string::npos);
    }
    if (name == "missing.imulog") {
      EXPECT_EQ(reader.error().code, Errc::kNotFound);
    }
    if (name.empty()) {
      EXPECT_NE(reader.error().message.find("directory"), std::string::npos);
    }
  }
  // An SQLite database that is something else.
  const std::string other = dir + "/other.db";
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(other.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "CREATE TABLE songs(title TEXT); INSERT INTO songs VALUES('x');", nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  auto reader = SessionLogReader::open(other);
  ASSERT_FALSE(reader.ok());
  EXPECT_NE(reader.error().message.find("not a session log"), std::string::npos) << reader.error().message;
}

TEST(SessionLogDamage, RejectsNewerSchemaWithAClearMessage) {
  const std::string path = scratch_dir() + "/future.imulog";
  {
    auto writer = SessionLogWriter::create(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    ASSERT_TRUE((*writer)->close().ok());
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  const std::string sql = "UPDATE metadata SET value='" + std::to_string(kSessionLogSchemaVersion + 1) +
                          "' WHERE key='schema_version'";
  ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  auto reader = SessionLogReader::open(path);
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.error().code, Errc::kCorrupt);
  EXPECT_NE(reader.error().message.find("update imucal"), std::string::npos) << reader.error().message;
}

// In a child process: a writer on `path` (commits only when asked) with one raw IMU stream, then
// `body`, then death without closing or destroying anything (a crash). Returns the child's exit
// code: body's, or 10 when the log could not be created.
int write_then_crash(const std::string& path, const std::function<int(SessionLogWriter&, int)>& body) {
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    SessionLogWriterOptions options;
    options.commit_interval_ns = 3600 * kNsPerSecond;
    options.commit_data_interval_ns = 0;
    auto writer = SessionLogWriter::create(path, options);
    if (!writer.ok()) _exit(10);
    const int id = *(*writer)->add_imu_stream(test_raw_imu_info());
    _exit(body(**writer, id));
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

// A writer process dies (no close, no destructor) after committing one batch and buffering a
// second: the first batch is readable, the second is lost, nothing is damaged.
TEST(SessionLogDamage, WriterCrashKeepsWhatWasCommitted) {
  const std::string path = scratch_dir() + "/crash.imulog";
  ASSERT_EQ(write_then_crash(path,
                             [](SessionLogWriter& w, int id) {
                               if (!w.set_metadata("rig", "bench").ok()) return 11;
                               if (!w.append_imu(id, make_raw_samples(3000, 0)).ok()) return 12;
                               if (!w.append_event({0, "note", "committed"}).ok()) return 13;
                               if (!w.flush().ok()) return 14;
                               if (!w.append_imu(id, make_raw_samples(500, 3'000'000'000, 3000)).ok())
                                 return 15;
                               return 0;
                             }),
            0);
  EXPECT_TRUE(fs::exists(path + "-wal"));

  auto reader = SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->health().complete);
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  EXPECT_EQ((*reader)->metadata().at("rig"), "bench");
  auto samples = (*reader)->read_imu(*(*reader)->find_imu_stream());
  ASSERT_TRUE(samples.ok()) << samples.error().message;
  expect_same_samples(*samples, make_raw_samples(3000, 0));
  EXPECT_EQ((*reader)->events()->size(), 1u);
  reader = Error{};  // close before the next open
  // Opening read-only changed nothing: a second reader sees the same.
  auto again = SessionLogReader::open(path);
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(*(*again)->imu_count(*(*again)->find_imu_stream()), 3000);
}

// A log whose writer died after five commits of 1000 samples each: its data is in its -wal.
std::string crashed_log_with_wal(const std::string& path) {
  EXPECT_EQ(
      write_then_crash(path,
                       [](SessionLogWriter& w, int id) {
                         for (int k = 0; k < 5; ++k) {
                           if (!w.append_imu(id, make_raw_samples(1000, k * 1'000'000'000LL, k * 1000)).ok())
                             return 11;
                           if (!w.flush().ok()) return 12;
                         }
                         return 0;
                       }),
      0);
  return path + "-wal";
}

std::int64_t samples_in(const SessionLogReader& r) {
  return r.imu_streams().empty() ? 0 : *r.imu_count(r.imu_streams().begin()->first);
}

// SQLite replays a -wal up to its first bad frame and ignores the rest without a word; the
// reader finds the commits that were lost and says so.
TEST(SessionLogDamage, ADamagedWriteAheadLogIsReported) {
  const std::string dir = scratch_dir();
  const std::string wal = crashed_log_with_wal(dir + "/crash.imulog");
  const auto wal_size = fs::file_size(wal);
  ASSERT_GT(wal_size, 100'000u);
  {
    auto intact = SessionLogReader::open(dir + "/crash.imulog");
    ASSERT_TRUE(intact.ok()) << intact.error().message;
    EXPECT_FALSE((*intact)->health().damaged) << (*intact)->health().damage_message;
    EXPECT_EQ(samples_in(**intact), 5000);
  }
  // One byte flipped in a page a third of the way in: the later commits are lost, and reported.
  const std::string flipped = dir + "/flipped.imulog";
  fs::copy_file(dir + "/crash.imulog", flipped);
  fs::copy_file(wal, flipped + "-wal");
  {
    std::fstream f(flipped + "-wal", std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(static_cast<std::streamoff>(wal_size / 3));
    char c = 0;
    f.get(c);
    f.seekp(static_cast<std::streamoff>(wal_size / 3));
    f.put(static_cast<char>(c ^ 0x10));
  }
  {
    auto r = SessionLogReader::open(flipped);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_TRUE((*r)->health().damaged);
    EXPECT_NE((*r)->health().damage_message.find("write-ahead log"), std::string::npos)
        << (*r)->health().damage_message;
    EXPECT_NE((*r)->health().damage_message.find("later commit(s)"), std::string::npos)
        << (*r)->health().damage_message;
    EXPECT_LT(samples_in(**r), 5000);
  }
  // Cut inside its last frame, as a writer that stops while committing leaves it (killed, a full
  // disk): the log reads as at its previous commit, incomplete, and is not called damaged.
  const std::string cut = dir + "/cut.imulog";
  fs::copy_file(dir + "/crash.imulog", cut);
  copy_prefix(wal, cut + "-wal", wal_size - 1000);
  {
    auto r = SessionLogReader::open(cut);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_FALSE((*r)->health().damaged) << (*r)->health().damage_message;
    EXPECT_FALSE((*r)->health().complete);
    EXPECT_EQ(samples_in(**r), 4000);
  }
  // The -wal left behind: the error says where the data is.
  const std::string alone = dir + "/alone.imulog";
  fs::copy_file(dir + "/crash.imulog", alone);
  // (Its main file holds only the header: everything since is in the -wal.)
  for (int attempt = 0; attempt < 2; ++attempt) {  // the first open leaves an empty -wal behind
    auto r = SessionLogReader::open(alone);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find(attempt == 0 ? "-wal is missing" : "-wal is empty"), std::string::npos)
        << r.error().message;
    EXPECT_NE(r.error().message.find("copy that file next to the log"), std::string::npos)
        << r.error().message;
  }
}

// What the writer does when it creates a log, stopped (killed) inside that first transaction:
// the main file holds only its header, in WAL mode, and the -wal either nothing (the pages were
// still in memory) or pages that no commit ends. Before, the first was called a log whose -wal
// is missing (copy it) although it lay beside it, and the second the same.
void create_and_die_before_commit(const std::string& path, bool spill_pages) {
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    sqlite3* db = nullptr;
    if (sqlite3_open(path.c_str(), &db) != SQLITE_OK) _exit(10);
    const std::string setup = std::string("PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL;") +
                              (spill_pages ? "PRAGMA cache_size=2;" : "") +
                              "BEGIN; CREATE TABLE metadata(key TEXT PRIMARY KEY, value TEXT);";
    if (sqlite3_exec(db, setup.c_str(), nullptr, nullptr, nullptr) != SQLITE_OK) _exit(11);
    for (int i = 0; i < 400; ++i) {
      const std::string row =
          "INSERT INTO metadata VALUES('k" + std::to_string(i) + "', '" + std::string(200, 'x') + "');";
      if (sqlite3_exec(db, row.c_str(), nullptr, nullptr, nullptr) != SQLITE_OK) _exit(12);
    }
    _exit(0);  // killed: no commit, nothing closed
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0);
}

TEST(SessionLogDamage, ALogStoppedBeforeItsFirstCommitIsNamedSoAndNotCalledMissingItsWal) {
  const std::string dir = scratch_dir();
  const std::string spilled = dir + "/spilled.imulog";
  create_and_die_before_commit(spilled, true);
  ASSERT_GT(fs::file_size(spilled + "-wal"), 0u);
  auto r = SessionLogReader::open(spilled);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kCorrupt);
  EXPECT_NE(r.error().message.find("before its first commit"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("record the session again"), std::string::npos) << r.error().message;
  EXPECT_EQ(r.error().message.find("missing"), std::string::npos) << r.error().message;

  const std::string in_memory = dir + "/in-memory.imulog";
  create_and_die_before_commit(in_memory, false);
  ASSERT_TRUE(fs::exists(in_memory + "-wal"));
  ASSERT_EQ(fs::file_size(in_memory + "-wal"), 0u);
  r = SessionLogReader::open(in_memory);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kCorrupt);
  EXPECT_NE(r.error().message.find("-wal is empty"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("before its first commit"), std::string::npos) << r.error().message;
  EXPECT_EQ(r.error().message.find("missing"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace imucal::log
