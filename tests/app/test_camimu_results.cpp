// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU calibration's solver-free pieces, from a hand-built result: Kalibr's
// camchain-imucam.yaml and imu.yaml (the scale-misalignment matrices give back the canonical
// model), the canonical record read by the static result's readers, result.json read back, the
// conversions of the inputs (nominal SI, the g-sensitivity B_g, a prior static calibration) and
// the matching of camchain cameras to log streams.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "app/calibration_check.hpp"
#include "app/camimu_inputs.hpp"
#include "app/results/camimu_results.hpp"
#include "app/results/static_results.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

Eigen::Matrix3d rotation(const Eigen::Vector3d& v) {
  return Eigen::AngleAxisd(v.norm(), v.normalized()).matrix();
}

/// An IMU far enough from the identity that a transposed or swapped matrix shows.
KrebsImuModel krebs_truth() {
  KrebsImuModel k;
  k.S_a = {0.9897, 1.0161, 1.0105};
  k.M_a = {0.0101, 0.0271, 0.0308};
  k.b_a = {0.3876, 0.0372, -0.7285};
  k.S_g = {0.9864, 1.0115, 1.0293};
  k.M_g = {-0.0128, 0.0319, -0.0237};
  k.C_bg = rotation({0.0002, 0.0069, 0.0133});
  k.B_g << -1.4e-4, 7.9e-5, 1.3e-4, 6.5e-5, 5.3e-4, 3.2e-4, 2.4e-4, -2.3e-4, -1.4e-4;
  k.b_g = {0.0366, 0.0578, 0.0663};
  return k;
}

/// A raw MPU-6000 stream (+-4 g, +-500 deg/s) whose nominal conversion is not the identity.
ImuStreamInfo raw_stream() {
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kRaw;
  info.rate_hz = 200.0;
  info.accel.scale = Eigen::Vector3d::Constant(4.0 * 9.80665 / 32768.0);
  info.accel.offset = {3.0, -2.0, 1.0};
  info.gyro.scale = Eigen::Vector3d::Constant(500.0 / 32768.0 * M_PI / 180.0);
  return info;
}

CameraModel camera(double fu) {
  CameraModel c;
  c.intrinsics = {fu, fu - 0.5, 189.1, 117.3};
  c.distortion_coeffs = {-0.2865, 0.0731, 0.00021, -0.00034};
  c.width = 376;
  c.height = 240;
  return c;
}

