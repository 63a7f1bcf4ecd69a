// SPDX-License-Identifier: BSD-3-Clause
// The stored calibration (app/stored_calibration.hpp): records from the static and camimu results
// (typed, and through their files) and their merge, the cameras an IMU-only session keeps, and the
// round trip (write, read, export, rollback) through a file-backed storage region.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "app/results/camimu_results.hpp"
#include "app/results/output.hpp"
#include "app/results/static_results.hpp"
#include "app/rig/stored_calibration.hpp"
#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/storage_device.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

using nlohmann::json;

calib::StaticCalibrationResult static_result();

std::string write_static(const std::string& dir, const std::string& stream = "imu0") {
  const calib::StaticCalibrationResult r = static_result();
  ImuStreamInfo info;
  info.name = stream;
  info.units = ImuUnits::kRaw;
  const std::string path = dir + "/static-" + stream + ".yaml";
  EXPECT_TRUE(write_text_file(path, static_result_yaml(r, info), OutputPolicy{true, {}}).ok());
  return path;
}

CamImuReport camimu_report(bool fixed_intrinsics) {
  CamImuReport r;
  r.imu_stream.name = "imu0";
  r.imu_stream.units = ImuUnits::kRaw;
  r.imu_stream.accel.scale = Eigen::Vector3d::Constant(4.0 * 9.80665 / 32768.0);
  r.imu_stream.gyro.scale = Eigen::Vector3d::Constant(500.0 / 32768.0 * M_PI / 180.0);
  auto& res = r.result;
  res.imu.S_a = {0.99, 1.01, 1.02};
  res.imu.b_g = {0.03, 0.05, 0.06};
  res.imu_sigma.S_a = {1e-4, 2e-4, 3e-4};  // the rest not determined
  res.canonical = *canonical_from_krebs(res.imu);
  if (fixed_intrinsics) res.fixed = {"S_a", "M_a", "S_g", "M_g", "C_bg"};
  CamImuCameraResult c;
  c.stream = "cam0";
  c.camera.intrinsics = Eigen::Vector4d(458.6, 457.3, 367.2, 248.4);
  c.camera.distortion_coeffs = Eigen::Vector4d(-0.28, 0.07, 2e-4, 2e-5);
  c.camera.width = 752;
  c.camera.height = 480;
  c.T_cam_imu.translation() = Eigen::Vector3d(0.03, -0.02, 0.01);
  c.timeshift_cam_imu_s = 0.0042;
  c.timeshift_sigma_s = 1.4e-4;
  res.cameras.push_back(c);
  return r;
}

std::string write_camimu(const std::string& dir, bool fixed_intrinsics) {
  const CamImuReport r = camimu_report(fixed_intrinsics);
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

calib::StaticCalibrationResult static_result() {
  calib::StaticCalibrationResult r;
  r.canonical.A_a << 5.9e-4, -5.8e-6, -1.9e-5, 0, 5.9e-4, -1.4e-5, 0, 0, 5.8e-4;
  r.canonical.b_a = Eigen::Vector3d(324.2, 805.4, -850.44);
  r.canonical.A_g << 1.3e-4, -8.3e-7, -4.2e-6, -2.3e-6, 1.35e-4, -1.0e-6, 2.5e-6, -3.4e-6, 1.3e-4;
  r.canonical.b_g = Eigen::Vector3d(7.4, -16.5, 49.75);
  r.canonical.G << 1e-4, 2e-5, -3e-4, 0, 0, 1e-5, 0, 0, 0;
  r.accel_sigma.bias = Eigen::Vector3d(1.5, 1.3, 1.2);
  r.gravity_mps2 = 9.81;
  return r;
}

TEST(StoredCalibration, StaticResultGivesTheCanonicalImu) {
  const std::string dir = test::scratch_dir();
  auto p = calibration_record_from_file(write_static(dir));
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->imu.source, "static");
  EXPECT_EQ(p->imu.input_units, "raw");
  EXPECT_DOUBLE_EQ(p->imu.model.b_a[2], -850.44);
  EXPECT_DOUBLE_EQ(p->imu.model.A_g(1, 1), 1.35e-4);
  ASSERT_TRUE(p->imu.sigma.accel);
  EXPECT_DOUBLE_EQ(p->imu.sigma.accel->bias[0], 1.5);
  // The g-sensitivity was not estimated: its sigma is not determined, not the file's zeros.
  ASSERT_TRUE(p->imu.sigma.G);
  EXPECT_TRUE(p->imu.sigma.G->array().isNaN().all());
  EXPECT_TRUE(p->cameras.empty());
}

