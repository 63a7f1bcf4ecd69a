// The stored calibration (app/stored_calibration.hpp): payloads from the static and camimu result
// files and their merge, validation, and the round trip through a file-backed storage region.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "app/camimu_results.hpp"
#include "app/result_writers.hpp"
#include "app/stored_calibration.hpp"
#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/storage_device.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

using nlohmann::json;

std::string write_static(const std::string& dir, const std::string& stream = "imu0") {
  calib::StaticCalibrationResult r;
  r.canonical.A_a << 5.9e-4, -5.8e-6, -1.9e-5, 0, 5.9e-4, -1.4e-5, 0, 0, 5.8e-4;
  r.canonical.b_a = Eigen::Vector3d(324.2, 805.4, -850.44);
  r.canonical.A_g << 1.3e-4, -8.3e-7, -4.2e-6, -2.3e-6, 1.35e-4, -1.0e-6, 2.5e-6, -3.4e-6, 1.3e-4;
  r.canonical.b_g = Eigen::Vector3d(7.4, -16.5, 49.75);
  r.canonical.G << 1e-4, 2e-5, -3e-4, 0, 0, 1e-5, 0, 0, 0;
  r.accel_sigma.bias = Eigen::Vector3d(1.5, 1.3, 1.2);
  r.gravity_mps2 = 9.81;
  ImuStreamInfo info;
  info.name = stream;
  info.units = ImuUnits::kRaw;
  const std::string path = dir + "/static-" + stream + ".yaml";
  EXPECT_TRUE(write_text_file(path, static_result_yaml(r, info), OutputPolicy{true, {}}).ok());
  return path;
}

std::string write_camimu(const std::string& dir, bool fixed_intrinsics) {
  CamImuReport r;
  r.imu_stream.name = "imu0";
  r.imu_stream.units = ImuUnits::kRaw;
  r.imu_stream.accel.scale = Eigen::Vector3d::Constant(4.0 * 9.80665 / 32768.0);
  r.imu_stream.gyro.scale = Eigen::Vector3d::Constant(500.0 / 32768.0 * M_PI / 180.0);
  auto& res = r.result;
  res.imu.S_a = {0.99, 1.01, 1.02};
  res.imu.b_g = {0.03, 0.05, 0.06};
  res.imu_sigma.S_a = {1e-4, 2e-4, 3e-4};
  res.canonical = *canonical_from_krebs(res.imu);
  if (fixed_intrinsics) res.fixed = {"S_a", "M_a", "S_g", "M_g", "C_bg"};
  CamImuCameraResult c;
  c.stream = "cam0";
  c.T_cam_imu.translation() = Eigen::Vector3d(0.03, -0.02, 0.01);
  c.timeshift_cam_imu_s = 0.0042;
  c.timeshift_sigma_s = 1.4e-4;
  res.cameras.push_back(c);
  const std::string out = dir + "/camimu";
  std::filesystem::create_directories(out);
  EXPECT_TRUE(
      write_text_file(out + "/calibration.yaml", camimu_calibration_yaml(r), OutputPolicy{true, {}}).ok());
  return out;
}

RigConfig file_config(const std::string& dir, int size_bytes = 4096) {
  RigConfig c;
  c.name = "bench-rig";
  c.storage.backend = StorageBackend::kFile;
  c.storage.path = dir + "/calibration.bin";
  c.storage.size_bytes = size_bytes;
  c.storage.offset_bytes = 512;
  return c;
}

TEST(StoredCalibration, StaticResultGivesTheCanonicalImu) {
  const std::string dir = test::scratch_dir();
  auto p = calibration_payload_from_file(write_static(dir));
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ((*p)["format"], kCalibrationFormat);
  EXPECT_EQ((*p)["imu"]["source"], "static");
  EXPECT_EQ((*p)["imu"]["input_units"], "raw");
  EXPECT_DOUBLE_EQ((*p)["imu"]["b_a"][2].get<double>(), -850.44);
  EXPECT_DOUBLE_EQ((*p)["imu"]["A_g"][1][1].get<double>(), 1.35e-4);
  EXPECT_DOUBLE_EQ((*p)["imu"]["sigma"]["accel"]["bias"][0].get<double>(), 1.5);
  EXPECT_TRUE((*p)["cameras"].empty());
}

TEST(StoredCalibration, CamimuResultGivesImuAndCameras) {
  const std::string dir = test::scratch_dir();
  auto p = calibration_payload_from_file(write_camimu(dir, false));  // the folder
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ((*p)["imu"]["source"], "camimu");
  ASSERT_EQ((*p)["cameras"].size(), 1u);
  const json& cam = (*p)["cameras"][0];
  EXPECT_EQ(cam["name"], "cam0");
  EXPECT_DOUBLE_EQ(cam["T_cam_imu"][0][3].get<double>(), 0.03);
  EXPECT_DOUBLE_EQ(cam["timeshift_cam_imu_s"].get<double>(), 0.0042);
}

