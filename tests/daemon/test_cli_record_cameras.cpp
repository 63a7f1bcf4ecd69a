// SPDX-License-Identifier: BSD-3-Clause
// `imucal record` with cameras: the IMU and the configured cameras into one log on one clock,
// on the virtual rig (rendered target or test pattern, simulated or real time), and the errors
// a camera configuration can give before anything is written.

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>

#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

std::string write_record_config(const std::string& dir, const std::string& camera_lines, int imu_rate = 200) {
  const std::string path = dir + "/rig.yaml";
  std::ofstream out(path);
  out << "name: test\nimu:\n  bus: sim\n  accel_range_g: 4\n  gyro_range_dps: 500\n  rate_hz: " << imu_rate
      << "\n  dlpf_hz: 98\n"
      << camera_lines << "target: " << test::source_path("config/checkerboard-7x6.yaml") << "\n"
      << "storage:\n  backend: file\n  path: " << dir << "/calibration.bin\n";
  return path;
}

const char* kSimCamera =
    "cameras:\n  - name: cam0\n    backend: sim\n    width: 320\n    height: 240\n    rate_hz: 15\n"
    "    pixel_format: GREY\n";

TEST(RecordCameras, SimulatedRigRecordsTheRenderedTargetBesideTheImu) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_record_config(dir, kSimCamera);
  const std::string log_path = dir + "/cam.imulog";
  const auto res =
      test::run_cli({"record", "--config", cfg, "-o", log_path, "--sim", "--duration", "3", "--json"});
  ASSERT_EQ(res.exit_code, 0) << res.err;
  const auto j = nlohmann::json::parse(res.out);
  ASSERT_EQ(j["cameras"].size(), 1u);
  const auto& c = j["cameras"][0];
  EXPECT_EQ(c["name"], "cam0");
  EXPECT_EQ(c["queue_dropped"], 0);
  EXPECT_EQ(c["device_dropped"], 0);
  EXPECT_FALSE(c["failed"].get<bool>());
  // 3 s of samples from power-up + 1 s setup; frames from 1 s after power-up at 15 Hz.
  EXPECT_GE(c["frames_written"].get<int>(), 25);

  auto reader = log::SessionLogReader::open(log_path);
  ASSERT_TRUE(reader.ok());
  auto cam_id = (*reader)->find_camera_stream("cam0");
  ASSERT_TRUE(cam_id.ok());
  const CameraStreamInfo& info = (*reader)->camera_streams().at(*cam_id);
  EXPECT_EQ(info.width, 320);
  EXPECT_EQ(info.backend, "sim");
  EXPECT_EQ(info.timestamp_source, "mid-exposure");
  auto imu = (*reader)->read_imu(*(*reader)->find_imu_stream());
  ASSERT_TRUE(imu.ok());
  // The frames show the board (the mean grey level differs between frames as the rig moves) and
  // lie on the IMU's clock, inside its span.
  std::vector<double> means;
  ASSERT_TRUE((*reader)
                  ->for_each_frame(*cam_id, log::kTimeMin, log::kTimeMax,
                                   [&](const CameraFrame& f) {
                                     EXPECT_GE(f.t_ns, imu->front().t_ns - 1'000'000'000);
                                     EXPECT_LE(f.t_ns, imu->back().t_ns + 100'000'000);
                                     auto img = log::decode_image(f.data, log::ReadMode::kGray8);
                                     EXPECT_TRUE(img.ok());
                                     double sum = 0;
                                     for (auto v : img->data) sum += v;
                                     means.push_back(sum / static_cast<double>(img->data.size()));
                                     return true;
                                   })
                  .ok());
  ASSERT_GE(means.size(), 2u);
  EXPECT_NE(means.front(), means.back());
}

