// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "log/dataset_io.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::log {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

bool same_sample(const ImuSample& a, const ImuSample& b) {
  if (a.t_ns != b.t_ns) return false;
  for (int k = 0; k < 3; ++k) {
    if (!same_bits(a.accel[k], b.accel[k]) || !same_bits(a.gyro[k], b.gyro[k])) return false;
  }
  return true;
}

std::vector<std::uint8_t> tiny_png(int depth) {
  cv::Mat image(6, 8, depth == 16 ? CV_16UC1 : CV_8UC1);
  cv::randu(image, cv::Scalar(0), cv::Scalar(depth == 16 ? 65535 : 255));
  std::vector<std::uint8_t> png;
  EXPECT_TRUE(cv::imencode(".png", image, png));
  return png;
}

struct SyntheticDataset {
  std::vector<ImuSample> imu;                                         // imu0 as written
  std::map<std::string, std::vector<std::vector<std::uint8_t>>> png;  // per camera
  std::map<std::string, std::vector<TimeNs>> frame_t;
  std::string imu_sensor_yaml;
};

/// A small EuRoC folder: imu0 (200 Hz, values with long digit strings as in the real
/// datasets), cam0 (8-bit PNGs, with sensor.yaml) and cam1 (16-bit PNGs, without).
SyntheticDataset write_dataset(const fs::path& dir) {
  SyntheticDataset d;
  std::mt19937_64 rng(42);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::string csv =
      "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
      "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
  const TimeNs t0 = 1403636579758555392;
  for (int i = 0; i < 200; ++i) {
    ImuSample s;
    s.t_ns = t0 + i * 5'000'000 + (i % 7);  // irregular last digits
    std::string row = std::to_string(s.t_ns);
    for (int k = 0; k < 6; ++k) {
      const double v = (k < 3 ? 0.1 : 3.0) * noise(rng) + (k == 5 ? 9.81 : 0.0);
      char buf[40];
      std::snprintf(buf, sizeof buf, "%.17g", v);  // as many digits as the EuRoC files carry
      (k < 3 ? s.gyro[k] : s.accel[k - 3]) = std::strtod(buf, nullptr);
      row += std::string(",") + buf;
    }
    csv += row + "\n";
    d.imu.push_back(s);
  }
  test::write_file(dir / "mav0/imu0/data.csv", csv);
  d.imu_sensor_yaml =
      "#Default imu sensor yaml file\nsensor_type: imu\ncomment: VI-Sensor IMU (ADIS16448)\nT_BS:\n  cols: "
      "4\n"
      "  rows: 4\n  data: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]\n"
      "rate_hz: 200\n\ngyroscope_noise_density: 1.6968e-04\n";
  test::write_file(dir / "mav0/imu0/sensor.yaml", d.imu_sensor_yaml);
  for (const std::string cam : {"cam0", "cam1"}) {
    std::string rows = "#timestamp [ns],filename\n";
    const int depth = cam == "cam0" ? 8 : 16;
    for (int i = 0; i < 3; ++i) {
      const TimeNs t = t0 + i * 50'000'000 + (cam == "cam1" ? 1'000 : 0);
      auto png = tiny_png(depth);
      const std::string name = std::to_string(t) + ".png";
      fs::create_directories(dir / "mav0" / cam / "data");
      std::ofstream(dir / "mav0" / cam / "data" / name, std::ios::binary)
          .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
      rows += std::to_string(t) + "," + name + "\n";
      d.png[cam].push_back(png);
      d.frame_t[cam].push_back(t);
    }
    test::write_file(dir / "mav0" / cam / "data.csv", rows);
  }
  test::write_file(
      dir / "mav0/cam0/sensor.yaml",
      "sensor_type: camera\ncomment: tiny\nrate_hz: 20\nresolution: [8, 6]\ncamera_model: pinhole\n"
      "intrinsics: [458.654, 457.296, 367.215, 248.375]\n");
  return d;
}

struct LogContents {
  std::map<std::string, ImuStreamInfo> imu_info;
  std::map<std::string, CameraStreamInfo> cam_info;
  std::map<std::string, std::vector<ImuSample>> imu;
  std::map<std::string, std::vector<CameraFrame>> frames;
};

LogContents read_contents(const std::string& path) {
  LogContents c;
  auto reader = SessionLogReader::open(path);
  EXPECT_TRUE(reader.ok()) << reader.error().message;
  if (!reader.ok()) return c;
  const SessionLogReader& r = **reader;
  EXPECT_TRUE(r.health().complete);
  EXPECT_FALSE(r.health().damaged);
  for (const auto& [id, info] : r.imu_streams()) {
    c.imu_info[info.name] = info;
    auto samples = r.read_imu(id);
    EXPECT_TRUE(samples.ok());
    if (samples.ok()) c.imu[info.name] = *samples;
  }
  for (const auto& [id, info] : r.camera_streams()) {
    c.cam_info[info.name] = info;
    auto& frames = c.frames[info.name];
    EXPECT_TRUE(r.for_each_frame(id, kTimeMin, kTimeMax, [&](const CameraFrame& f) {
                   frames.push_back(f);
                   return true;
                 }).ok());
  }
  return c;
}

std::vector<std::string> partial_files(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().filename().string().find(".partial-") != std::string::npos) out.push_back(e.path().string());
  }
  return out;
}

