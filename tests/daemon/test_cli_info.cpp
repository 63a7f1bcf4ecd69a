// SPDX-License-Identifier: BSD-3-Clause
// imucal info: text and JSON summaries of a real log, gaps, incomplete and damaged logs, and
// files that are not logs.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// 2000 samples at a nominal 1 kHz with one 10 ms hole after sample 999 (flagged on the sample
// after it), 20 frames at 20 Hz, 3 events.
std::string write_log(const std::string& path, bool close = true) {
  auto writer = log::SessionLogWriter::create(path);
  EXPECT_TRUE(writer.ok()) << writer.error().message;
  auto& w = **writer;
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kRaw;
  info.rate_hz = 1000.0;
  info.device = "mpu6000@spi0.0";
  info.accel_full_scale_g = 4;
  info.gyro_full_scale_dps = 500;
  info.dlpf_hz = 98;
  const int imu = *w.add_imu_stream(info);
  CameraStreamInfo cam_info;
  cam_info.name = "cam0";
  cam_info.width = 8;
  cam_info.height = 8;
  cam_info.rate_hz = 20.0;
  cam_info.backend = "sim";
  cam_info.timestamp_source = "mid-exposure";
  const int cam = *w.add_camera_stream(cam_info);
  EXPECT_TRUE(w.set_metadata("rig", "bench rig 7").ok());
  std::vector<ImuSample> samples(2000);
  TimeNs t_ns = 10 * kNsPerSecond;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    samples[i].t_ns = t_ns;
    samples[i].accel = {1.0, 2.0, 16384.0};
    if (i == 1000) samples[i].flags = kImuFlagGapBefore;
    t_ns += (i == 999) ? 10'000'000 : 1'000'000;
  }
  EXPECT_TRUE(w.append_imu(imu, samples).ok());
  for (int f = 0; f < 20; ++f) {
    CameraFrame frame;
    frame.t_ns = 10 * kNsPerSecond + TimeNs{f} * 50'000'000;
    frame.width = 8;
    frame.height = 8;
    frame.encoding = "gray8";
    frame.data.assign(64, 128);
    EXPECT_TRUE(w.append_frame(cam, frame).ok());
  }
  EXPECT_TRUE(w.append_event({10 * kNsPerSecond, "prompt", "Hold still"}).ok());
  EXPECT_TRUE(w.append_event({11 * kNsPerSecond, "pose_begin", "{}"}).ok());
  EXPECT_TRUE(w.append_event({12 * kNsPerSecond, "pose_end", "{}"}).ok());
  if (close) {
    EXPECT_TRUE(w.close().ok());
  } else {
    EXPECT_TRUE(w.flush().ok());
  }
  return path;
}