TEST(StoredCalibration, TheTypedResultsGiveTheRecordTheirFilesGive) {
  // The service builds the record from the solve's results, `store write` from their files:
  // the same calibration either way.
  const std::string dir = test::scratch_dir();
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kRaw;
  const CalibrationRecord typed = calibration_record_from_static(static_result(), info, "imu-static.yaml");
  auto from_file = calibration_record_from_file(write_static(dir));
  ASSERT_TRUE(from_file.ok()) << from_file.error().message;
  EXPECT_TRUE(same_calibration(typed, *from_file)) << calibration_record_json(typed).dump(1) << "\n"
                                                   << calibration_record_json(*from_file).dump(1);
  ASSERT_EQ(typed.files.size(), 1u);
  EXPECT_EQ(typed.files[0].kind, "static");
  ASSERT_TRUE(typed.gravity_mps2);
  EXPECT_DOUBLE_EQ(*typed.gravity_mps2, 9.81);
  // With G estimated its sigma is the solve's.
  calib::StaticCalibrationResult r = static_result();
  r.gsens_mode = GSensitivityMode::kEstimate;
  r.gsens_sigma = Eigen::Matrix3d::Constant(2e-6);
  EXPECT_DOUBLE_EQ((*calibration_record_from_static(r, info, "x").imu.sigma.G)(2, 1), 2e-6);
}

TEST(StoredCalibration, CamimuResultGivesImuAndCameras) {
  const std::string dir = test::scratch_dir();
  auto p = calibration_record_from_file(write_camimu(dir, false));  // the folder
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->imu.source, "camimu");
  ASSERT_TRUE(p->imu.sigma.krebs);
  EXPECT_DOUBLE_EQ(p->imu.sigma.krebs->S_a[1], 2e-4);
  EXPECT_TRUE(std::isnan(p->imu.sigma.krebs->M_g[0]));  // not determined
  ASSERT_EQ(p->cameras.size(), 1u);
  const CameraRecord& cam = p->cameras[0];
  EXPECT_EQ(cam.name, "cam0");
  EXPECT_DOUBLE_EQ(cam.T_cam_imu(0, 3), 0.03);
  EXPECT_DOUBLE_EQ(cam.timeshift_cam_imu_s, 0.0042);
  EXPECT_TRUE(std::isnan(cam.rotation_sigma_rad[0]));
}

TEST(StoredCalibration, TheTypedCamimuReportGivesTheRecordItsFileGives) {
  const std::string dir = test::scratch_dir();
  for (bool fixed : {false, true}) {
    const CalibrationRecord typed = calibration_record_from_camimu(camimu_report(fixed), "calibration.yaml");
    auto from_file = calibration_record_from_file(write_camimu(dir, fixed));
    ASSERT_TRUE(from_file.ok()) << from_file.error().message;
    EXPECT_TRUE(same_calibration(typed, *from_file)) << calibration_record_json(typed).dump(1) << "\n"
                                                     << calibration_record_json(*from_file).dump(1);
    ASSERT_EQ(typed.files.size(), 1u);
    ASSERT_TRUE(typed.files[0].fixed);
    EXPECT_EQ(typed.files[0].fixed->size(), fixed ? 5u : 0u);
  }
}

TEST(StoredCalibration, MergeTakesTheImuFromStaticAndTheCamerasFromCamimu) {
  const std::string dir = test::scratch_dir();
  const std::string stat = write_static(dir);
  for (bool fixed : {false, true}) {
    auto p = calibration_record_from_files({write_camimu(dir, fixed), stat});
    ASSERT_TRUE(p.ok()) << p.error().message;
    EXPECT_EQ(p->imu.source, "static");
    EXPECT_EQ(p->cameras.size(), 1u);
    EXPECT_EQ(p->files.size(), 2u);
    ASSERT_EQ(p->notes.size(), 1u);
    EXPECT_EQ(p->notes[0].find("estimated its own IMU intrinsics") != std::string::npos, !fixed)
        << p->notes[0];
  }
  EXPECT_EQ(calibration_record_from_files({stat, stat}).error().code, Errc::kInvalidArgument);
  auto other = calibration_record_from_files({write_static(dir, "imu1"), write_camimu(dir, true)});
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.error().message.find("different IMU"), std::string::npos) << other.error().message;
}