TEST(DatasetEurocRoundTrip, ExportImportReproducesEveryValueBitForBit) {
  const fs::path dir = test::scratch_dir();
  const SyntheticDataset d = write_dataset(dir / "in");

  auto first = import_euroc((dir / "in").string(), (dir / "a.imulog").string(), {});
  ASSERT_TRUE(first.ok()) << first.error().message;
  EXPECT_EQ(first->imu_samples, 200);
  EXPECT_EQ(first->frames, 6);
  EXPECT_EQ(first->camera_streams, 2);

  const LogContents a = read_contents((dir / "a.imulog").string());
  ASSERT_EQ(a.imu.at("imu0").size(), d.imu.size());
  for (std::size_t i = 0; i < d.imu.size(); ++i) {
    ASSERT_TRUE(same_sample(a.imu.at("imu0")[i], d.imu[i])) << "sample " << i;
  }
  EXPECT_EQ(a.imu_info.at("imu0").units, ImuUnits::kSi);
  EXPECT_EQ(a.imu_info.at("imu0").rate_hz, 200.0);  // from sensor.yaml
  EXPECT_EQ(a.cam_info.at("cam0").width, 8);
  EXPECT_EQ(a.cam_info.at("cam0").height, 6);
  EXPECT_EQ(a.cam_info.at("cam0").rate_hz, 20.0);
  EXPECT_EQ(a.cam_info.at("cam1").width, 8);  // from the first image
  for (const std::string cam : {"cam0", "cam1"}) {
    ASSERT_EQ(a.frames.at(cam).size(), 3u);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(a.frames.at(cam)[i].t_ns, d.frame_t.at(cam)[i]);
      EXPECT_EQ(a.frames.at(cam)[i].encoding, "png");
      EXPECT_EQ(a.frames.at(cam)[i].data, d.png.at(cam)[i]) << cam << " frame " << i << ": PNG bytes changed";
    }
  }

  auto exported = export_euroc((dir / "a.imulog").string(), (dir / "out").string(), {});
  ASSERT_TRUE(exported.ok()) << exported.error().message;
  EXPECT_EQ(exported->imu_samples, 200);
  EXPECT_EQ(exported->frames, 6);
  EXPECT_TRUE(partial_files(dir).empty());
  EXPECT_EQ(test::read_file((dir / "out/mav0/imu0/sensor.yaml").string()), d.imu_sensor_yaml);
  EXPECT_THAT(
      test::read_file((dir / "out/mav0/imu0/data.csv").string()),
      ::testing::StartsWith("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                            "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"));
  EXPECT_EQ(test::read_file((dir / "out/mav0/cam1/data.csv").string()).substr(0, 25),
            "#timestamp [ns],filename\n");
  const std::string png_path =
      (dir / "out/mav0/cam0/data" / (std::to_string(d.frame_t.at("cam0")[1]) + ".png")).string();
  const std::string png_bytes = test::read_file(png_path);
  EXPECT_EQ(std::vector<std::uint8_t>(png_bytes.begin(), png_bytes.end()), d.png.at("cam0")[1]);

  auto second = import_euroc((dir / "out/mav0").string(), (dir / "b.imulog").string(), {});  // accepts mav0/
  ASSERT_TRUE(second.ok()) << second.error().message;
  const LogContents b = read_contents((dir / "b.imulog").string());
  ASSERT_EQ(b.imu.at("imu0").size(), a.imu.at("imu0").size());
  for (std::size_t i = 0; i < a.imu.at("imu0").size(); ++i) {
    ASSERT_TRUE(same_sample(a.imu.at("imu0")[i], b.imu.at("imu0")[i])) << "sample " << i;
  }
  EXPECT_EQ(b.imu_info.at("imu0").rate_hz, a.imu_info.at("imu0").rate_hz);
  for (const std::string cam : {"cam0", "cam1"}) {
    ASSERT_EQ(b.frames.at(cam).size(), 3u);
    EXPECT_EQ(b.cam_info.at(cam).width, a.cam_info.at(cam).width);
    EXPECT_EQ(b.cam_info.at(cam).height, a.cam_info.at(cam).height);
    EXPECT_EQ(b.cam_info.at(cam).rate_hz, a.cam_info.at(cam).rate_hz);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(b.frames.at(cam)[i].t_ns, a.frames.at(cam)[i].t_ns);
      EXPECT_EQ(b.frames.at(cam)[i].data, a.frames.at(cam)[i].data);
    }
  }

  // A second export writes byte-identical CSVs.
  ASSERT_TRUE(export_euroc((dir / "b.imulog").string(), (dir / "out2").string(), {}).ok());
  for (const char* f : {"mav0/imu0/data.csv", "mav0/cam0/data.csv", "mav0/cam1/data.csv"}) {
    EXPECT_EQ(test::read_file((dir / "out" / f).string()), test::read_file((dir / "out2" / f).string())) << f;
  }
}