TEST(CliInfo, TextSummaryOfARealLog) {
  const std::string log = write_log(test::scratch_dir() + "/session.imulog");
  auto r = test::run_cli({"info", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("status: complete"));
  EXPECT_THAT(r.out, HasSubstr("imu0 (id 1, raw counts, device mpu6000@spi0.0, accel +-4 g, gyro +-500 dps"));
  EXPECT_THAT(r.out, HasSubstr("samples: 2000, nominal 1000 Hz"));
  EXPECT_THAT(r.out, HasSubstr("1 with samples lost, longest 10 ms"));
  EXPECT_THAT(r.out, HasSubstr("flagged: 1 after a gap"));
  EXPECT_THAT(r.out, HasSubstr("frames: 20, nominal 20 Hz, measured 20 Hz"));
  EXPECT_THAT(r.out, HasSubstr("events: 3 (pose_begin 1, pose_end 1, prompt 1)"));
  EXPECT_THAT(r.out, HasSubstr("rig: bench rig 7"));
  EXPECT_THAT(r.out, HasSubstr("duration: 2.008 s"));
  EXPECT_TRUE(r.err.empty()) << r.err;
}

// Text from the file reaches the terminal without control characters: a log's metadata holding
// an escape sequence that would retitle the terminal and clear its screen.
TEST(CliInfo, ControlCharactersFromTheLogDoNotReachTheTerminal) {
  const std::string log = test::scratch_dir() + "/session.imulog";
  {
    auto writer = log::SessionLogWriter::create(log);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    ASSERT_TRUE((*writer)->set_metadata("rig", "\x1b]0;pwned\x07\x1b[2Jcalibration written OK").ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto r = test::run_cli({"info", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find('\x1b'), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find('\x07'), std::string::npos) << r.out;
  EXPECT_THAT(r.out, HasSubstr("calibration written OK"));  // the printable part stays
}

TEST(CliInfo, JsonSummaryHasEveryDocumentedField) {
  const std::string log = write_log(test::scratch_dir() + "/session.imulog");
  auto r = test::run_cli({"info", "--json", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["path"], log);
  EXPECT_EQ(j["complete"], true);
  EXPECT_EQ(j["damaged"], false);
  EXPECT_EQ(j["schema_version"], std::to_string(log::kSessionLogSchemaVersion));
  EXPECT_EQ(j["t_start_ns"], 10 * kNsPerSecond);
  EXPECT_EQ(j["t_end_ns"], 10 * kNsPerSecond + 2'008'000'000);
  EXPECT_DOUBLE_EQ(j["duration_s"].get<double>(), 2.008);
  ASSERT_EQ(j["imu_streams"].size(), 1u);
  const auto& imu = j["imu_streams"][0];
  EXPECT_EQ(imu["name"], "imu0");
  EXPECT_EQ(imu["units"], "raw");
  EXPECT_EQ(imu["count"], 2000);
  EXPECT_EQ(imu["median_period_ns"], 1'000'000);
  EXPECT_EQ(imu["gap_intervals"], 1);
  EXPECT_EQ(imu["longest_interval_ns"], 10'000'000);
  EXPECT_EQ(imu["longest_interval_at_ns"], 10 * kNsPerSecond + 1'009'000'000);
  EXPECT_EQ(imu["flagged_gap_samples"], 1);
  EXPECT_DOUBLE_EQ(imu["nominal_rate_hz"].get<double>(), 1000.0);
  EXPECT_NEAR(imu["measured_rate_hz"].get<double>(), 1999.0 / 2.008, 1e-9);
  EXPECT_EQ(imu["dlpf_hz"], 98);
  const auto& cam = j["camera_streams"][0];
  EXPECT_EQ(cam["count"], 20);
  EXPECT_EQ(cam["gap_intervals"], 0);
  EXPECT_EQ(cam["timestamp_source"], "mid-exposure");
  EXPECT_EQ(j["events"]["count"], 3);
  EXPECT_EQ(j["events"]["by_kind"]["prompt"], 1);
  EXPECT_EQ(j["metadata"]["rig"], "bench rig 7");
  EXPECT_EQ(j["metadata"]["complete"], "1");
}

TEST(CliInfo, IncompleteLogIsReportedButReadable) {
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/open.imulog";
  {
    // The writer is destroyed without close(): the data stays, complete stays 0.
    write_log(log, /*close=*/false);
  }
  auto r = test::run_cli({"info", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("INCOMPLETE"));
  EXPECT_THAT(r.out, HasSubstr("samples: 2000"));
}

TEST(CliInfo, DamagedLogPrintsWhatWasReadAndWarns) {
  const std::string dir = test::scratch_dir();
  const std::string log = write_log(dir + "/session.imulog");
  fs::resize_file(log, fs::file_size(log) - 3000);
  auto r = test::run_cli({"info", "--json", log});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_THAT(r.err, HasSubstr("WARNING"));
  EXPECT_THAT(r.err, HasSubstr("truncated"));
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["damaged"], true);
  EXPECT_THAT(j["damage_message"].get<std::string>(), HasSubstr("truncated"));
}

// What is printed must arrive: stdout on a full device is an output error, not a success.
TEST(CliInfo, AFullStdoutIsAnOutputError) {
  const std::string dir = test::scratch_dir();
  const std::string log = write_log(dir + "/session.imulog");
  for (const char* json : {"", " --json"}) {
    const std::string cmd =
        std::string(IMUCAL_CLI_PATH) + " info" + json + " " + log + " > /dev/full 2> " + dir + "/err.txt";
    const int status = std::system(cmd.c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 7) << json;
    EXPECT_THAT(test::read_file(dir + "/err.txt"),
                HasSubstr("could not write the output to standard output"));
  }
}

// Each frame's image is checked against its CRC: a corrupt one is counted and the log damaged.
TEST(CliInfo, AFrameFailingItsCrcIsReported) {
  const std::string dir = test::scratch_dir();
  const std::string log = write_log(dir + "/session.imulog");
  ASSERT_TRUE(test::run_sql(log, "UPDATE frames SET data = zeroblob(64) WHERE rowid = 3"));
  auto r = test::run_cli({"info", "--json", log});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["damaged"], true);
  EXPECT_EQ(j["camera_streams"][0]["unusable_frames"], 1);
  EXPECT_THAT(j["damage_message"].get<std::string>(), HasSubstr("CRC mismatch"));
  // export refuses, as its folder would miss the frame; with --allow-damaged it says so.
  auto e = test::run_cli({"export", "euroc", log, dir + "/out"});
  EXPECT_EQ(e.exit_code, 3) << e.err;
  EXPECT_THAT(e.err, HasSubstr("CRC mismatch"));
  EXPECT_FALSE(fs::exists(dir + "/out"));
  auto salvaged = test::run_cli({"export", "euroc", log, dir + "/out", "--allow-damaged"});
  EXPECT_EQ(salvaged.exit_code, 0) << salvaged.err;
  EXPECT_THAT(salvaged.out + salvaged.err, HasSubstr("CRC mismatch"));
}

// A log written by a newer imucal is an input this one cannot read: exit 3 everywhere.
TEST(CliInfo, ANewerSchemaIsAnInputErrorInEveryCommand) {
  const std::string dir = test::scratch_dir();
  const std::string log = write_log(dir + "/session.imulog");
  ASSERT_TRUE(
      test::run_sql(log, "PRAGMA user_version=2; UPDATE metadata SET value='2' WHERE key='schema_version'"));
  for (const std::vector<std::string>& args : {std::vector<std::string>{"info", log},
                                               {"calibrate", "static", log, "-o", dir + "/r.yaml"},
                                               {"export", "euroc", log, dir + "/out"},
                                               {"allan", log, "-o", dir + "/a.yaml"}}) {
    auto r = test::run_cli(args);
    EXPECT_EQ(r.exit_code, 3) << args[0] << ": " << r.err;
    EXPECT_THAT(r.err, HasSubstr("update imucal")) << args[0];
  }
}

TEST(CliInfo, NotALogIsAnInputError) {
  const std::string dir = test::scratch_dir();
  std::ofstream(dir + "/notes.txt") << "hello\n";
  auto r = test::run_cli({"info", dir + "/notes.txt"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_THAT(r.err, HasSubstr("not a session log"));
  EXPECT_TRUE(r.out.empty());
  r = test::run_cli({"info", dir + "/missing.imulog"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_THAT(r.err, HasSubstr("no such session log"));
  r = test::run_cli({"info"});
  EXPECT_EQ(r.exit_code, 2);
}

}  // namespace
}  // namespace imucal