TEST(StoredCalibration, OtherFilesAreRefusedWithTheReason) {
  const std::string dir = test::scratch_dir();
  std::ofstream(dir + "/x.yaml") << "method: something else\n";
  EXPECT_EQ(calibration_record_from_file(dir + "/x.yaml").error().code, Errc::kCorrupt);
  EXPECT_EQ(calibration_record_from_file(dir + "/none.yaml").error().code, Errc::kNotFound);
  std::ofstream(dir + "/bad.yaml") << "method: static multi-position (Tedaldi 2013)\ncanonical: {A_a: 3}\n";
  EXPECT_EQ(calibration_record_from_file(dir + "/bad.yaml").error().code, Errc::kCorrupt);
  // The typed readers name the file and what is wrong in it.
  const auto damaged = [&](const std::string& path, const std::string& from, const std::string& to) {
    std::string text = test::read_file(path);
    const auto at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    std::ofstream(path, std::ios::trunc) << text;
    auto r = calibration_record_from_file(path);
    EXPECT_FALSE(r.ok());
    return r.ok() ? Error{} : r.error();
  };
  const std::string stat = write_static(dir);
  Error e = damaged(stat, "input_units: raw", "input_units: volts");
  EXPECT_EQ(e.code, Errc::kCorrupt);
  EXPECT_NE(e.message.find(stat + ": "), std::string::npos) << e.message;
  EXPECT_NE(e.message.find("input_units 'volts'"), std::string::npos) << e.message;
  e = damaged(write_static(dir), "b_a: [", "b_a: [.nan, ");
  EXPECT_EQ(e.code, Errc::kCorrupt);
  EXPECT_NE(e.message.find("canonical.b_a: expected 3 numbers"), std::string::npos) << e.message;
  const std::string cam = write_camimu(dir, false) + "/calibration.yaml";
  e = damaged(cam, "timeshift_cam_imu:", "time_shift:");
  EXPECT_EQ(e.code, Errc::kCorrupt);
  EXPECT_NE(e.message.find(cam + ": "), std::string::npos) << e.message;
  EXPECT_NE(e.message.find("timeshift_cam_imu"), std::string::npos) << e.message;
}

TEST(StoredCalibration, AnIMUOnlySessionKeepsTheStoredCameras) {
  const std::string dir = test::scratch_dir();
  StoredCalibration stored;
  stored.sequence = 7;
  stored.record = *calibration_record_from_files({write_static(dir), write_camimu(dir, true)});
  CalibrationRecord fresh = *calibration_record_from_file(write_static(dir));
  const std::string said = keep_stored_cameras(fresh, stored);
  ASSERT_EQ(fresh.cameras.size(), 1u);
  EXPECT_NE(said.find("sequence 7"), std::string::npos) << said;
  ASSERT_FALSE(fresh.notes.empty());
  EXPECT_EQ(fresh.notes.back(), said);
  // A record with cameras keeps its own.
  CalibrationRecord with = *stored.record;
  with.cameras[0].name = "mine";
  EXPECT_EQ(keep_stored_cameras(with, stored), "");
  EXPECT_EQ(with.cameras[0].name, "mine");
}

// Before: an IMU-only session's record replaced one with a thermal model, which was dropped
// without a word (the cameras were kept, with a note).
TEST(StoredCalibration, AStoredThermalModelThatIsNotKeptIsSaidSo) {
  const std::string dir = test::scratch_dir();
  StoredCalibration stored;
  stored.sequence = 4;
  stored.record = *calibration_record_from_file(write_static(dir));
  stored.record->thermal = ThermalModel{};
  stored.record->thermal->reference_c = 35.0;
  CalibrationRecord fresh = *calibration_record_from_file(write_static(dir));
  const std::string said = keep_stored_cameras(fresh, stored);
  EXPECT_FALSE(fresh.thermal) << "a thermal model belongs to the IMU calibration it corrected";
  EXPECT_NE(said.find("the stored thermal model (sequence 4, reference 35.0 deg C) is not kept"),
            std::string::npos)
      << said;
  ASSERT_FALSE(fresh.notes.empty());
  EXPECT_EQ(fresh.notes.back(), said);
}

TEST(StoredCalibration, WritesReadsAndExportsThroughAFile) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir);
  auto empty = read_stored_calibration(config);
  ASSERT_TRUE(empty.ok()) << empty.error().message;
  EXPECT_FALSE(empty->record);
  EXPECT_FALSE(empty->note.empty());

  const CalibrationRecord p = *calibration_record_from_files({write_static(dir), write_camimu(dir, true)});
  for (int i = 0; i < 3; ++i) {
    auto w = write_stored_calibration(config, p);
    ASSERT_TRUE(w.ok()) << w.error().message;
    EXPECT_EQ(w->slot, i % 2);
    EXPECT_EQ(w->sequence, static_cast<std::uint32_t>(i + 1));
  }
  auto r = read_stored_calibration(config);
  ASSERT_TRUE(r.ok() && r->record);
  EXPECT_EQ(r->record->rig, "bench-rig");
  EXPECT_TRUE(same_calibration(*r->record, p));
  EXPECT_EQ(r->slots.size(), 2u);
  // The YAML export reads back as the same calibration (store verify EXPORT.yaml).
  std::ofstream(dir + "/export.yaml") << stored_calibration_yaml(*r->record);
  auto back = calibration_record_from_file(dir + "/export.yaml");
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(same_calibration(*back, p));
  EXPECT_EQ(calibration_record_json(*back), calibration_record_json(*r->record));
  // A rollback restores the previous record (sequence 2) as sequence 4.
  auto rolled = rollback_stored_calibration(config);
  ASSERT_TRUE(rolled.ok()) << rolled.error().message;
  EXPECT_EQ(rolled->restored_sequence, 2u);
  EXPECT_EQ(rolled->written.sequence, 4u);
  EXPECT_TRUE(same_calibration(*rolled->written.record, p));
}