TEST(RecordCameras, RealTimeTestPatternKeepsEveryFrameAndSample) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_record_config(dir, kSimCamera, 1000);
  const std::string log_path = dir + "/rt.imulog";
  const auto res = test::run_cli({"record", "--config", cfg, "-o", log_path, "--sim", "--realtime",
                                  "--sim-camera", "pattern", "--duration", "2", "--json"});
  ASSERT_EQ(res.exit_code, 0) << res.err;
  const auto j = nlohmann::json::parse(res.out);
  EXPECT_EQ(j["samples_lost"], 0);
  EXPECT_EQ(j["log_dropped"], 0);
  ASSERT_EQ(j["cameras"].size(), 1u);
  EXPECT_EQ(j["cameras"][0]["queue_dropped"], 0);
  EXPECT_GE(j["cameras"][0]["frames_written"].get<int>(), 10);
}

TEST(RecordCameras, CameraConfigurationErrorsStopBeforeAnythingIsWritten) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_record_config(dir, kSimCamera);
  const std::string log_path = dir + "/none.imulog";
  auto res = test::run_cli({"record", "--config", cfg, "-o", log_path, "--sim", "--sim-motion", "still"});
  EXPECT_EQ(res.exit_code, 2);
  EXPECT_NE(res.err.find("checkerboard"), std::string::npos) << res.err;
  EXPECT_FALSE(std::filesystem::exists(log_path));

  const std::string bad =
      write_record_config(dir,
                          "cameras:\n  - name: cam0\n    backend: sim\n    width: 320\n    height: 240\n"
                          "    rate_hz: 15\n    pixel_format: YUYV\n");
  res = test::run_cli({"record", "--config", bad, "-o", log_path, "--sim", "--duration", "1"});
  EXPECT_EQ(res.exit_code, 2);
  EXPECT_NE(res.err.find("GREY"), std::string::npos) << res.err;
  EXPECT_FALSE(std::filesystem::exists(log_path));

  const std::string v4l2 =
      write_record_config(dir,
                          "cameras:\n  - name: cam0\n    backend: v4l2\n    device: /dev/video97\n"
                          "    width: 320\n    height: 240\n    rate_hz: 15\n    pixel_format: GREY\n");
  res = test::run_cli({"record", "--config", v4l2, "-o", log_path, "--sim", "--duration", "1"});
  EXPECT_EQ(res.exit_code, 2);
  EXPECT_NE(res.err.find("simulated cameras only"), std::string::npos) << res.err;
  EXPECT_FALSE(std::filesystem::exists(log_path));
}

// One writer per log: while a recorder writes, a second one on the same path is refused, with
// --force too (naming the holder), and the first one's log comes out complete.
TEST(RecordCameras, ASecondRecorderOnTheSameLogIsRefused) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_record_config(dir, "");
  const std::string log_path = dir + "/busy.imulog";
  const std::string first = std::string(IMUCAL_CLI_PATH) + " record --config " + cfg + " -o " + log_path +
                            " --sim --realtime --duration 3 > " + dir + "/first.txt 2>&1 &";
  ASSERT_EQ(std::system(first.c_str()), 0);
  // Wait for the first recorder to have created its log.
  for (int i = 0; i < 500 && !std::filesystem::exists(log_path); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  auto forced = test::run_cli(
      {"record", "--config", cfg, "-o", log_path, "--sim", "--realtime", "--duration", "1", "--force"});
  EXPECT_EQ(forced.exit_code, 7) << forced.err;
  EXPECT_NE(forced.err.find("is being written by process"), std::string::npos) << forced.err;
  auto plain =
      test::run_cli({"record", "--config", cfg, "-o", log_path, "--sim", "--realtime", "--duration", "1"});
  EXPECT_EQ(plain.exit_code, 2) << plain.err;
  EXPECT_NE(plain.err.find("already exists"), std::string::npos) << plain.err;
  // The first recorder finishes undisturbed.
  for (int i = 0; i < 300; ++i) {
    if (test::read_file(dir + "/first.txt").find("recorded ") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  auto reader = log::SessionLogReader::open(log_path);
  ASSERT_TRUE(reader.ok()) << reader.error().message << "\n" << test::read_file(dir + "/first.txt");
  EXPECT_TRUE((*reader)->health().complete) << test::read_file(dir + "/first.txt");
  EXPECT_GT(*(*reader)->imu_count(*(*reader)->find_imu_stream()), 400);
}

}  // namespace
}  // namespace imucal
