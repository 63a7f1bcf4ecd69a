// SPDX-License-Identifier: BSD-3-Clause
// The calibration record (core/calibration_record.hpp): its JSON form in both directions, a record
// as an earlier build stored it, undetermined figures, and the checks of a malformed record.

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "core/calibration_payload.hpp"
#include "core/calibration_record.hpp"

namespace imucal {
namespace {

using nlohmann::json;

// The record `make demo` stored with the build before the record was typed (read back with
// `imucal store read --json`): the storage of rigs calibrated then holds records like it.
constexpr const char* kStoredByAnEarlierBuild =
    R"json({"cameras": [{"T_cam_imu": [[-0.9994694294606155, 0.029483445653512474, 0.013841459679841621, 0.03101344097264715], [-0.029160265550715967, -0.9993101688041897, 0.022997074543385097, -0.01819928720587483], [0.014509944406648583, 0.02258125233326663, 0.9996397093735209, -0.013997470094002682], [0, 0, 0, 1]], "name": "cam0", "rotation_sigma_rad": [4.843253987650967e-05, 5.909809406232593e-05, 9.237118193877512e-05], "stream": "cam0", "timeshift_cam_imu_s": -1.1909327537913869e-05, "timeshift_sigma_s": 1.6104854448790493e-05, "translation_sigma_m": [0.0009152678702851214, 0.0006685207613580963, 0.0010802447793139078]}], "created_utc": "2026-11-28T06:02:45Z", "format": "imucal.calibration", "gravity_mps2": 9.80665, "imu": {"A_a": [[0.00116967421393, -3.50289727457e-05, 3.87040325196e-05], [0, 0.0012307367081, 2.52854663433e-05], [0, 0, 0.00117778870867]], "A_g": [[0.000269229499916, -9.59870817319e-06, 8.74910094785e-06], [1.8043760557e-05, 0.000261087318508, 5.51893877463e-06], [-9.30192856473e-07, -7.42424401812e-06, 0.000271741821973]], "G": [[0.000123680797678, -1.22928958523e-06, -0.000177346384082], [0.000154806296482, -1.39327295285e-05, 9.70671675044e-05], [-0.000115283911482, 0.000127837094992, 8.42497031023e-05]], "b_a": [-359.021175523, 84.8016285529, -86.046915683], "b_g": [-5.03734672308, 143.729422446, -123.30860189], "form": "a = A_a (a_raw - b_a); w = A_g (w_raw - b_g) - G a", "input_units": "raw", "sigma": {"G": [[3.19329533951e-06, 3.30538340387e-06, 4.40592576967e-06], [3.16280476724e-06, 2.5206790329e-06, 2.51142161321e-06], [2.64898039535e-06, 5.15608119335e-06, 6.10078020665e-06]], "accel": {"bias": [0.941921436958, 0.788047375267, 1.40939239008], "misalignment": [[0, 0.00019760948498, 0.000284962776912], [0, 0, 0.000250435907312], [0, 0, 0]], "scale": [1.55806780704e-07, 1.5092183594e-07, 2.58780916915e-07]}, "gyro": {"bias": [0.0840335216775, 0.058104510149, 0.129671075654], "misalignment": [[0, 0.000102808363783, 0.000253052268034], [0.000140506115669, 0, 0.000186597781965], [0.000188921499167, 0.000239147740741, 0]], "scale": [2.92407725714e-08, 2.74229333714e-08, 5.55693002691e-08]}, "model": "tedaldi: corrected = misalignment * diag(scale) * (raw - bias)"}, "source": "static", "stream": "imu0"}, "rig": "sim", "software_version": "0.1.0", "source": {"files": [{"kind": "static", "method": "static multi-position (Tedaldi 2013)", "path": "/tmp/demo-old/state/sessions/sim-20261128T055536Z/imu-static.yaml"}, {"fixed": ["S_a", "M_a", "S_g", "M_g", "C_bg", "B_g"], "kind": "camimu", "method": "continuous-time camera-IMU (Krebs 2012)", "path": "/tmp/demo-old/state/sessions/sim-20261128T055536Z/camimu/calibration.yaml"}], "notes": ["imu from the static result; cameras from the camimu result"]}, "version": 1})json";

CalibrationRecord a_record() {
  CalibrationRecord r;
  r.created_utc = "2026-11-28T06:00:00Z";
  r.software_version = "0.1.0";
  r.rig = "bench";
  r.imu.stream = "imu0";
  r.imu.input_units = "raw";
  r.imu.model.A_a = Eigen::Matrix3d::Identity() * 1.2e-3;
  r.imu.model.b_a = Eigen::Vector3d(-359.02, 84.8, -86.05);
  r.imu.model.G(0, 2) = 1.7e-4;
  r.imu.source = "static";
  r.imu.sigma.model = "tedaldi: corrected = misalignment * diag(scale) * (raw - bias)";
  TriadSigma t;
  t.bias = Eigen::Vector3d(0.9, 0.8, 1.4);
  t.scale = Eigen::Vector3d(1.5e-7, kNotDetermined, 2.6e-7);
  r.imu.sigma.accel = t;
  r.imu.sigma.gyro = t;
  r.imu.sigma.G = Eigen::Matrix3d::Constant(kNotDetermined);
  CameraRecord c;
  c.name = "cam0";
  c.stream = "cam0";
  c.T_cam_imu(0, 3) = 0.031;
  c.rotation_sigma_rad = Eigen::Vector3d(4.8e-5, 5.9e-5, 9.2e-5);
  c.timeshift_cam_imu_s = -1.2e-5;
  r.cameras.push_back(c);  // translation and time-shift sigmas not determined
  r.gravity_mps2 = 9.80665;
  r.files.push_back({"imu-static.yaml", "static", "static multi-position (Tedaldi 2013)", std::nullopt});
  r.files.push_back({"calibration.yaml", "camimu", "continuous-time camera-IMU (Krebs 2012)",
                     std::vector<std::string>{"S_a", "M_a"}});
  r.notes.push_back("imu from the static result; cameras from the camimu result");
  return r;
}

TEST(CalibrationRecord, ItsJsonFormReadsBackAsTheSameRecordThroughCbor) {
  const CalibrationRecord r = a_record();
  const json j = calibration_record_json(r);
  EXPECT_EQ(j["format"], kCalibrationFormat);
  EXPECT_EQ(j["version"], 1);  // no thermal model: readable by the builds that read version 1
  EXPECT_EQ(j["cameras"][0]["rotation_sigma_rad"][0].get<double>(), 4.8e-5);  // as versions 1 and 2 wrote it
  // Figures that were not determined are null, never 0.
  EXPECT_TRUE(j["imu"]["sigma"]["accel"]["scale"][1].is_null());
  EXPECT_TRUE(j["cameras"][0]["translation_sigma_m"][0].is_null());
  EXPECT_TRUE(j["cameras"][0]["timeshift_sigma_s"].is_null());
  EXPECT_FALSE(j["source"]["files"][0].contains("fixed"));
  EXPECT_EQ(j["source"]["files"][1]["fixed"].size(), 2u);
  auto back = calibration_record_from_json(json::from_cbor(json::to_cbor(j)));
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(same_calibration(*back, r));
  EXPECT_EQ(calibration_record_json(*back), j);
  EXPECT_EQ(back->rig, "bench");
  EXPECT_EQ(back->notes, r.notes);
  ASSERT_TRUE(back->files[1].fixed);
  EXPECT_EQ(*back->files[1].fixed, (std::vector<std::string>{"S_a", "M_a"}));
  EXPECT_TRUE(std::isnan(back->imu.sigma.accel->scale[1]));
  EXPECT_TRUE(std::isnan(back->cameras[0].timeshift_sigma_s));
}

TEST(CalibrationRecord, ARecordAnEarlierBuildStoredStillReadsAndWritesBackUnchanged) {
  const json stored = json::parse(kStoredByAnEarlierBuild);
  auto r = calibration_record_from_json(stored);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->rig, "sim");
  EXPECT_EQ(r->imu.source, "static");
  EXPECT_EQ(r->imu.input_units, "raw");
  EXPECT_DOUBLE_EQ(r->imu.model.b_a[0], -359.021175523);
  EXPECT_DOUBLE_EQ(r->imu.model.A_g(2, 2), 0.000271741821973);
  ASSERT_TRUE(r->imu.sigma.accel && r->imu.sigma.gyro && r->imu.sigma.G);
  ASSERT_EQ(r->cameras.size(), 1u);
  EXPECT_DOUBLE_EQ(r->cameras[0].T_cam_imu(0, 3), 0.03101344097264715);
  ASSERT_EQ(r->files.size(), 2u);
  EXPECT_TRUE(r->files[1].fixed);
  // Written again (a rollback restores it this way), it is the same document: the same
  // calibration for every reader, old or new.
  EXPECT_EQ(calibration_record_json(*r), stored);
}

TEST(CalibrationRecord, AMalformedRecordIsRefusedNamingWhatIsWrong) {
  const json good = calibration_record_json(a_record());
  auto refused = [&](const std::function<void(json&)>& spoil, const std::string& says) {
    json j = good;
    spoil(j);
    auto r = calibration_record_from_json(j);
    ASSERT_FALSE(r.ok()) << "accepted a record whose " << says << " is wrong";
    EXPECT_EQ(r.error().code, Errc::kCorrupt);
    EXPECT_NE(r.error().message.find(says), std::string::npos) << r.error().message;
  };
  refused([](json& j) { j["format"] = "other"; }, "not an imucal calibration");
  refused([](json& j) { j["version"] = 0; }, "version 0");
  {
    // A newer version is not damage: named as a newer imucal's, with its own code.
    json j = good;
    j["version"] = 4;
    auto r = calibration_record_from_json(j);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kNewerVersion);
    EXPECT_NE(r.error().message.find("version 4"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("a newer imucal wrote it: update imucal"), std::string::npos);
    j["version"] = 0;
    EXPECT_EQ(calibration_record_from_json(j).error().message.find("newer"), std::string::npos)
        << "an older version than any is not a newer imucal's";
  }
  refused([](json& j) { j["version"] = "2"; }, "version \"2\"");
  refused([](json& j) { j.erase("imu"); }, "no imu");
  refused([](json& j) { j["imu"]["A_a"][1] = json::array({1, 2}); }, "imu.A_a");
  refused([](json& j) { j["imu"]["b_g"][0] = nullptr; }, "imu.b_g");  // a model figure must be there
  refused([](json& j) { j["imu"]["stream"] = 3; }, "imu.stream");
  refused([](json& j) { j["cameras"] = json::object(); }, "cameras must be a list");
  refused([](json& j) { j["cameras"][0]["T_cam_imu"] = json::array({1, 2, 3}); }, "cam0 T_cam_imu");
  refused([](json& j) { j["imu"]["sigma"]["accel"]["bias"] = "big"; }, "imu.sigma.accel.bias");
  refused([](json& j) { j["source"]["notes"] = json::array({1}); }, "source.notes");
}

/// A fisheye camera's intrinsics as a camera-IMU solve held them, one sigma not known.
CameraIntrinsicsRecord some_intrinsics() {
  CameraIntrinsicsRecord k;
  k.camera.projection = ProjectionModel::kPinhole;
  k.camera.distortion_model = DistortionModel::kEquidistant;
  k.camera.intrinsics = Eigen::Vector4d(259.5, 259.1, 172.4, 128.9);
  k.camera.distortion_coeffs = Eigen::Vector4d(-0.03, 0.012, -0.004, 0.0007);
  k.camera.width = 346;
  k.camera.height = 260;
  k.intrinsics_sigma = {0.41, 0.40, 0.22, kNotDetermined};
  k.distortion_coeffs_sigma = {0.002, 0.004, 0.003, 0.001};
  return k;
}

TEST(CalibrationRecord, ACameraWithItsIntrinsicsMakesItVersion3AndReadsBack) {
  CalibrationRecord r = a_record();
  r.cameras[0].intrinsics = some_intrinsics();
  const json j = calibration_record_json(r);
  // Version 3: an older imucal refuses it as a newer one's instead of dropping the intrinsics.
  EXPECT_EQ(j["version"], 3);
  const json& cam = j["cameras"][0]["camera"];
  EXPECT_EQ(cam["camera_model"], "pinhole");
  EXPECT_EQ(cam["distortion_model"], "equidistant");
  EXPECT_EQ(cam["intrinsics"][2], 172.4);
  EXPECT_EQ(cam["resolution"], json::array({346, 260}));
  EXPECT_TRUE(cam["intrinsics_sigma"][3].is_null());  // not known, never 0
  // Its sigmas in single precision (4 bytes of CBOR each), its figures in full.
  EXPECT_EQ(cam["intrinsics_sigma"][0].get<double>(), static_cast<double>(0.41f));
  EXPECT_EQ(j["cameras"][0]["rotation_sigma_rad"][0].get<double>(), static_cast<double>(4.8e-5f));
  EXPECT_EQ(j["cameras"][0]["T_cam_imu"][0][3].get<double>(), 0.031);
  EXPECT_LT(json::to_cbor(j).size(), json::to_cbor(calibration_record_json(a_record())).size() + 250)
      << "a camera's intrinsics with sigmas add less than 250 bytes";
  EXPECT_FALSE(cam.contains("shutter"));  // the record's line_delay_s says it
  auto back = calibration_record_from_json(json::from_cbor(json::to_cbor(j)));
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_TRUE(back->cameras[0].intrinsics);
  EXPECT_TRUE(same_calibration(*back, r));
  EXPECT_EQ(calibration_record_json(*back), j);
  EXPECT_EQ(back->cameras[0].intrinsics->camera.intrinsics[3], 128.9);
  EXPECT_TRUE(std::isnan(back->cameras[0].intrinsics->intrinsics_sigma[3]));
  // A changed focal length is another calibration.
  CalibrationRecord other = *back;
  other.cameras[0].intrinsics->camera.intrinsics[0] += 0.01;
  EXPECT_FALSE(same_calibration(other, r));
  other.cameras[0].intrinsics.reset();
  EXPECT_FALSE(same_calibration(other, r));
}

TEST(CalibrationRecord, MalformedIntrinsicsAreRefusedNamingTheCamera) {
  CalibrationRecord rec = a_record();
  rec.cameras[0].intrinsics = some_intrinsics();
  const json good = calibration_record_json(rec);
  auto refused = [&](const std::function<void(json&)>& spoil, const std::string& says) {
    json j = good;
    spoil(j);
    auto r = calibration_record_from_json(j);
    ASSERT_FALSE(r.ok()) << "accepted intrinsics whose " << says << " is wrong";
    EXPECT_EQ(r.error().code, Errc::kCorrupt);
    EXPECT_NE(r.error().message.find(says), std::string::npos) << r.error().message;
  };
  refused([](json& j) { j["cameras"][0]["camera"] = 3; }, "camera cam0 camera must be a mapping");
  refused([](json& j) { j["cameras"][0]["camera"]["intrinsics"] = json::array({1, 2}); }, "intrinsics");
  refused([](json& j) { j["cameras"][0]["camera"]["camera_model"] = "kannala"; }, "camera_model");
  refused([](json& j) { j["cameras"][0]["camera"]["intrinsics_sigma"] = json::array({1}); },
          "cam0 camera.intrinsics_sigma");
  refused([](json& j) { j["cameras"][0]["camera"].erase("distortion_coeffs_sigma"); },
          "camera.distortion_coeffs_sigma");
}

ThermalModel a_thermal_model() {
  ThermalModel t;
  t.reference_c = 40.0;
  t.min_c = 21.5;
  t.max_c = 58.25;
  for (int i = 0; i < 3; ++i) {
    t.gyro[i].determined = true;
    t.gyro[i].coeffs = Eigen::Vector3d(0.02 + i, -3e-4, 1e-6);
    t.gyro[i].sigma = Eigen::Vector3d(1e-3, 2e-5, kNotDetermined);
    t.accel[i].determined = i != 2;
    t.accel[i].coeffs = i == 0 ? Eigen::VectorXd(Eigen::Vector2d(1.5, -0.01)) : Eigen::VectorXd();
    t.accel[i].sigma = i == 0 ? Eigen::VectorXd(Eigen::Vector2d(0.1, 0.001)) : Eigen::VectorXd();
  }
  t.accel[2].reason = "no order could be fitted";
  return t;
}

TEST(CalibrationRecord, AThermalModelMakesItVersion2AndReadsBack) {
  CalibrationRecord r = a_record();
  r.thermal = a_thermal_model();
  const json j = calibration_record_json(r);
  EXPECT_EQ(j["version"], 2);
  EXPECT_EQ(j["thermal"]["reference_c"], 40.0);
  EXPECT_EQ(j["thermal"]["gyro"][1]["order"], 3);
  EXPECT_EQ(j["thermal"]["accel"][1]["order"], 0);  // determined: no change with temperature
  EXPECT_TRUE(j["thermal"]["accel"][2]["order"].is_null());
  EXPECT_TRUE(j["thermal"]["gyro"][0]["sigma"][2].is_null());  // not determined, never 0
  EXPECT_NE(j["thermal"]["form"].get<std::string>().find("T_ref"), std::string::npos);
  auto back = calibration_record_from_json(json::from_cbor(json::to_cbor(j)));
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_TRUE(back->thermal);
  EXPECT_TRUE(same_calibration(*back, r));
  EXPECT_EQ(calibration_record_json(*back), j);
  EXPECT_EQ(back->thermal->accel[2].reason, "no order could be fitted");
  EXPECT_DOUBLE_EQ(back->thermal->gyro_change(50.0)[1], 1.02 * 10 - 3e-4 * 100 + 1e-6 * 1000);
  // Clamped to the valid range.
  EXPECT_DOUBLE_EQ(back->thermal->accel_change(80.0)[0], 1.5 * 18.25 - 0.01 * 18.25 * 18.25);
  EXPECT_EQ(back->thermal->accel_change(80.0)[2], 0.0);

  CalibrationRecord other = r;
  other.thermal->gyro[2].coeffs[0] += 1e-9;
  EXPECT_FALSE(same_calibration(other, r));
  other.thermal.reset();
  EXPECT_FALSE(same_calibration(other, r));

  auto refused = [&](const std::function<void(json&)>& spoil, const std::string& says) {
    json bad = j;
    spoil(bad);
    auto x = calibration_record_from_json(bad);
    ASSERT_FALSE(x.ok()) << "accepted a thermal model whose " << says << " is wrong";
    EXPECT_NE(x.error().message.find(says), std::string::npos) << x.error().message;
  };
  refused([](json& x) { x["thermal"]["gyro"][0]["order"] = 4; }, "thermal.gyro[0].order");
  refused([](json& x) { x["thermal"]["gyro"][1]["coeffs"] = json::array({1, 2}); }, "thermal.gyro[1].coeffs");
  refused([](json& x) { x["thermal"]["accel"].erase(2); }, "thermal.accel");
  refused([](json& x) { x["thermal"]["valid_range_c"] = json::array({50, 20}); }, "valid_range_c");
  // A model fitted to temperatures no die reaches (one sample at 1e308 gave a reference of 7e61).
  refused([](json& x) { x["thermal"]["reference_c"] = 7e61; }, "must be die temperatures");
  refused(
      [](json& x) {
        x["thermal"]["valid_range_c"] = json::array({20, 1e308});
      },
      "must be die temperatures");
}

// A figure the record holds as an infinity or NaN (CBOR can carry them; a record writes null for
// "not determined") is refused as an altered record (before: an infinite gravity was read, then
// served as null, "~", by store read).
TEST(CalibrationRecord, AFigureThatIsNotFiniteIsRefused) {
  const json j = calibration_record_json(a_record());
  const double inf = std::numeric_limits<double>::infinity();
  for (const auto& [spoil, says] : std::vector<std::pair<std::function<void(json&)>, std::string>>{
           {[&](json& x) { x["gravity_mps2"] = inf; }, "gravity_mps2 must be a finite number or null"},
           {[&](json& x) { x["gravity_mps2"] = -9.8; }, "gravity_mps2 must be a positive number"},
           {[&](json& x) { x["cameras"][0]["timeshift_sigma_s"] = -inf; },
            "timeshift_sigma_s must be a finite number or null"},
           {[&](json& x) { x["cameras"][0]["timeshift_cam_imu_s"] = std::nan(""); },
            "timeshift_cam_imu_s must be a finite number or null"}}) {
    json bad = json::from_cbor(json::to_cbor(j));
    spoil(bad);
    auto x = calibration_record_from_json(json::from_cbor(json::to_cbor(bad)));
    ASSERT_FALSE(x.ok()) << "accepted: " << says;
    EXPECT_EQ(x.error().code, Errc::kCorrupt);
    EXPECT_NE(x.error().message.find(says), std::string::npos) << x.error().message;
  }
  auto fine = calibration_record_from_json(j);
  ASSERT_TRUE(fine.ok()) << fine.error().message;
}

TEST(CalibrationRecord, SameCalibrationLooksAtTheImuAndTheCamerasOnly) {
  const CalibrationRecord a = a_record();
  CalibrationRecord b = a;
  b.created_utc = "later";
  b.rig = "other";
  b.notes.clear();
  EXPECT_TRUE(same_calibration(a, b));
  b.imu.model.b_g[1] += 1e-9;
  EXPECT_FALSE(same_calibration(a, b));
  b = a;
  b.cameras[0].timeshift_sigma_s = 1e-5;  // determined now
  EXPECT_FALSE(same_calibration(a, b));
  b = a;
  b.imu.sigma.krebs = KrebsImuSigma{};
  EXPECT_FALSE(same_calibration(a, b));
  b = a;
  b.cameras[0].line_delay_s = 30e-6;  // a rolling shutter now
  EXPECT_FALSE(same_calibration(a, b));
}

// A rolling shutter's line delay is kept with its sigma; a global camera has neither key.
TEST(CalibrationRecord, ARollingShuttersLineDelayReadsBack) {
  CalibrationRecord r = a_record();
  EXPECT_FALSE(calibration_record_json(r)["cameras"][0].contains("line_delay_s"));
  r.cameras[0].line_delay_s = 29.7e-6;
  r.cameras[0].line_delay_sigma_s = 0.2e-6;
  const json j = calibration_record_json(r);
  EXPECT_DOUBLE_EQ(j["cameras"][0]["line_delay_s"].get<double>(), 29.7e-6);
  auto back = calibration_record_from_json(json::from_cbor(json::to_cbor(j)));
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_TRUE(back->cameras[0].line_delay_s);
  EXPECT_DOUBLE_EQ(*back->cameras[0].line_delay_s, 29.7e-6);
  EXPECT_DOUBLE_EQ(back->cameras[0].line_delay_sigma_s, 0.2e-6);
  EXPECT_TRUE(same_calibration(*back, r));
  json bad = j;
  bad["cameras"][0]["line_delay_s"] = nullptr;
  auto refused = calibration_record_from_json(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("line_delay_s"), std::string::npos);
}

// The stored payload is walked before nlohmann's recursive CBOR parser sees it: a nesting that
// would overflow the stack, a length beyond the bytes, or a payload no record could be is refused.
TEST(CalibrationRecord, APayloadIsBoundedInDepthAndSizeBeforeItIsParsed) {
  const json j = calibration_record_json(a_record());
  const std::vector<std::uint8_t> good = json::to_cbor(j);
  auto back = calibration_payload_json(good);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(*back, j);

  const auto nested = [](std::size_t depth, std::uint8_t open, std::vector<std::uint8_t> tail) {
    std::vector<std::uint8_t> b(depth, open);
    b.insert(b.end(), tail.begin(), tail.end());
    return b;
  };
  // 32 levels are read, 33 are not: definite arrays (0x81), maps ({0: ...}: 0xA1 0x00), tags
  // (0xC1) and indefinite arrays (0x9F ... 0xFF).
  EXPECT_TRUE(calibration_payload_json(nested(32, 0x81, {0x00})).ok());
  for (const auto& deep : {nested(33, 0x81, {0x00}), nested(1'000'000, 0x81, {0x00}),
                           nested(1'000'000, 0xC1, {0x00}), nested(100'000, 0x9F, {})}) {
    auto r = calibration_payload_json(deep.size() > kMaxCalibrationPayloadBytes
                                          ? std::span(deep).first(kMaxCalibrationPayloadBytes)
                                          : std::span(deep));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kCorrupt);
    EXPECT_NE(r.error().message.find("deeper than 32 levels"), std::string::npos) << r.error().message;
  }
  std::vector<std::uint8_t> maps;
  for (int i = 0; i < 40; ++i) maps.insert(maps.end(), {0xA1, 0x00});
  maps.push_back(0x00);
  EXPECT_NE(calibration_payload_json(maps).error().message.find("deeper than 32"), std::string::npos);

  const std::pair<std::vector<std::uint8_t>, const char*> bad[] = {
      {{0x9B, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF}, "more items than the bytes"},  // 2^64-1 items
      {{0xBB, 0x7F, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF}, "map longer than the bytes"},
      {{0x7A, 0xFF, 0xFF, 0xFF, 0xFF, 0x61}, "string longer than the bytes"},
      {{0x82, 0x00}, "more items than the bytes"},
      {{0x19, 0x01}, "truncated"},  // a 16-bit number with one byte
      {{0x00, 0x00}, "after its CBOR item"},
      {{0xFF}, "break byte"},
      {{0x1C}, "reserved"},
      {{}, "truncated"}};
  for (const auto& [bytes, why] : bad) {
    auto r = calibration_payload_json(bytes);
    ASSERT_FALSE(r.ok()) << why;
    EXPECT_NE(r.error().message.find(why), std::string::npos) << r.error().message;
  }
  std::vector<std::uint8_t> long_string = {0x5A, 0x00, 0x04, 0x00, 0x00};  // 256 KiB of bytes
  long_string.resize(long_string.size() + 256 * 1024);
  auto r = calibration_payload_json(long_string);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("more than a record"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace imucal