TEST(StoredCalibration, APayloadTooLargeForTheRegionIsRefusedAndNothingWritten) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir, 256);
  const CalibrationRecord p = *calibration_record_from_file(write_static(dir));
  auto w = write_stored_calibration(config, p);
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.error().code, Errc::kInvalidArgument);
  auto r = read_stored_calibration(config);
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE(r->record);
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

// A payload of 200,000 nested one-element arrays is 200 KB of intact record. nlohmann's CBOR
// parser recursed once per level: store read, store verify, store rollback and imucald's session
// start overflowed the stack (SIGSEGV). Now the depth is refused before the parser sees it.
TEST(StoredCalibration, ADeeplyNestedPayloadIsCorruptNotACrash) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir, 1 << 20);
  auto dev = drivers::open_storage_device(config.storage, drivers::StorageAccess::kWrite);
  ASSERT_TRUE(dev.ok());
  auto store = drivers::CalibrationStore::open(**dev, 512, 1 << 20);
  ASSERT_TRUE(store.ok());
  const CalibrationRecord p = *calibration_record_from_file(write_static(dir));
  const std::vector<std::uint8_t> good = nlohmann::json::to_cbor(calibration_record_json(p));
  ASSERT_TRUE(store->write(good).ok());             // slot A: a good record, for the rollback
  std::vector<std::uint8_t> nested(200'000, 0x81);  // array of one item, 200,000 deep
  nested.push_back(0x00);
  ASSERT_TRUE(store->write(nested).ok());  // slot B, the newest
  auto r = read_stored_calibration(config);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::kCorrupt);
  EXPECT_NE(r.error().message.find("slot B"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("deeper than 32 levels"), std::string::npos) << r.error().message;
  // With a good record newest again, a rollback to the nested one is refused for the same reason.
  ASSERT_TRUE(store->write(good).ok());  // slot A again: the nested record is now the older one
  ASSERT_TRUE(read_stored_calibration(config).ok());
  auto rolled = rollback_stored_calibration(config);
  ASSERT_FALSE(rolled.ok());
  EXPECT_NE(rolled.error().message.find("deeper than 32 levels"), std::string::npos)
      << rolled.error().message;
}

// Before: the record of a newer imucal (a newer record version) was taken for an unreadable one,
// and the next write made this imucal's record the newest over it, without a word.
TEST(StoredCalibration, ARecordOfANewerImucalStaysTheNewestUnlessAsked) {
  const std::string dir = test::scratch_dir();
  const RigConfig config = file_config(dir);
  const CalibrationRecord p = *calibration_record_from_file(write_static(dir));
  ASSERT_TRUE(write_stored_calibration(config, p).ok());
  nlohmann::json newer = calibration_record_json(p);
  newer["version"] = kCalibrationRecordVersion + 1;
  {
    auto dev = drivers::open_storage_device(config.storage, drivers::StorageAccess::kWrite);
    ASSERT_TRUE(dev.ok());
    auto store = drivers::CalibrationStore::open(**dev, 512, 4096);
    ASSERT_TRUE(store.ok());
    ASSERT_TRUE(store->write(nlohmann::json::to_cbor(newer)).ok());  // slot B, sequence 2
  }
  auto refused = write_stored_calibration(config, p);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, Errc::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("written by a newer imucal"), std::string::npos)
      << refused.error().message;
  ASSERT_EQ(refused.error().remedies.size(), 1u);
  EXPECT_EQ(refused.error().remedies[0].option, "replace_newer");
  auto replaced = write_stored_calibration(config, p, drivers::StoreWriteOptions{true});
  ASSERT_TRUE(replaced.ok()) << replaced.error().message;
  EXPECT_EQ(replaced->sequence, 3u);
}

}  // namespace
}  // namespace imucal::app