CamImuReport report() {
  CamImuReport r;
  r.log_path = "/data/rig.imulog";
  r.imu_stream = raw_stream();
  r.imu_samples = 11820;
  r.imu_rostopic = "/imu0";
  r.noise_source = "imu.yaml";
  r.options.noise = {0.004, 2e-4, 9e-5, 3e-5};
  auto& res = r.result;
  res.model = CamImuModelKind::kExtended;
  res.imu = krebs_truth();
  res.imu_sigma.S_a = {1e-4, 2e-4, 3e-4};
  res.imu_sigma.B_g.setConstant(2e-5);
  res.imu_sigma.C_bg = {1e-4, 1e-4, 2e-4};
  res.canonical = *canonical_from_krebs(res.imu);
  res.fixed = {"timeshift"};
  res.gravity_w = {0.01, -0.02, -9.80665};
  res.gravity_sigma_rad = {1e-4, 2e-4};
  for (int i = 0; i < 2; ++i) {
    CamImuCameraResult c;
    c.name = "cam" + std::to_string(i);
    c.stream = i == 0 ? "cam0" : "right";
    c.camera = camera(200.3 + i);
    c.T_cam_imu.linear() = rotation({3.1, 0.02 * (i + 1), -0.03});
    c.T_cam_imu.translation() = Eigen::Vector3d(0.0312, -0.0184, -0.0136 + 0.1 * i);
    c.rotation_sigma_rad = {1e-3, 2e-3, 3e-3};
    c.translation_sigma_m = {1e-3, 2e-3, 4e-3};
    c.timeshift_cam_imu_s = i == 0 ? 0.0042 : -0.0031;  // both signs
    c.timeshift_sigma_s = 1.4e-4;
    c.frames = 1169;
    c.corners = 49000;
    c.reprojection_rms_px = 0.12;
    c.corner_sigma_px = 0.3;
    c.residuals_px = {{0.01234F, -0.5F}, {1.25F, 0.0F}};
    c.outlier_px = 0.9;
    res.cameras.push_back(c);
    CamImuCameraReport in;
    in.name = c.name;
    in.source = "cam.yaml cam" + std::to_string(i);
    in.rostopic = "/" + c.stream + "/image_raw";
    in.stream.name = c.stream;
    in.frames = 1200;
    in.frames_with_target = 1169;
    r.cameras.push_back(in);
  }
  res.biases = {{1000, res.imu.b_a, res.imu.b_g}, {2000001000, res.imu.b_a * 1.01, res.imu.b_g * 0.99}};
  ImuSignalFit fit;
  fit.model = "extended";
  fit.t_ns = {1000, 5001000};
  fit.accel_measured = {{0.1F, 0.2F, 9.8F}, {0.0F, 0.0F, 9.81F}};
  fit.accel_predicted = {{0.1F, 0.2F, 9.79F}, {0.0F, 0.0F, 9.8123456F}};
  fit.gyro_measured = {{0.0123457F, 0.0F, 0.0F}, {0.0F, 0.5F, 0.0F}};
  fit.gyro_predicted = {{0.0123F, 0.0F, 0.0F}, {0.0F, 0.5F, 0.0F}};
  fit.gyro_residual_rms = {1e-3, 2e-3, 3e-3};
  res.signal_fits.push_back(fit);
  res.quality.xcorr = {{{-0.01, 0.5}, {0.0, 0.9}, {0.01, 0.6}}, {{0.0, 1.0}}};
  res.quality.xcorr_peak_s = {0.0042, -0.0031};
  res.quality.iterations = 17;
  res.quality.accel_residual_rms = {0.03, 0.04, 0.05};
  res.warnings = {"z rotation barely excited"};
  r.warnings = res.warnings;
  return r;
}