TEST(DatasetEuroc, MissingImageFailsWithLineAndLeavesNothing) {
  const fs::path dir = test::scratch_dir();
  const SyntheticDataset d = write_dataset(dir / "in");
  fs::remove(dir / "in/mav0/cam0/data" / (std::to_string(d.frame_t.at("cam0")[2]) + ".png"));
  auto r = import_euroc((dir / "in").string(), (dir / "x.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("cam0/data.csv:4: image"));
  EXPECT_THAT(r.error().message, HasSubstr("missing"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));
  EXPECT_TRUE(partial_files(dir).empty());
}

// Above OutputOptions::in_memory_bytes the IMU files are read twice (checked, then written as
// they are read again): the same log as when they are held.
TEST(DatasetEuroc, ReadTwiceInsteadOfHeldTheSameLog) {
  const fs::path dir = test::scratch_dir();
  const SyntheticDataset d = write_dataset(dir / "in");
  auto held = import_euroc((dir / "in").string(), (dir / "held.imulog").string(), {});
  ASSERT_TRUE(held.ok()) << held.error().message;
  OutputOptions streamed;
  streamed.in_memory_bytes = 0;
  auto twice = import_euroc((dir / "in").string(), (dir / "twice.imulog").string(), streamed);
  ASSERT_TRUE(twice.ok()) << twice.error().message;
  EXPECT_EQ(twice->imu_samples, held->imu_samples);
  EXPECT_EQ(twice->t_first_ns, held->t_first_ns);
  EXPECT_EQ(twice->t_last_ns, held->t_last_ns);
  const LogContents a = read_contents((dir / "held.imulog").string());
  const LogContents b = read_contents((dir / "twice.imulog").string());
  ASSERT_EQ(b.imu.at("imu0").size(), d.imu.size());
  for (std::size_t i = 0; i < d.imu.size(); ++i) EXPECT_TRUE(same_sample(b.imu.at("imu0")[i], d.imu[i])) << i;
  EXPECT_EQ(a.imu_info.at("imu0").rate_hz, b.imu_info.at("imu0").rate_hz);
  EXPECT_EQ(a.frames.at("cam0").size(), b.frames.at("cam0").size());
}

TEST(DatasetEuroc, MalformedCsvNamesFileAndLine) {
  const fs::path dir = test::scratch_dir();
  write_dataset(dir / "in");
  std::string csv = test::read_file((dir / "in/mav0/imu0/data.csv").string());
  csv += "1403636580758555392,0.1,0.2,oops,1,2,3\n";
  test::write_file(dir / "in/mav0/imu0/data.csv", csv);
  auto r = import_euroc((dir / "in").string(), (dir / "x.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("imu0/data.csv:202: column 4 (w_RS_S_z): 'oops' is not a number"));
  EXPECT_FALSE(fs::exists(dir / "x.imulog"));
  auto not_euroc = import_euroc(dir.string(), (dir / "x.imulog").string(), {});
  ASSERT_FALSE(not_euroc.ok());
  EXPECT_THAT(not_euroc.error().message, HasSubstr("not an EuRoC dataset"));
}

TEST(DatasetEuroc, RefusesToOverwriteUnlessForced) {
  const fs::path dir = test::scratch_dir();
  write_dataset(dir / "in");
  test::write_file(dir / "x.imulog", "precious");
  auto r = import_euroc((dir / "in").string(), (dir / "x.imulog").string(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kAlreadyExists) << r.error().message;
  EXPECT_EQ(test::read_file((dir / "x.imulog").string()), "precious");
  OutputOptions force;
  force.force = true;
  ASSERT_TRUE(import_euroc((dir / "in").string(), (dir / "x.imulog").string(), force).ok());
  EXPECT_EQ(read_contents((dir / "x.imulog").string()).imu.at("imu0").size(), 200u);

  // Export: an earlier export is replaced only with force; any other folder never.
  fs::create_directories(dir / "other");
  test::write_file(dir / "other/notes.txt", "keep me");
  auto into_other = export_euroc((dir / "x.imulog").string(), (dir / "other").string(), force);
  ASSERT_FALSE(into_other.ok());
  EXPECT_THAT(into_other.error().message, HasSubstr("is not an earlier imucal export"));
  EXPECT_EQ(test::read_file((dir / "other/notes.txt").string()), "keep me");
  // A plain file named mav0 does not make a folder an export, nor does mav0/ beside other files.
  test::write_file(dir / "other/mav0", "not a folder");
  auto plain_mav0 = export_euroc((dir / "x.imulog").string(), (dir / "other").string(), force);
  ASSERT_FALSE(plain_mav0.ok());
  EXPECT_EQ(test::read_file((dir / "other/notes.txt").string()), "keep me");
  fs::remove(dir / "other/mav0");
  fs::create_directories(dir / "other/mav0");
  auto mixed = export_euroc((dir / "x.imulog").string(), (dir / "other").string(), force);
  ASSERT_FALSE(mixed.ok());
  EXPECT_THAT(mixed.error().message, HasSubstr("is not an earlier imucal export"));
  EXPECT_EQ(test::read_file((dir / "other/notes.txt").string()), "keep me");
  // A downloaded dataset whose only top-level folder is mav0/ (with its ground truth) is not an
  // export either.
  test::write_file(dir / "downloaded/mav0/state_groundtruth_estimate0/data.csv", "#t\n");
  test::write_file(dir / "downloaded/mav0/imu0/data.csv", "#t\n");
  auto downloaded = export_euroc((dir / "x.imulog").string(), (dir / "downloaded").string(), force);
  ASSERT_FALSE(downloaded.ok());
  EXPECT_TRUE(fs::exists(dir / "downloaded/mav0/state_groundtruth_estimate0/data.csv"));
  // Never into the folder that holds the log, even when it looks like an export.
  fs::create_directories(dir / "logdir/mav0");
  fs::copy_file(dir / "x.imulog", dir / "logdir/x.imulog");
  auto onto_log = export_euroc((dir / "logdir/x.imulog").string(), (dir / "logdir").string(), force);
  ASSERT_FALSE(onto_log.ok());
  EXPECT_THAT(onto_log.error().message, HasSubstr("holds the log being exported"));
  EXPECT_TRUE(fs::exists(dir / "logdir/x.imulog"));
  ASSERT_TRUE(export_euroc((dir / "x.imulog").string(), (dir / "out").string(), {}).ok());
  auto again = export_euroc((dir / "x.imulog").string(), (dir / "out").string(), {});
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, Errc::kAlreadyExists) << again.error().message;
  ASSERT_TRUE(export_euroc((dir / "x.imulog").string(), (dir / "out").string(), force).ok());
  EXPECT_TRUE(fs::exists(dir / "out/mav0/imu0/data.csv"));
  EXPECT_TRUE(partial_files(dir).empty());
}

TEST(DatasetEuroc, RawLogExportsInSiAndGray8FramesAsPng) {
  const fs::path dir = test::scratch_dir();
  const std::string log = (dir / "raw.imulog").string();
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kRaw;
  info.rate_hz = 1000.0;
  info.accel.scale = Eigen::Vector3d::Constant(9.80665 / 8192.0);
  info.accel.offset = Eigen::Vector3d(10, -20, 30);
  info.gyro.scale = Eigen::Vector3d::Constant(M_PI / 180.0 / 65.5);
  std::vector<ImuSample> samples(5);
  for (int i = 0; i < 5; ++i) {
    samples[static_cast<std::size_t>(i)].t_ns = 1'000'000 * i;
    samples[static_cast<std::size_t>(i)].accel = Eigen::Vector3d(100 + i, -200, 8192);
    samples[static_cast<std::size_t>(i)].gyro = Eigen::Vector3d(-3, 4, 5 + i);
  }
  CameraStreamInfo cam;
  cam.name = "cam0";
  cam.width = 4;
  cam.height = 2;
  cam.rate_hz = 10;
  cam.backend = "sim";
  CameraFrame frame;
  frame.t_ns = 2'000'000;
  frame.width = 4;
  frame.height = 2;
  frame.encoding = "gray8";
  frame.data = {0, 10, 20, 30, 40, 50, 60, 70};
  {
    auto w = SessionLogWriter::create(log);
    ASSERT_TRUE(w.ok()) << w.error().message;
    auto id = (*w)->add_imu_stream(info);
    ASSERT_TRUE(id.ok());
    ASSERT_TRUE((*w)->append_imu(*id, samples).ok());
    auto cid = (*w)->add_camera_stream(cam);
    ASSERT_TRUE(cid.ok());
    ASSERT_TRUE((*w)->append_frame(*cid, frame).ok());
    ASSERT_TRUE((*w)->close().ok());
  }
  auto r = export_euroc(log, (dir / "out").string(), {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_FALSE(r->notes.empty());
  EXPECT_THAT(r->notes[0], HasSubstr("raw counts"));
  auto csv = test::read_file((dir / "out/mav0/imu0/data.csv").string());
  auto parsed = parse_euroc_imu_csv(csv, "data.csv");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  ASSERT_EQ(parsed->size(), 5u);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ((*parsed)[i].t_ns, samples[i].t_ns);
    const Eigen::Vector3d a = info.accel.to_si(samples[i].accel);
    const Eigen::Vector3d g = info.gyro.to_si(samples[i].gyro);
    for (int k = 0; k < 3; ++k) {
      EXPECT_TRUE(same_bits((*parsed)[i].accel[k], a[k]));
      EXPECT_TRUE(same_bits((*parsed)[i].gyro[k], g[k]));
    }
  }
  EXPECT_THAT(test::read_file((dir / "out/mav0/imu0/sensor.yaml").string()), HasSubstr("rate_hz: 1000"));
  EXPECT_THAT(test::read_file((dir / "out/mav0/cam0/sensor.yaml").string()), HasSubstr("resolution: [4, 2]"));
  const cv::Mat png = cv::imread((dir / "out/mav0/cam0/data/2000000.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(png.empty());
  ASSERT_EQ(png.type(), CV_8UC1);
  EXPECT_EQ(png.at<std::uint8_t>(1, 3), 70);
  EXPECT_EQ(png.at<std::uint8_t>(0, 1), 10);
}

}  // namespace
}  // namespace imucal::log
