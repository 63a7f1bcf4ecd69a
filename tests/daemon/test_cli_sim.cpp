// SPDX-License-Identifier: BSD-3-Clause
// imucal sim: writes a log and its truth, refuses to overwrite, repeats a run from a truth
// file, rejects bad options with usage errors.

#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

std::int64_t sample_count(const std::string& path) {
  auto reader = log::SessionLogReader::open(path);
  EXPECT_TRUE(reader.ok()) << (reader.ok() ? "" : reader.error().message);
  if (!reader.ok()) return -1;
  auto id = (*reader)->find_imu_stream();
  auto n = (*reader)->imu_count(*id);
  return n.ok() ? *n : -1;
}

TEST(CliSim, StillWritesLogAndTruthAndRefusesToOverwrite) {
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "still.imulog").string();
  auto r = test::run_cli({"sim", "still", "--seed", "3", "--duration", "5", "--imu-rate", "200", "-o", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // 5 s at 200 Hz from a chip whose clock runs 1.5 % slow (the default --clock-ppm).
  EXPECT_THAT(r.out, testing::ContainsRegex("wrote 98[456] samples"));
  EXPECT_THAT(r.out, HasSubstr("chip clock -15000 ppm"));
  EXPECT_TRUE(fs::exists(dir / "still.truth.yaml"));
  EXPECT_FALSE(fs::exists(dir / "still.imulog-wal"));
  EXPECT_NEAR(static_cast<double>(sample_count(log)), 985.0, 1.0);
  const YAML::Node truth = YAML::LoadFile((dir / "still.truth.yaml").string());
  EXPECT_EQ(truth["kind"].as<std::string>(), "still");
  EXPECT_EQ(truth["seed"].as<int>(), 3);
  EXPECT_DOUBLE_EQ(truth["trajectory"]["duration_s"].as<double>(), 5.0);

  auto again = test::run_cli({"sim", "still", "--seed", "3", "--duration", "5", "-o", log});
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_THAT(again.err, HasSubstr("--force"));
  auto forced = test::run_cli({"sim", "still", "--seed", "3", "--duration", "2", "-o", log, "--force"});
  EXPECT_EQ(forced.exit_code, 0) << forced.err;
  EXPECT_NEAR(static_cast<double>(sample_count(log)), 197.0, 1.0);
}

// sim --force over a live recording is refused and says nothing of this run was written (before:
// "stopped, N samples (S s) kept in LOG", counting the recording's own samples as the sim's).
TEST(CliSim, ARefusedLiveLogIsNotCalledTheSimulationsKeptSamples) {
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "live.imulog").string();
  ASSERT_EQ(test::run_cli({"sim", "still", "--seed", "3", "--duration", "2", "-o", log}).exit_code, 0);
  const std::string before = test::read_file(log);
  test::CommandResult r;
  {
    const test::WriterLockHolder writer(log);
    ASSERT_TRUE(writer.held());
    r = test::run_cli({"sim", "still", "--seed", "4", "--duration", "2", "-o", log, "--force"});
  }
  EXPECT_EQ(r.exit_code, 7) << r.err;
  // Refused before the run (the output check sees the writer's lock); a writer that takes the
  // lock after that check gets "nothing was written: LOG is the file that was there before"
  // from the run itself. Either way nothing is called the simulation's kept samples.
  EXPECT_THAT(r.err, HasSubstr("is being written by process"));
  EXPECT_THAT(r.err, testing::Not(HasSubstr("kept in")));
  EXPECT_EQ(test::read_file(log), before);
}

TEST(CliSim, StaticAndGsensWithTruthFromFile) {
  const fs::path dir = test::scratch_dir();
  const std::string a = (dir / "a.imulog").string(), b = (dir / "b.imulog").string();
  auto r = test::run_cli({"sim", "static", "--seed", "12", "--poses", "9", "--still", "3", "--accel-range",
                          "2", "--gyro-range", "250", "-o", a});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("9 poses"));
  // Another seed, but the parameters of the first run.
  auto g = test::run_cli(
      {"sim", "gsens", "--seed", "13", "--hold", "2", "--truth", (dir / "a.truth.yaml").string(), "-o", b});
  ASSERT_EQ(g.exit_code, 0) << g.err;
  const YAML::Node ta = YAML::LoadFile((dir / "a.truth.yaml").string());
  const YAML::Node tb = YAML::LoadFile((dir / "b.truth.yaml").string());
  EXPECT_EQ(YAML::Dump(ta["imu"]), YAML::Dump(tb["imu"]));
  EXPECT_EQ(YAML::Dump(ta["canonical"]), YAML::Dump(tb["canonical"]));
  EXPECT_TRUE(tb["params_from_file"].as<bool>());
  EXPECT_EQ(tb["imu"]["accel"]["full_scale_g"].as<int>(), 2);
  EXPECT_EQ(tb["trajectory"]["poses"].as<int>(), 6);

  auto reader = log::SessionLogReader::open(b);
  ASSERT_TRUE(reader.ok());
  const ImuStreamInfo& info = (*reader)->imu_streams().begin()->second;
  EXPECT_EQ(info.accel_full_scale_g, 2);
  EXPECT_EQ(info.gyro_full_scale_dps, 250);
}