/// Writes a file into the test's scratch folder (made once per test: scratch_dir empties it).
std::string write(const std::string& name, const std::string& text) {
  static std::string test_name, dir;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  if (info->name() != test_name) {
    test_name = info->name();
    dir = test::scratch_dir();
  }
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

Eigen::Matrix3d matrix(const YAML::Node& rows) {
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m(r, c) = rows[r][c].as<double>();
  return m;
}

Eigen::Vector3d vector(const YAML::Node& v) {
  return {v[0].as<double>(), v[1].as<double>(), v[2].as<double>()};
}

TEST(CamImuResults, CamchainHasKalibrKeysAndRoundTripsExtrinsicsAndTimeshift) {
  const CamImuReport r = report();
  const YAML::Node root = YAML::Load(camimu_camchain_yaml(r));
  for (int i = 0; i < 2; ++i) {
    const YAML::Node cam = root["cam" + std::to_string(i)];
    ASSERT_TRUE(cam) << i;
    for (const char* key : {"camera_model", "intrinsics", "distortion_model", "distortion_coeffs",
                            "resolution", "rostopic", "T_cam_imu", "timeshift_cam_imu"})
      EXPECT_TRUE(cam[key]) << key;
    const auto& c = r.result.cameras[i];
    ASSERT_EQ(cam["T_cam_imu"].size(), 4u);
    for (int row = 0; row < 4; ++row) {
      ASSERT_EQ(cam["T_cam_imu"][row].size(), 4u);
      for (int col = 0; col < 4; ++col)
        EXPECT_EQ(cam["T_cam_imu"][row][col].as<double>(), c.T_cam_imu.matrix()(row, col)) << row << col;
    }
    // Kalibr's sign, t_imu = t_cam + shift, kept as given.
    EXPECT_EQ(cam["timeshift_cam_imu"].as<double>(), c.timeshift_cam_imu_s);
    EXPECT_EQ(cam["rostopic"].as<std::string>(), "/" + c.stream + "/image_raw");
    EXPECT_EQ(cam["imucal"]["timeshift_sigma_s"].as<double>(), 1.4e-4);
  }
  EXPECT_FALSE(root["cam0"]["T_cn_cnm1"]);
  Eigen::Matrix4d T10;
  for (int row = 0; row < 4; ++row)
    for (int col = 0; col < 4; ++col) T10(row, col) = root["cam1"]["T_cn_cnm1"][row][col].as<double>();
  const Eigen::Matrix4d expected =
      (r.result.cameras[1].T_cam_imu * r.result.cameras[0].T_cam_imu.inverse()).matrix();
  EXPECT_LT((T10 - expected).cwiseAbs().maxCoeff(), 1e-15);

  // The camchain reads back as the calibration's cameras, on their streams.
  auto cams = read_camchain(write("camchain-imucam.yaml", camimu_camchain_yaml(r)));
  ASSERT_TRUE(cams.ok()) << cams.error().message;
  ASSERT_EQ(cams->size(), 2u);
  EXPECT_EQ((*cams)[1].camera.intrinsics, r.result.cameras[1].camera.intrinsics);
  EXPECT_EQ((*cams)[1].camera_stream, "right");
}

TEST(CamImuResults, ImuYamlScaleMisalignmentGivesBackTheCanonicalModel) {
  const CamImuReport r = report();
  const YAML::Node imu = YAML::Load(camimu_imu_yaml(r))["imu0"];
  ASSERT_TRUE(imu);
  EXPECT_EQ(imu["model"].as<std::string>(), "scale-misalignment");
  EXPECT_EQ(imu["rostopic"].as<std::string>(), "/imu0");
  EXPECT_EQ(imu["update_rate"].as<double>(), 200.0);
  EXPECT_EQ(imu["accelerometer_noise_density"].as<double>(), 0.004);
  EXPECT_EQ(imu["gyroscope_random_walk"].as<double>(), 3e-5);
  // Kalibr's model: a_raw = M_accel a + b_a, w_raw = M_gyro C_gyro_i w + A C_gyro_i a + b_g.
  const Eigen::Matrix3d Ma = matrix(imu["accelerometers"]["M"]);
  const Eigen::Matrix3d Mg = matrix(imu["gyroscopes"]["M"]);
  const Eigen::Matrix3d A = matrix(imu["gyroscopes"]["A"]);
  const Eigen::Matrix3d C = matrix(imu["gyroscopes"]["C_gyro_i"]);
  EXPECT_EQ(Ma(0, 1), 0.0);  // lower triangular, as Kalibr estimates it
  EXPECT_EQ(Mg(1, 2), 0.0);
  CanonicalImuModel c;
  c.A_a = Ma.inverse();
  c.b_a = vector(imu["imucal"]["b_a"]);
  c.A_g = C.transpose() * Mg.inverse();
  c.b_g = vector(imu["imucal"]["b_g"]);
  c.G = c.A_g * A * C;
  const CanonicalImuModel& truth = r.result.canonical;
  EXPECT_LT((c.A_a - truth.A_a).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((c.A_g - truth.A_g).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((c.G - truth.G).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((c.b_a - truth.b_a).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((c.b_g - truth.b_g).cwiseAbs().maxCoeff(), 1e-12);

  // It is also a noise file for the next run (`--imu`).
  auto noise = read_kalibr_imu_noise(write("imu.yaml", camimu_imu_yaml(r)));
  ASSERT_TRUE(noise.ok()) << noise.error().message;
  EXPECT_EQ(noise->gyro_noise_density, 9e-5);

  // The basic model is Kalibr's "calibrated" IMU, without the matrices.
  CamImuReport basic = r;
  basic.result.model = CamImuModelKind::kBasic;
  const YAML::Node b = YAML::Load(camimu_imu_yaml(basic))["imu0"];
  EXPECT_EQ(b["model"].as<std::string>(), "calibrated");
  EXPECT_FALSE(b["gyroscopes"]);
}

TEST(CamImuResults, CalibrationYamlIsReadByTheStaticResultReaders) {
  const CamImuReport r = report();
  const std::string path = write("calibration.yaml", camimu_calibration_yaml(r));
  auto c = read_imucal_calibration(path);
  ASSERT_TRUE(c.ok()) << c.error().message;
  ASSERT_TRUE(c->input_units.has_value());
  EXPECT_EQ(*c->input_units, ImuUnits::kRaw);
  // For the raw values: on nominal SI it is the result's canonical model.
  const CanonicalImuModel si = canonical_on_nominal_si(c->model, r.imu_stream);
  EXPECT_LT((si.A_a - r.result.canonical.A_a).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((si.A_g - r.result.canonical.A_g).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((si.b_a - r.result.canonical.b_a).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((si.b_g - r.result.canonical.b_g).cwiseAbs().maxCoeff(), 1e-12);
  // A raw sample corrects to the same SI value either way.
  const Eigen::Vector3d raw(1200.0, -8000.0, 3000.0);
  EXPECT_LT(
      (c->model.correct_accel(raw) - r.result.canonical.correct_accel(r.imu_stream.accel.to_si(raw))).norm(),
      1e-12);
  auto G = read_gsens_matrix(path);
  ASSERT_TRUE(G.ok()) << G.error().message;
  EXPECT_LT((*G - r.result.canonical.G).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(CamImuResults, ResultJsonReadsBack) {
  CamImuReport r = report();
  r.result.quality.covariance_cluster_s = 1.0;
  r.result.quality.covariance_clusters = 35;
  SplitCheck& sc = r.result.self_check;
  sc.parts = 2;
  sc.spans_s = {{0.0, 17.0}, {17.0, 34.0}};
  sc.part_errors = {"", ""};
  sc.parameters = {{"cam0 translation x", "mm", {0.5, 2.5}, {0.5, 0.6}}};
  judge_split_check(&sc);
  const std::string path = write("result.json", camimu_result_json(r));
  const auto j = nlohmann::json::parse(test::read_file(path));
  EXPECT_EQ(j["fixed"][0], "timeshift");
  EXPECT_EQ(j["inputs"]["noise"]["accelerometer_random_walk"].get<double>(), 2e-4);
  EXPECT_EQ(j["biases"].size(), 2u);
  EXPECT_DOUBLE_EQ(j["biases"][1]["t_s"].get<double>(), 2.0);
  auto back = read_camimu_result(path);
  ASSERT_TRUE(back.ok()) << back.error().message;
  const auto& res = r.result;
  EXPECT_EQ(back->model, res.model);
  ASSERT_EQ(back->cameras.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    const auto& a = back->cameras[i];
    const auto& b = res.cameras[i];
    EXPECT_EQ(a.stream, b.stream);
    EXPECT_EQ(a.T_cam_imu.matrix(), b.T_cam_imu.matrix());
    EXPECT_EQ(a.timeshift_cam_imu_s, b.timeshift_cam_imu_s);
    EXPECT_EQ(a.rotation_sigma_rad, b.rotation_sigma_rad);
    EXPECT_EQ(a.camera.intrinsics, b.camera.intrinsics);
    EXPECT_EQ(a.frames, b.frames);
    // The residuals to 1e-4 px.
    ASSERT_EQ(a.residuals_px.size(), 2u);
    EXPECT_NEAR(a.residuals_px[0].x(), 0.0123, 1e-6);
    EXPECT_EQ(a.residuals_px[1], b.residuals_px[1]);
    EXPECT_EQ(a.outlier_px, 0.9);
  }
  EXPECT_EQ(back->imu.B_g, res.imu.B_g);
  EXPECT_EQ(back->imu.C_bg, res.imu.C_bg);
  EXPECT_EQ(back->imu_sigma.S_a, res.imu_sigma.S_a);
  EXPECT_EQ(back->canonical.A_g, res.canonical.A_g);
  EXPECT_EQ(back->gravity_w, res.gravity_w);
  EXPECT_EQ(back->biases.size(), 2u);
  EXPECT_EQ(back->biases[1].b_g, res.biases[1].b_g);
  // The measured and predicted signals: times to 1 us, values to 1e-6 m/s^2 and 1e-7 rad/s.
  ASSERT_EQ(back->signal_fits.size(), 1u);
  const ImuSignalFit& f = back->signal_fits[0];
  EXPECT_EQ(f.model, "extended");
  ASSERT_EQ(f.t_ns.size(), 2u);
  EXPECT_EQ(f.t_ns[1], res.signal_fits[0].t_ns[1]);
  EXPECT_NEAR(f.accel_predicted[1].z(), 9.8123456, 1e-5);
  EXPECT_NEAR(f.gyro_measured[0].x(), 0.0123457, 1e-8);
  EXPECT_EQ(f.gyro_residual_rms, res.signal_fits[0].gyro_residual_rms);
  EXPECT_EQ(back->quality.xcorr.size(), 2u);
  EXPECT_EQ(back->quality.xcorr[0][1].second, 0.9);
  EXPECT_EQ(back->quality.iterations, 17);
  EXPECT_EQ(back->warnings, res.warnings);
  EXPECT_EQ(back->quality.covariance_clusters, 35);
  EXPECT_EQ(back->quality.covariance_cluster_s, 1.0);
  EXPECT_EQ(back->self_check.verdict, SplitCheck::Verdict::kAgree);
  EXPECT_EQ(back->self_check.summary, sc.summary);
  ASSERT_EQ(back->self_check.parameters.size(), 1u);
  EXPECT_EQ(back->self_check.parameters[0].values, sc.parameters[0].values);

  auto bad = read_camimu_result(write("bad.json", "{\"model\": \"extended\"}"));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, Errc::kCorrupt);
}

// The Krebs model is w_raw = S_g M_g C_bg^T w + B_g C_bg^T a + b_g: a canonical G becomes the B_g
// that canonical_from_krebs turns back into G, for any S_g, M_g and C_bg.
TEST(CamImuInputs, GsensToKrebsRoundTripsThroughCanonical) {
  KrebsImuModel k = krebs_truth();
  Eigen::Matrix3d G;
  G << 2e-4, -1e-4, 3e-5, 4e-4, 1e-4, -2e-4, -5e-5, 6e-5, 3e-4;
  k.B_g = krebs_gsens_from_canonical(G, k);
  auto c = canonical_from_krebs(k);
  ASSERT_TRUE(c.ok());
  EXPECT_LT((c->G - G).cwiseAbs().maxCoeff(), 1e-17);
  // And through krebs_from_canonical: the same B_g.
  auto back = krebs_from_canonical(*c);
  ASSERT_TRUE(back.ok());
  EXPECT_LT((back->model.B_g - k.B_g).cwiseAbs().maxCoeff(), 1e-15);
  // With the identity gyro it is G itself.
  EXPECT_EQ(krebs_gsens_from_canonical(G, KrebsImuModel{}), G);
}

// The rotation a held static calibration's axes may be off by, from its factors' sigmas, with
// known answers on an aligned IMU: an accelerometer misalignment T(0,1) = e turns the body frame
// (x along the accelerometer's x axis) by e about z; a gyro misalignment T(0,1) = e is half a
// rotation (e/2 about z) and half a shear; scales turn nothing.
TEST(CamImuInputs, TheHeldAxesCovarianceComesFromTheStaticSigmas) {
  NamedCalibration::Spread s;
  EXPECT_TRUE(held_axes_covariance(s).isZero(0.0));  // no sigma: nothing added
  s.accel_sigma.T(0, 1) = 3e-4;
  s.gyro_sigma.T(0, 1) = 2e-4;
  s.accel_sigma.scale = s.gyro_sigma.scale = Eigen::Vector3d::Constant(1e-3);
  const Eigen::Matrix3d cov = held_axes_covariance(s);
  EXPECT_NEAR(cov(2, 2), 3e-4 * 3e-4 + 1e-4 * 1e-4, 1e-10);
  EXPECT_NEAR(cov(0, 0), 0.0, 1e-12);
  EXPECT_NEAR(cov(1, 1), 0.0, 1e-12);
  EXPECT_NEAR(cov(0, 2), 0.0, 1e-12);
  // A sigma the static calibration could not determine leaves the added rotation undetermined.
  s.gyro_sigma.T(1, 2) = std::nan("");
  EXPECT_TRUE(held_axes_covariance(s).array().isNaN().all());
}

// The static result YAML carries its factors' sigmas, read beside the canonical model.
TEST(CamImuInputs, TheStaticResultsSigmasAreReadForThePropagation) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/static.yaml";
  std::ofstream(path)
      << "canonical:\n  A_a: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  b_a: [0, 0, 0]\n"
         "  A_g: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  b_g: [0, 0, 0]\n"
         "  G: [[0, 0, 0], [0, 0, 0], [0, 0, 0]]\n"
         "accel:\n  misalignment: [[1, 0.01, 0], [0, 1, 0], [0, 0, 1]]\n  scale: [1, 1, 1]\n"
         "  sigma:\n    misalignment: [[0, 2e-4, 0], [0, 0, 0], [0, 0, 0]]\n    scale: [1e-3, 1e-3, 1e-3]\n"
         "gyro:\n  misalignment: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  scale: [1, 1, 1]\n"
         "  sigma:\n    misalignment: [[0, .nan, 0], [0, 0, 0], [0, 0, 0]]\n    scale: [0, 0, 0]\n";
  auto c = read_imucal_calibration(path);
  ASSERT_TRUE(c.ok()) << c.error().message;
  ASSERT_TRUE(c->spread.has_value());
  EXPECT_DOUBLE_EQ(c->spread->accel.T(0, 1), 0.01);
  EXPECT_DOUBLE_EQ(c->spread->accel_sigma.T(0, 1), 2e-4);
  EXPECT_TRUE(std::isnan(c->spread->gyro_sigma.T(0, 1)));
  // A file without them (imu_tk's, or an older one) still reads, without a spread.
  std::ofstream(path) << "canonical:\n  A_a: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  b_a: [0, 0, 0]\n"
                         "  A_g: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  b_g: [0, 0, 0]\n"
                         "  G: [[0, 0, 0], [0, 0, 0], [0, 0, 0]]\n";
  auto bare = read_imucal_calibration(path);
  ASSERT_TRUE(bare.ok()) << bare.error().message;
  EXPECT_FALSE(bare->spread.has_value());
}

TEST(CamImuInputs, StaticResultOnRawCountsBecomesTheKrebsStartAndFixesTheIntrinsics) {
  const ImuStreamInfo info = raw_stream();
  const KrebsImuModel truth = krebs_truth();
  const CanonicalImuModel si = *canonical_from_krebs(truth);
  // The static result of a raw stream is for counts; rotate it into another frame as the static
  // calibration's own frame differs from the Krebs body frame.
  NamedCalibration file;
  file.path = "static.yaml";
  file.input_units = ImuUnits::kRaw;
  file.model = canonical_on_input_units(si.expressed_in(rotation({0.01, -0.02, 0.03})), info);
  auto prior = imu_prior(file, std::nullopt, info);
  ASSERT_TRUE(prior.ok()) << prior.error().message;
  ASSERT_TRUE(prior->init.has_value());
  EXPECT_LT((prior->init->S_a - truth.S_a).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((prior->init->M_g - truth.M_g).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((prior->init->C_bg - truth.C_bg).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((prior->init->B_g - truth.B_g).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((prior->init->b_a - truth.b_a).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(fixed_block_names(prior->fixed),
            (std::vector<std::string>{"S_a", "M_a", "S_g", "M_g", "C_bg", "B_g"}));

  // --gsens with the same file: G is rotated into the body frame, the same B_g.
  GsensInput gsens{"static.yaml", file.model.G, file};
  prior = imu_prior(std::nullopt, gsens, info);
  ASSERT_TRUE(prior.ok()) << prior.error().message;
  EXPECT_EQ(fixed_block_names(prior->fixed), (std::vector<std::string>{"B_g"}));
  // No intrinsics: the start is the identity gyro, so B_g is the G of the Krebs body frame.
  EXPECT_LT((prior->init->B_g - si.G).cwiseAbs().maxCoeff(), 1e-15);

  // A calibration of SI values does not fit a raw stream.
  file.input_units = ImuUnits::kSi;
  prior = imu_prior(file, std::nullopt, info);
  ASSERT_FALSE(prior.ok());
  EXPECT_EQ(prior.error().code, Errc::kInvalidArgument);
}

TEST(CamImuInputs, SamplesOnNominalSiWithoutSaturated) {
  const ImuStreamInfo info = raw_stream();
  std::vector<ImuSample> raw(3);
  for (int i = 0; i < 3; ++i) {
    raw[i].t_ns = 5000000 * i;
    raw[i].accel = {100.0 * i, 2000.0, -8192.0};
    raw[i].gyro = {-65.5, 0.0, 131.0};
  }
  raw[1].flags = kImuFlagGyroSaturated;
  std::size_t saturated = 0;
  const auto s = camimu_samples(raw, info, &saturated);
  EXPECT_EQ(saturated, 1u);
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s[1].t_ns, 10000000);
  EXPECT_LT((s[1].accel - info.accel.to_si(raw[2].accel)).norm(), 1e-15);
  EXPECT_NEAR(s[0].gyro[2], 131.0 * 500.0 / 32768.0 * M_PI / 180.0, 1e-15);
}

TEST(CamImuInputs, CamerasFindTheirStreams) {
  std::map<int, CameraStreamInfo> streams;
  streams[1].name = "left";
  streams[2].name = "right";
  std::vector<CamchainCamera> cams(2);
  cams[0].name = "cam0";
  cams[0].camera_stream = "right";  // imucal's key first
  cams[0].rostopic = "/left/image_raw";
  cams[1].name = "cam1";
  cams[1].rostopic = "/left/image_raw";  // Kalibr's topic
  auto ids = match_camera_streams(cams, streams);
  ASSERT_TRUE(ids.ok()) << ids.error().message;
  EXPECT_EQ(*ids, (std::vector<int>{2, 1}));

  cams[1].rostopic = "/right/image";  // a stream taken twice
  ids = match_camera_streams(cams, streams);
  ASSERT_FALSE(ids.ok());
  EXPECT_EQ(ids.error().code, Errc::kInvalidArgument);

  cams[1].rostopic = "/cam7/image_raw";
  ids = match_camera_streams(cams, streams);
  ASSERT_FALSE(ids.ok());
  EXPECT_EQ(ids.error().code, Errc::kNotFound);
  EXPECT_NE(ids.error().message.find("left, right"), std::string::npos) << ids.error().message;

  // One camera, one stream: by order whatever the names.
  streams.erase(2);
  cams.resize(1);
  cams[0].camera_stream.clear();
  cams[0].rostopic = "/cam0/image_raw";
  ids = match_camera_streams(cams, streams);
  ASSERT_TRUE(ids.ok()) << ids.error().message;
  EXPECT_EQ(*ids, std::vector<int>{1});
}

TEST(CamImuInputs, FixedBlocksAndNoiseFile) {
  calib::CamImuFixed fixed;
  ASSERT_TRUE(set_fixed_block("B_g", &fixed).ok());
  ASSERT_TRUE(set_fixed_block("timeshift", &fixed).ok());
  EXPECT_EQ(fixed_block_names(fixed), (std::vector<std::string>{"B_g", "timeshift"}));
  auto bad = set_fixed_block("Bg", &fixed);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("S_a, M_a"), std::string::npos);

  // imucal allan's flat imu.yaml.
  auto noise =
      read_kalibr_imu_noise(write("allan.yaml",
                                  "accelerometer_noise_density: 0.002\naccelerometer_random_walk: 3e-4\n"
                                  "gyroscope_noise_density: 1.6e-4\ngyroscope_random_walk: 2e-6\n"
                                  "rostopic: /imu0\nupdate_rate: 200\n"));
  ASSERT_TRUE(noise.ok()) << noise.error().message;
  EXPECT_EQ(noise->accel_noise_density, 0.002);
  EXPECT_EQ(noise->gyro_random_walk, 2e-6);
  auto missing = read_kalibr_imu_noise(write("short.yaml", "accelerometer_noise_density: 0.002\n"));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::kCorrupt);
  EXPECT_NE(missing.error().message.find("accelerometer_random_walk"), std::string::npos);
}

TEST(CamImuInputs, TheImuFilesTopicChoosesTheStreamAndItsRateIsGivenBack) {
  auto topic =
      read_kalibr_imu_topic(write("kalibr-imu.yaml",
                                  "imu0:\n  accelerometer_noise_density: 0.002\n  rostopic: /vi/imu\n"
                                  "  update_rate: 200.0\n"));
  ASSERT_TRUE(topic.ok()) << topic.error().message;
  EXPECT_EQ(topic->rostopic, "/vi/imu");
  EXPECT_EQ(topic->update_rate, 200.0);
  auto bad = read_kalibr_imu_topic(write("bad-rate.yaml", "rostopic: /imu0\nupdate_rate: -5\n"));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("update_rate"), std::string::npos);

  std::map<int, ImuStreamInfo> streams;
  streams[1].name = "imu0";
  streams[1].device = "rosbag:/dvs/imu";
  streams[2].name = "imu1";
  streams[2].device = "rosbag:/vi/imu";
  EXPECT_EQ(imu_stream_of_topic(streams, "/vi/imu"), "imu1");  // the bag's topic, whatever the name
  EXPECT_EQ(imu_stream_of_topic(streams, "/imu0"), "imu0");    // else the stream of that name
  EXPECT_EQ(imu_stream_of_topic(streams, "/other"), "");

  // imu.yaml gives the rate back as given, else the stream's to six digits.
  CamImuReport r = report();
  r.imu_stream.rate_hz = 1002.0039920159681;
  EXPECT_EQ(YAML::Load(camimu_imu_yaml(r))["imu0"]["update_rate"].as<double>(), 1002.0);
  r.imu_update_rate = 1000.0;
  EXPECT_EQ(YAML::Load(camimu_imu_yaml(r))["imu0"]["update_rate"].as<double>(), 1000.0);
  // imu.yaml is the flat --imu form: the next run reads back the same noise, topic and rate.
  const std::string flat = write("imu-input.yaml", camimu_imu_input_yaml(r));
  EXPECT_FALSE(YAML::LoadFile(flat)["imu0"]);
  auto noise = read_kalibr_imu_noise(flat);
  ASSERT_TRUE(noise.ok()) << noise.error().message;
  EXPECT_EQ(noise->gyro_noise_density, r.options.noise.gyro_noise_density);
  EXPECT_EQ(noise->accel_random_walk, r.options.noise.accel_random_walk);
  auto again = read_kalibr_imu_topic(flat);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->rostopic, r.imu_rostopic);
  EXPECT_EQ(again->update_rate, 1000.0);
}

TEST(CamImuInputs, CamOverlapsAreReadRenumberedAcrossFilesAndWrittenBack) {
  const std::string pinhole =
      "  camera_model: pinhole\n  intrinsics: [400, 400, 320, 240]\n  distortion_model: radtan\n"
      "  distortion_coeffs: [0, 0, 0, 0]\n  resolution: [640, 480]\n";
  const std::string chain =
      "cam0:\n" + pinhole + "  cam_overlaps: [1]\ncam1:\n" + pinhole + "  cam_overlaps: [0]\n";
  const std::string a = write("chain-a.yaml", chain);
  const std::string b = write("chain-b.yaml", chain);
  auto cams = read_camchain_files({a, b});
  ASSERT_TRUE(cams.ok()) << cams.error().message;
  ASSERT_EQ(cams->size(), 4u);
  EXPECT_EQ(*(*cams)[0].cam_overlaps, std::vector<int>{1});
  EXPECT_EQ(*(*cams)[3].cam_overlaps, std::vector<int>{2});  // the second file's cam1: cam3 overlaps cam2

  CamImuReport r = report();
  r.cameras[0].cam_overlaps = std::vector<int>{1};
  r.cameras[1].cam_overlaps = std::vector<int>{0};
  const YAML::Node root = YAML::Load(camimu_camchain_yaml(r));
  EXPECT_EQ(root["cam1"]["cam_overlaps"].as<std::vector<int>>(), std::vector<int>{0});
  r.cameras[0].cam_overlaps.reset();
  EXPECT_FALSE(YAML::Load(camimu_camchain_yaml(r))["cam0"]["cam_overlaps"]);  // not given, not guessed
}

}  // namespace
}  // namespace imucal::app
