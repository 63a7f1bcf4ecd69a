// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "core/text_file.hpp"
#include "log/dataset_io.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_helpers.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::log {
namespace {

/// True when `error` names the remedy `option` (with `value`, when given).
using test::has_remedy;

namespace fs = std::filesystem;
using ::testing::HasSubstr;

struct ImportedLog {
  ImuStreamInfo info;
  std::vector<ImuSample> samples;
  std::map<std::string, std::string> metadata;
};

ImportedLog read_imported(const std::string& path) {
  ImportedLog log;
  auto reader = SessionLogReader::open(path);
  EXPECT_TRUE(reader.ok()) << reader.error().message;
  if (!reader.ok()) return log;
  EXPECT_EQ((*reader)->imu_streams().size(), 1u);
  auto id = (*reader)->find_imu_stream();
  EXPECT_TRUE(id.ok());
  log.info = (*reader)->imu_streams().at(*id);
  log.samples = *(*reader)->read_imu(*id);
  log.metadata = (*reader)->metadata();
  return log;
}

/// imu_tk-style files: 100 Hz, a static pose, counts of a +-2 g / +-250 dps MPU-6000.
void write_raw_pair(const fs::path& dir, int rows, double gyro_time_jitter_s = 0.0) {
  std::string acc = "# accelerometer, raw counts\n", gyr = "# gyroscope, raw counts\n";
  for (int i = 0; i < rows; ++i) {
    const double t = 10.0 + 0.01 * i;
    char buf[128];
    std::snprintf(buf, sizeof buf, "%.9f %d %d %d\n", t, 120 + i % 3, -340, 16100 + i % 5);
    acc += buf;
    std::snprintf(buf, sizeof buf, "%.9f %d %d %d\n", t + (i % 2 ? gyro_time_jitter_s : 0.0), -12, 7 + i % 2,
                  3);
    gyr += buf;
  }
  test::write_file(dir / "acc.txt", acc);
  test::write_file(dir / "gyr.txt", gyr);
}

TEST(DatasetAscii, RawCountsKeepCountsAndNominalConversion) {
  const fs::path dir = test::scratch_dir();
  write_raw_pair(dir, 300);
  AsciiImport in;
  in.accel_path = (dir / "acc.txt").string();
  in.gyro_path = (dir / "gyr.txt").string();
  in.units = ImuUnits::kRaw;
  in.accel.scale = Eigen::Vector3d(0.0006, 0.0006, 0.0006);
  in.accel.offset = Eigen::Vector3d(1, 2, 3);
  std::vector<double> fractions;
  OutputOptions options;
  options.progress = [&fractions](double f) { fractions.push_back(f); };
  auto r = import_ascii(in, (dir / "raw.imulog").string(), options);
  ASSERT_TRUE(r.ok()) << r.error().message;
  // Progress is a fraction: it never goes back, stays in [0, 1] and ends at 1.
  ASSERT_FALSE(fractions.empty());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_GE(fractions.front(), 0.0);
  EXPECT_DOUBLE_EQ(fractions.back(), 1.0);
  EXPECT_EQ(r->imu_samples, 300);
  EXPECT_NEAR(r->rate_hz, 100.0, 1e-9);
  const ImportedLog log = read_imported((dir / "raw.imulog").string());
  EXPECT_EQ(log.info.units, ImuUnits::kRaw);
  EXPECT_EQ(log.info.accel.scale, in.accel.scale);
  EXPECT_EQ(log.info.accel.offset, in.accel.offset);
  EXPECT_EQ(log.info.gyro.scale, default_raw_gyro_conversion().scale);
  ASSERT_EQ(log.samples.size(), 300u);
  EXPECT_EQ(log.samples[0].t_ns, 10'000'000'000);
  EXPECT_EQ(log.samples[299].t_ns, 12'990'000'000);
  EXPECT_EQ(log.samples[7].accel, Eigen::Vector3d(121, -340, 16102));
  EXPECT_EQ(log.samples[7].gyro, Eigen::Vector3d(-12, 8, 3));
  EXPECT_THAT(log.metadata.at("import"), HasSubstr("ascii"));
}

TEST(DatasetAscii, SiValuesExactAndNearestPairing) {
  const fs::path dir = test::scratch_dir();
  test::write_file(dir / "acc.txt", "0.000 0.1 0.2 9.7\n0.005 0.15 0.25 9.75\n0.010 0.125 0.2 9.8\n");
  // Gyroscope stamped 0.4 ms later: within half a 5 ms period, so paired.
  test::write_file(dir / "gyr.txt", "0.0004 0.01 0.02 0.03\n0.0054 0.04 0.05 0.06\n0.0104 0.07 0.08 0.09\n");
  AsciiImport in;
  in.accel_path = (dir / "acc.txt").string();
  in.gyro_path = (dir / "gyr.txt").string();
  in.units = ImuUnits::kSi;
  auto r = import_ascii(in, (dir / "si.imulog").string(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_FALSE(r->notes.empty());
  EXPECT_THAT(r->notes[0], HasSubstr("nearest"));
  const ImportedLog log = read_imported((dir / "si.imulog").string());
  EXPECT_EQ(log.info.units, ImuUnits::kSi);
  ASSERT_EQ(log.samples.size(), 3u);
  EXPECT_EQ(log.samples[1].t_ns, 5'000'000);
  EXPECT_EQ(log.samples[1].accel, Eigen::Vector3d(0.15, 0.25, 9.75));
  EXPECT_EQ(log.samples[1].gyro, Eigen::Vector3d(0.04, 0.05, 0.06));
}

TEST(DatasetAscii, UnitMismatchFailsAndLeavesNoOutput) {
  const fs::path dir = test::scratch_dir();
  write_raw_pair(dir, 50);
  AsciiImport in;
  in.accel_path = (dir / "acc.txt").string();
  in.gyro_path = (dir / "gyr.txt").string();
  in.units = ImuUnits::kSi;
  auto r = import_ascii(in, (dir / "x.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(has_remedy(r.error(), "units", "raw")) << r.error().message;
  EXPECT_THAT(r.error().message, HasSubstr("raw counts"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));
  in.unit_check = false;
  EXPECT_TRUE(import_ascii(in, (dir / "x.imulog").string(), {}).ok());
}

TEST(DatasetAscii, UnpairableFilesAndMalformedRows) {
  const fs::path dir = test::scratch_dir();
  write_raw_pair(dir, 50, 0.004);  // every other gyro row 4 ms late: within half of 10 ms
  AsciiImport in;
  in.accel_path = (dir / "acc.txt").string();
  in.gyro_path = (dir / "gyr.txt").string();
  in.units = ImuUnits::kRaw;
  ASSERT_TRUE(import_ascii(in, (dir / "ok.imulog").string(), {}).ok());
  write_raw_pair(dir, 50, 0.006);  // 6 ms late: no partner within 5 ms
  auto r = import_ascii(in, (dir / "x.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("gyr.txt:"));
  EXPECT_THAT(r.error().message, HasSubstr("half"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));

  test::write_file(dir / "acc.txt", "0 1 2 3\n0.01 1 2 3\n0.02 1 2\n");
  auto bad = import_ascii(in, (dir / "x.imulog").string(), {});
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, HasSubstr("acc.txt:3: expected 4"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));
}

/// Imports read twice instead of held (OutputOptions::in_memory_bytes = 0).
OutputOptions streamed() {
  OutputOptions o;
  o.in_memory_bytes = 0;
  return o;
}

/// Streamed options that append `rows` to `file` once the first reading has ended (progress 0.5);
/// `*appended` says whether it happened.
OutputOptions appending_between_readings(const fs::path& file, std::string rows, bool* appended) {
  OutputOptions o = streamed();
  *appended = false;
  o.progress = [file, rows = std::move(rows), appended](double f) {
    if (f < 0.5 || *appended) return;
    *appended = true;
    std::ofstream(file, std::ios::app) << rows;
  };
  return o;
}

void expect_same_log(const std::string& held, const std::string& streamed_log) {
  const ImportedLog a = read_imported(held), b = read_imported(streamed_log);
  EXPECT_EQ(a.info.rate_hz, b.info.rate_hz);
  EXPECT_EQ(a.info.units, b.info.units);
  ASSERT_EQ(a.samples.size(), b.samples.size());
  for (std::size_t i = 0; i < a.samples.size(); ++i) {
    EXPECT_EQ(a.samples[i].t_ns, b.samples[i].t_ns) << i;
    EXPECT_EQ(a.samples[i].accel, b.samples[i].accel) << i;
    EXPECT_EQ(a.samples[i].gyro, b.samples[i].gyro) << i;
    if (a.samples[i].t_ns != b.samples[i].t_ns) break;
  }
}

// Inputs above OutputOptions::in_memory_bytes are read twice (checked, then paired and written as
// they are read again), so memory does not grow with them: the log, the summary and every
// refusal are the same as when the rows are held.
TEST(DatasetAscii, ReadTwiceInsteadOfHeldTheSameLogAndTheSameRefusals) {
  const fs::path dir = test::scratch_dir();
  // Jittered gyro times (nearest pairing), and rows outside the common span at both ends.
  write_raw_pair(dir, 20000, 0.004);
  std::string acc = test::read_file((dir / "acc.txt").string());
  test::write_file(dir / "acc.txt", "9.95 1 2 3\n" + acc + "210.5 1 2 3\n");
  AsciiImport in;
  in.accel_path = (dir / "acc.txt").string();
  in.gyro_path = (dir / "gyr.txt").string();
  in.units = ImuUnits::kRaw;
  auto held = import_ascii(in, (dir / "held.imulog").string(), {});
  ASSERT_TRUE(held.ok()) << held.error().message;
  std::vector<double> fractions;
  OutputOptions options = streamed();
  options.progress = [&fractions](double f) { fractions.push_back(f); };
  auto twice = import_ascii(in, (dir / "twice.imulog").string(), options);
  ASSERT_TRUE(twice.ok()) << twice.error().message;
  EXPECT_EQ(twice->imu_samples, 20000);
  EXPECT_EQ(twice->imu_samples, held->imu_samples);
  EXPECT_EQ(twice->t_first_ns, held->t_first_ns);
  EXPECT_EQ(twice->t_last_ns, held->t_last_ns);
  EXPECT_EQ(twice->notes, held->notes);
  EXPECT_THAT(twice->notes[0], HasSubstr("10000 rows paired with the nearest"));
  EXPECT_THAT(twice->notes[1], HasSubstr("dropped 2 accelerometer and 0 gyroscope rows"));
  expect_same_log((dir / "held.imulog").string(), (dir / "twice.imulog").string());
  ASSERT_FALSE(fractions.empty());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_DOUBLE_EQ(fractions.back(), 1.0);

  // The refusals: a row without a partner, a malformed row, raw counts called SI.
  const auto same_refusal = [&](const AsciiImport& bad, const std::string& what) {
    auto a = import_ascii(bad, (dir / "x.imulog").string(), {});
    auto b = import_ascii(bad, (dir / "x.imulog").string(), streamed());
    ASSERT_FALSE(a.ok()) << what;
    ASSERT_FALSE(b.ok()) << what;
    EXPECT_EQ(a.error().message, b.error().message) << what;
    EXPECT_EQ(a.error().code, b.error().code) << what;
    EXPECT_FALSE(fs::exists(dir / "x.imulog")) << what;
  };
  write_raw_pair(dir, 3000, 0.006);
  same_refusal(in, "unpairable");
  write_raw_pair(dir, 3000);
  test::write_file(dir / "gyr.txt", test::read_file((dir / "gyr.txt").string()) + "40.0 1 2\n");
  same_refusal(in, "malformed");
  write_raw_pair(dir, 3000);
  AsciiImport si = in;
  si.units = ImuUnits::kSi;
  same_refusal(si, "units");
  test::write_file(dir / "gyr.txt", "500 1 2 3\n501 1 2 3\n");
  same_refusal(in, "no overlap");

  // Rows appended to a file between the two readings (when the first has ended): refused.
  write_raw_pair(dir, 3000);
  bool appended = false;
  auto changed =
      import_ascii(in, (dir / "x.imulog").string(),
                   appending_between_readings(dir / "acc.txt", "500 1 2 3\n501 1 2 3\n", &appended));
  ASSERT_TRUE(appended);
  ASSERT_FALSE(changed.ok());
  EXPECT_THAT(changed.error().message,
              HasSubstr("acc.txt changed while it was imported (3000 rows, then 3002)"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));
}

TEST(DatasetCsvImport, ReadTwiceInsteadOfHeldTheSameLog) {
  const fs::path dir = test::scratch_dir();
  std::string csv = "t_ns,ax,ay,az,gx,gy,gz\n";
  for (int i = 0; i < 30000; ++i) {
    csv += std::to_string(1'000'000'000 + 2'500'000LL * i + (i % 3) * 1000) + ",0.1,-0.2," +
           std::to_string(9.8 + 0.001 * (i % 11)) + ",0.01,0.02,0.03\n";
  }
  test::write_file(dir / "d.csv", csv);
  CsvImport in;
  in.path = (dir / "d.csv").string();
  in.format.columns = *parse_csv_columns("t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6");
  in.format.time_unit = TimeUnit::kNs;
  in.format.skip_header = 1;
  auto held = import_csv(in, (dir / "held.imulog").string(), {});
  ASSERT_TRUE(held.ok()) << held.error().message;
  auto twice = import_csv(in, (dir / "twice.imulog").string(), streamed());
  ASSERT_TRUE(twice.ok()) << twice.error().message;
  EXPECT_EQ(twice->imu_samples, 30000);
  EXPECT_EQ(twice->rate_hz, held->rate_hz);
  EXPECT_EQ(twice->rate_hz, 1e9 / 2'501'000.0);  // the median interval, jitter included
  expect_same_log((dir / "held.imulog").string(), (dir / "twice.imulog").string());
  // Rows appended between the two readings: refused.
  bool appended = false;
  auto changed = import_csv(
      in, (dir / "x.imulog").string(),
      appending_between_readings(dir / "d.csv", "900000000000,0.1,-0.2,9.8,0.01,0.02,0.03\n", &appended));
  ASSERT_TRUE(appended);
  ASSERT_FALSE(changed.ok());
  EXPECT_THAT(changed.error().message, HasSubstr("changed while it was imported (30000 rows, then 30001)"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));

  in.format.time_unit = TimeUnit::kMs;  // nanoseconds read as milliseconds: 2500 s apart
  auto wrong = import_csv(in, (dir / "w.imulog").string(), streamed());
  ASSERT_FALSE(wrong.ok());
  EXPECT_TRUE(has_remedy(wrong.error(), "time_unit")) << wrong.error().message;
  EXPECT_FALSE(fs::exists(dir / "w.imulog"));
}

TEST(DatasetCsvImport, ColumnMappingTimeUnitAndTemperature) {
  const fs::path dir = test::scratch_dir();
  std::string csv = "time_us,ax,ay,az,gx,gy,gz,temp_raw\n";
  for (int i = 0; i < 20; ++i) {
    csv += std::to_string(1000000 + 2500 * i) + ",100,-200," + std::to_string(8192 + i) + ",1,2,3," +
           std::to_string(-521 + i) + "\n";
  }
  test::write_file(dir / "d.csv", csv);
  CsvImport in;
  in.path = (dir / "d.csv").string();
  in.format.columns = *parse_csv_columns("t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6,temp=7");
  in.format.time_unit = TimeUnit::kUs;
  in.format.skip_header = 1;
  in.units = ImuUnits::kRaw;
  in.temperature_scale = 1.0 / 340.0;
  in.temperature_offset = 36.53;
  auto r = import_csv(in, (dir / "d.imulog").string(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_NEAR(r->rate_hz, 400.0, 1e-9);
  const ImportedLog log = read_imported((dir / "d.imulog").string());
  ASSERT_EQ(log.samples.size(), 20u);
  EXPECT_EQ(log.samples[3].t_ns, 1'007'500'000);
  EXPECT_EQ(log.samples[3].accel, Eigen::Vector3d(100, -200, 8195));
  EXPECT_EQ(log.samples[3].temperature, -518.0);
  EXPECT_DOUBLE_EQ(log.info.temperature_scale, 1.0 / 340.0);
  EXPECT_DOUBLE_EQ(log.info.temperature_offset, 36.53);

  // Wrong time unit: microseconds read as seconds give a 2500 s period.
  in.format.time_unit = TimeUnit::kS;
  auto wrong = import_csv(in, (dir / "w.imulog").string(), {});
  ASSERT_FALSE(wrong.ok());
  EXPECT_TRUE(has_remedy(wrong.error(), "time_unit")) << wrong.error().message;
  EXPECT_THAT(wrong.error().message, HasSubstr("the time unit (now s)"));
  EXPECT_FALSE(fs::exists(dir / "w.imulog"));
}

TEST(DatasetOutput, PendingOutputRemovesUncommittedAndRefusesExisting) {
  const fs::path dir = test::scratch_dir();
  {
    auto out = PendingOutput::begin((dir / "o.imulog").string(), PendingOutput::Kind::kFile, false);
    ASSERT_TRUE(out.ok());
    test::write_file(out->temp_path(), "half written");
    test::write_file(out->temp_path() + "-wal", "wal");
  }
  EXPECT_TRUE(fs::is_empty(dir));
  {
    auto out = PendingOutput::begin((dir / "o.imulog").string(), PendingOutput::Kind::kFile, false);
    ASSERT_TRUE(out.ok());
    test::write_file(out->temp_path(), "complete");
    ASSERT_TRUE(out->commit().ok());
  }
  EXPECT_EQ(test::read_file((dir / "o.imulog").string()), "complete");
  auto again = PendingOutput::begin((dir / "o.imulog").string(), PendingOutput::Kind::kFile, false);
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, Errc::kAlreadyExists);
  EXPECT_THAT(again.error().message, HasSubstr("already exists"));
  // Two writers of one new output: both start, the first to finish wins and the second is refused
  // at its commit instead of replacing the first's file.
  {
    auto a = PendingOutput::begin((dir / "race.imulog").string(), PendingOutput::Kind::kFile, false);
    auto b = PendingOutput::begin((dir / "race.imulog").string(), PendingOutput::Kind::kFile, false);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_NE(a->temp_path(), b->temp_path());
    test::write_file(a->temp_path(), "first");
    test::write_file(b->temp_path(), "second");
    ASSERT_TRUE(a->commit().ok());
    const Status late = b->commit();
    ASSERT_FALSE(late.ok());
    EXPECT_EQ(late.error().code, Errc::kAlreadyExists);
    EXPECT_THAT(late.error().message, HasSubstr("appeared while it was being written"));
  }
  EXPECT_EQ(test::read_file((dir / "race.imulog").string()), "first");
  for (const auto& entry : fs::directory_iterator(dir))  // the loser's temporary is gone
    EXPECT_EQ(entry.path().filename().string().find("race.imulog.partial"), std::string::npos)
        << entry.path();
  auto no_dir = PendingOutput::begin((dir / "nope/o.imulog").string(), PendingOutput::Kind::kFile, false);
  ASSERT_FALSE(no_dir.ok());
  EXPECT_THAT(no_dir.error().message, HasSubstr("does not exist"));
}

// What writers killed before their rename left ("<path>.partial-<pid>-<n>" with its -wal, a
// result's "<path>.tmp-<pid>") is removed by the next writer of that path once the writer is
// gone (before: left for good); a running process's temporaries and other names are kept.
TEST(DatasetOutput, AKilledWritersTemporariesAreRemovedByTheNextWriter) {
  const fs::path dir = test::scratch_dir();
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) _exit(0);
  ASSERT_EQ(waitpid(child, nullptr, 0), child);
  const std::string dead = std::to_string(child);
  const std::string alive = std::to_string(getppid());
  const std::vector<std::string> stale = {"o.imulog.partial-" + dead + "-0",
                                          "o.imulog.partial-" + dead + "-0-wal", "o.imulog.tmp-" + dead};
  const std::vector<std::string> kept = {"o.imulog.partial-" + alive + "-0", "o.imulog.tmp-x" + dead,
                                         "p.imulog.tmp-" + dead, "o.imulog.partial-" + dead};
  for (const auto& name : stale) test::write_file((dir / name).string(), "left by a killed writer");
  for (const auto& name : kept) test::write_file((dir / name).string(), "not ours to remove");
  fs::create_directory(dir / ("e.partial-" + dead + "-3"));  // an export's folder
  test::write_file((dir / ("e.partial-" + dead + "-3") / "imu0.csv").string(), "t");
  auto out = PendingOutput::begin((dir / "o.imulog").string(), PendingOutput::Kind::kFile, false);
  ASSERT_TRUE(out.ok()) << out.error().message;
  for (const auto& name : stale) EXPECT_FALSE(fs::exists(dir / name)) << name;
  for (const auto& name : kept) EXPECT_TRUE(fs::exists(dir / name)) << name;
  auto folder = PendingOutput::begin((dir / "e").string(), PendingOutput::Kind::kDirectory, false);
  ASSERT_TRUE(folder.ok()) << folder.error().message;
  EXPECT_FALSE(fs::exists(dir / ("e.partial-" + dead + "-3")));
}

}  // namespace
}  // namespace imucal::log

namespace imucal::log {
namespace {

TEST(ReadTextFile, ReadsWholeFilesAndRefusesWhatIsNotARegularFile) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/a.txt";
  std::string big(3'000'000, 'x');
  big += "end\n";
  std::ofstream(path, std::ios::binary) << big;
  auto text = read_text_file(path);
  ASSERT_TRUE(text.ok()) << text.error().message;
  EXPECT_EQ(*text, big);
  auto folder = read_text_file(dir);
  ASSERT_FALSE(folder.ok());
  EXPECT_NE(folder.error().message.find("is a folder"), std::string::npos) << folder.error().message;
  // A FIFO without a writer would block a reader forever; it is refused at once.
  const std::string fifo = dir + "/fifo";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  auto piped = read_text_file(fifo);
  ASSERT_FALSE(piped.ok());
  EXPECT_NE(piped.error().message.find("not a regular file"), std::string::npos) << piped.error().message;
  // A limit refuses what is far larger than the file can be, without reading it.
  auto limited = read_text_file(path, 1000);
  ASSERT_FALSE(limited.ok());
  EXPECT_EQ(limited.error().code, Errc::kInvalidArgument);
  EXPECT_NE(limited.error().message.find("3000004 bytes"), std::string::npos) << limited.error().message;
  EXPECT_FALSE(read_text_file("/dev/zero").ok());  // never ends: not a regular file
  auto missing = read_text_file(dir + "/none.txt");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::kNotFound);
}

// The importers read their files line by line in chunks: lines that cross chunk boundaries, CRLF
// ends and a last line without '\n' come out as from the text whole, at any chunk size.
TEST(TextLineReader, LinesAreTheSameAtEveryChunkSize) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/lines.txt";
  const std::string text = "t x y z\r\n0.0 1 2 3\n\n" + std::string(5000, '7') + "\n# comment\r\nlast line";
  std::ofstream(path, std::ios::binary) << text;
  std::vector<std::string> expected;
  for (std::size_t pos = 0; pos <= text.size();) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    expected.push_back(text.substr(pos, end - pos));
    pos = end + 1;
  }
  for (const std::size_t chunk : {1u, 2u, 3u, 7u, 64u, 4096u, 1u << 20}) {
    auto reader = TextLineReader::open(path, chunk);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    std::vector<std::string> got;
    std::string_view line;
    while ((*reader)->next(line)) got.emplace_back(line);
    EXPECT_FALSE((*reader)->error().has_value()) << chunk;
    EXPECT_EQ(got, expected) << "chunk " << chunk;
    EXPECT_EQ((*reader)->offset(), text.size()) << chunk;
  }
  // The importers' parsers give the same rows from the file as from the text.
  const std::string triads = dir + "/acc.txt";
  std::string rows;
  for (int i = 0; i < 5000; ++i) rows += std::to_string(i * 0.01) + " 0.1 -0.2 9.81\r\n";
  std::ofstream(triads, std::ios::binary) << rows;
  auto file = TriadRowReader::open(triads);
  ASSERT_TRUE(file.ok()) << file.error().message;
  std::vector<TimeNs> t_ns;
  std::vector<int> lines;
  TriadRow row;
  for (auto more = (*file)->next(row); more.ok() && *more; more = (*file)->next(row)) {
    t_ns.push_back(row.t_ns);
    lines.push_back(row.line);
  }
  auto from_text = parse_triad_text(rows, triads);
  ASSERT_TRUE(from_text.ok()) << from_text.error().message;
  EXPECT_EQ(t_ns, from_text->t_ns);
  EXPECT_EQ(lines, from_text->line);
  EXPECT_EQ(t_ns.size(), 5000u);
}

TEST(TextLineReader, RefusesWhatIsNotATextFile) {
  const std::string dir = test::scratch_dir();
  // A line longer than any dataset line (a binary file, or one without line ends) is an error.
  const std::string binary = dir + "/one-line.bin";
  std::ofstream(binary, std::ios::binary) << std::string(3 * TextLineReader::kMaxLineBytes, 'x');
  auto reader = TextLineReader::open(binary);
  ASSERT_TRUE(reader.ok());
  std::string_view line;
  EXPECT_FALSE((*reader)->next(line));
  ASSERT_TRUE((*reader)->error().has_value());
  EXPECT_EQ((*reader)->error()->code, Errc::kCorrupt);
  EXPECT_THAT((*reader)->error()->message, ::testing::HasSubstr("longer than"));
  EXPECT_EQ((*reader)->offset(), 0u);  // no line was taken from it
  const Status csv = for_each_csv_sample(binary, CsvFormat{}, [](const ImuSample&) { return Status{}; });
  ASSERT_FALSE(csv.ok());
  EXPECT_THAT(csv.error().message, ::testing::HasSubstr("longer than"));
  // A folder and a FIFO are refused at open, as by read_text_file.
  auto folder = TextLineReader::open(dir);
  ASSERT_FALSE(folder.ok());
  EXPECT_THAT(folder.error().message, ::testing::HasSubstr("is a folder"));
  const std::string fifo = dir + "/fifo";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  auto piped = TextLineReader::open(fifo);
  ASSERT_FALSE(piped.ok());
  EXPECT_THAT(piped.error().message, ::testing::HasSubstr("not a regular file"));
  EXPECT_FALSE(TextLineReader::open(dir + "/none.txt").ok());
}

}  // namespace
}  // namespace imucal::log