TEST(CliSim, BadOptionsAreUsageErrors) {
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "x.imulog").string();
  auto poses = test::run_cli({"sim", "static", "--seed", "1", "--poses", "5", "-o", log});
  EXPECT_EQ(poses.exit_code, 2);
  auto range = test::run_cli({"sim", "still", "--seed", "1", "--accel-range", "3", "-o", log});
  EXPECT_EQ(range.exit_code, 2);
  auto drop = test::run_cli({"sim", "still", "--seed", "1", "--duration", "2", "--drop", "1-2", "-o", log});
  EXPECT_EQ(drop.exit_code, 2);
  EXPECT_THAT(drop.err, HasSubstr("START:DURATION"));
  const std::string bad_truth = (dir / "bad.yaml").string();
  std::ofstream(bad_truth) << "imu:\n  accel: {bias_mps2: [0, 0, 500]}\n  gyro: {}\n";
  auto truth =
      test::run_cli({"sim", "still", "--seed", "1", "--duration", "2", "--truth", bad_truth, "-o", log});
  EXPECT_EQ(truth.exit_code, 3);
  EXPECT_THAT(truth.err, HasSubstr("m/s^2"));
  EXPECT_FALSE(fs::exists(log));
}

// 8 kHz does not fit through I2C at 400 kHz: the session is written, the losses are flagged
// and counted, and the summary says why.
TEST(CliSim, ARateTheBusCannotCarryIsRecordedWithItsLossesExplained) {
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "i2c.imulog").string();
  auto r = test::run_cli(
      {"sim", "still", "--seed", "2", "--duration", "2", "--imu-rate", "8000", "--bus", "i2c", "-o", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("dropped samples"));
  EXPECT_THAT(r.out, HasSubstr("the bus cannot carry this rate"));
  const YAML::Node truth = YAML::LoadFile((dir / "i2c.truth.yaml").string());
  EXPECT_GT(truth["recording"]["dropped_samples"].as<int>(), 8000);
  EXPECT_EQ(truth["recording"]["samples"].as<std::int64_t>(), sample_count(log));
}

// A filesystem that fills up while a session is simulated into it: the command says it stopped
// and how much it kept (exit 7), and the log holds every committed sample, readable and not
// called damaged. Needs a tmpfs mount (root).
TEST(CliSim, AFullDiskStopsWithWhatWasKept) {
  const std::string dir = test::scratch_dir();
  // A long folder name: the message names the log, and must carry it whole.
  const std::string mnt = dir + "/full-" + std::string(120, 'x');
  fs::create_directories(mnt);
  if (std::system(("mount -t tmpfs -o size=600k tmpfs " + mnt + " 2>/dev/null").c_str()) != 0)
    GTEST_SKIP() << "cannot mount a small tmpfs here (needs root): the full-disk test is skipped";
  struct Unmount {
    std::string path;
    ~Unmount() { (void)std::system(("umount " + path).c_str()); }
  } unmount{mnt};
  const std::string log = mnt + "/x.imulog";
  auto r = test::run_cli({"sim", "static", "--seed", "1", "-o", log});
  EXPECT_EQ(r.exit_code, 7) << r.err;
  EXPECT_THAT(r.err, HasSubstr("disk is full"));
  EXPECT_THAT(r.err, HasSubstr("readable and marked incomplete"));
  auto reader = log::SessionLogReader::open(log);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->health().complete);
  EXPECT_FALSE((*reader)->health().damaged) << (*reader)->health().damage_message;
  const auto kept = *(*reader)->imu_count(*(*reader)->find_imu_stream());
  EXPECT_GT(kept, 500);  // commits every 5 s of samples: more than the last one survives
  EXPECT_THAT(r.err, HasSubstr("stopped, " + std::to_string(kept) + " samples"));
}

}  // namespace
}  // namespace imucal