TEST(StoredCalibration, MergeTakesTheImuFromStaticAndTheCamerasFromCamimu) {
  const std::string dir = test::scratch_dir();
  const std::string stat = write_static(dir);
  for (bool fixed : {false, true}) {
    auto p = calibration_payload_from_files({write_camimu(dir, fixed), stat});
    ASSERT_TRUE(p.ok()) << p.error().message;
    EXPECT_EQ((*p)["imu"]["source"], "static");
    EXPECT_EQ((*p)["cameras"].size(), 1u);
    EXPECT_EQ((*p)["source"]["files"].size(), 2u);
    const std::string note = (*p)["source"]["notes"][0];
    EXPECT_EQ(note.find("estimated its own IMU intrinsics") != std::string::npos, !fixed) << note;
  }
  EXPECT_EQ(calibration_payload_from_files({stat, stat}).error().code, Errc::kInvalidArgument);
  auto other = calibration_payload_from_files({write_static(dir, "imu1"), write_camimu(dir, true)});
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.error().message.find("different IMU"), std::string::npos) << other.error().message;
}

TEST(StoredCalibration, OtherFilesAreRefusedWithTheReason) {
  const std::string dir = test::scratch_dir();
  std::ofstream(dir + "/x.yaml") << "method: something else\n";
  EXPECT_EQ(calibration_payload_from_file(dir + "/x.yaml").error().code, Errc::kCorrupt);
  EXPECT_EQ(calibration_payload_from_file(dir + "/none.yaml").error().code, Errc::kNotFound);
  std::ofstream(dir + "/bad.yaml") << "method: static multi-position (Tedaldi 2013)\ncanonical: {A_a: 3}\n";
  EXPECT_EQ(calibration_payload_from_file(dir + "/bad.yaml").error().code, Errc::kCorrupt);
}

TEST(StoredCalibration, ValidationChecksShapes) {
  const std::string dir = test::scratch_dir();
  json p = *calibration_payload_from_file(write_static(dir));
  EXPECT_TRUE(validate_calibration_payload(p).ok());
  json bad = p;
  bad["imu"]["A_a"][1] = json::array({1, 2});
  EXPECT_FALSE(validate_calibration_payload(bad).ok());
  bad = p;
  bad["version"] = 2;
  EXPECT_FALSE(validate_calibration_payload(bad).ok());
  bad = p;
  bad["cameras"] = json::array({json{{"name", "cam0"}, {"T_cam_imu", json::array({1, 2, 3})}}});
  EXPECT_FALSE(validate_calibration_payload(bad).ok());
}

TEST(StoredCalibration, WritesReadsAndExportsThroughAFile) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir);
  auto empty = read_stored_calibration(config);
  ASSERT_TRUE(empty.ok()) << empty.error().message;
  EXPECT_FALSE(empty->payload);
  EXPECT_FALSE(empty->note.empty());

  const json p = *calibration_payload_from_files({write_static(dir), write_camimu(dir, true)});
  for (int i = 0; i < 3; ++i) {
    auto w = write_stored_calibration(config, p);
    ASSERT_TRUE(w.ok()) << w.error().message;
    EXPECT_EQ(w->slot, i % 2);
    EXPECT_EQ(w->sequence, static_cast<std::uint32_t>(i + 1));
  }
  auto r = read_stored_calibration(config);
  ASSERT_TRUE(r.ok() && r->payload);
  EXPECT_EQ((*r->payload)["rig"], "bench-rig");
  EXPECT_TRUE(same_calibration(*r->payload, p));
  EXPECT_EQ(r->slots.size(), 2u);
  // The YAML export reads back as the same calibration (store verify EXPORT.yaml).
  std::ofstream(dir + "/export.yaml") << stored_calibration_yaml(*r->payload);
  auto back = calibration_payload_from_file(dir + "/export.yaml");
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(same_calibration(*back, p));
  EXPECT_EQ(*back, *r->payload);
}

TEST(StoredCalibration, APayloadTooLargeForTheRegionIsRefusedAndNothingWritten) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir, 256);
  const json p = *calibration_payload_from_file(write_static(dir));
  auto w = write_stored_calibration(config, p);
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.error().code, Errc::kInvalidArgument);
  auto r = read_stored_calibration(config);
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE(r->payload);
}

TEST(StoredCalibration, AnIntactRecordWithAForeignPayloadIsCorrupt) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir);
  auto dev = drivers::open_storage_device(config.storage, drivers::StorageAccess::kWrite);
  ASSERT_TRUE(dev.ok());
  auto store = drivers::CalibrationStore::open(**dev, 512, 4096);
  ASSERT_TRUE(store.ok());
  const std::vector<std::uint8_t> junk = {0xFF, 0xFE, 0x00, 0x01};  // not CBOR of a calibration
  ASSERT_TRUE(store->write(junk).ok());
  auto r = read_stored_calibration(config);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kCorrupt);
  EXPECT_NE(r.error().message.find("slot A"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace imucal::app
