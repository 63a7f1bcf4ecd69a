// SPDX-License-Identifier: BSD-3-Clause
// The service's virtual rig (sim/service_rig.hpp): its clock's pace against the wall clock, the
// wait while the service's worker is busy, the injected IMU fault, its cameras on the rig's clock
// and the final table of the result beside its truth.

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <numbers>
#include <sstream>
#include <thread>
#include <vector>

#include "drivers/mpu6000/output_settings.hpp"
#include "sim/camera_scene.hpp"
#include "sim/camimu.hpp"
#include "sim/service_rig.hpp"
#include "sim/truth.hpp"
#include "sim/virtual_cameras.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::sim {
namespace {

namespace mpu = drivers::mpu6000;

ServiceRigOptions options(double time_scale, bool camera) {
  mpu::OutputRequest req;
  req.rate_hz = 200.0;
  auto settings = mpu::settings_for(req);
  EXPECT_TRUE(settings.ok());
  ServiceRigOptions o;
  o.settings = *settings;
  o.time_scale = time_scale;
  o.seed = 3;
  if (camera) {
    CameraConfig cc;
    cc.name = "cam0";
    cc.width = 320;
    cc.height = 240;
    cc.rate_hz = 20.0;
    cc.pixel_format = "GREY";
    o.cameras.push_back(cc);
    TargetDescription t;
    t.cols = 6;
    t.rows = 5;
    t.col_spacing_m = t.row_spacing_m = 0.04;
    o.target = t;
  }
  return o;
}

std::unique_ptr<ServiceRig> make(const ServiceRigOptions& o) {
  auto rig = make_service_rig(o);
  EXPECT_TRUE(rig.ok()) << (rig.ok() ? "" : rig.error().message);
  return rig.ok() ? std::move(*rig) : nullptr;
}

TEST(ServiceRig, EachTickIsTwentyMillisecondsOfSamplesAndAsFastAsItComputesAtScaleZero) {
  auto rig = make(options(0.0, false));
  ASSERT_TRUE(rig);
  const TimeNs t0 = rig->now_ns();
  std::size_t samples = 0;
  for (int i = 0; i < 50; ++i) {
    const TimeNs before = rig->now_ns();
    auto tick = rig->tick(false, [&](std::span<const ImuSample> s) { samples += s.size(); });
    ASSERT_TRUE(tick.ok());
    EXPECT_TRUE(tick->advanced);
    EXPECT_FALSE(tick->next.has_value());  // at once
    EXPECT_GE(rig->now_ns() - before, 20'000'000);
  }
  // At least a second of rig time, and the samples of most of it (the chip starts up first).
  EXPECT_GE(rig->now_ns() - t0, 1'000'000'000);
  EXPECT_GT(samples, 150u);
}

TEST(ServiceRig, OnAcceleratedTimeItWaitsForTheWorkerAndTheWaitIsNoRigTime) {
  auto rig = make(options(100.0, false));
  ASSERT_TRUE(rig);
  auto none = [](std::span<const ImuSample>) {};
  ASSERT_TRUE(rig->tick(false, none).ok());
  const TimeNs before = rig->now_ns();
  for (int i = 0; i < 3; ++i) {
    auto tick = rig->tick(true, none);
    ASSERT_TRUE(tick.ok());
    EXPECT_FALSE(tick->advanced);
    ASSERT_TRUE(tick->next.has_value());
  }
  EXPECT_EQ(rig->now_ns(), before);  // no rig time while the worker runs
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  // After the wait the next tick is due 20 ms / 100 of wall time on, not in the past by the
  // 200 ms waited (which would make it catch up at full speed).
  const auto now = std::chrono::steady_clock::now();
  auto tick = rig->tick(false, none);
  ASSERT_TRUE(tick.ok());
  ASSERT_TRUE(tick->advanced);
  ASSERT_TRUE(tick->next.has_value());
  EXPECT_GT(*tick->next, now + std::chrono::microseconds(100));
  EXPECT_LT(*tick->next, now + std::chrono::milliseconds(100));
}

TEST(ServiceRig, AtRealTimeTheWorkerDoesNotStopTheClock) {
  auto rig = make(options(1.0, false));
  ASSERT_TRUE(rig);
  const TimeNs before = rig->now_ns();
  auto tick = rig->tick(true, [](std::span<const ImuSample>) {});
  ASSERT_TRUE(tick.ok());
  EXPECT_TRUE(tick->advanced);
  EXPECT_GE(rig->now_ns() - before, 20'000'000);
}

TEST(ServiceRig, AHostThatCannotKeepUpIsToldOnceThatTheRigRunsSlowerThanAsked) {
  ServiceRigOptions o = options(1.0, false);
  o.pace_window_s = 0.2;
  auto rig = make(o);
  ASSERT_TRUE(rig);
  auto none = [](std::span<const ImuSample>) {};
  // Each tick is 20 ms of rig time; 40 ms of wall time between them is half the pace asked,
  // however fast the machine.
  std::vector<std::string> notices;
  for (int i = 0; i < 20; ++i) {
    auto tick = rig->tick(false, none);
    ASSERT_TRUE(tick.ok());
    if (!tick->pace_notice.empty()) notices.push_back(tick->pace_notice);
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
  }
  ASSERT_EQ(notices.size(), 1u) << (notices.empty() ? "" : notices.back());  // said once, not per window
  EXPECT_NE(notices[0].find("slower than the 1x asked"), std::string::npos) << notices[0];
  EXPECT_NE(notices[0].find("--time-scale"), std::string::npos) << notices[0];
}

TEST(ServiceRig, AnUnpluggedImuFailsTheTickAfterItsTime) {
  auto rig = make(options(0.0, false));
  ASSERT_TRUE(rig);
  rig->unplug_imu_after(0.1);
  auto none = [](std::span<const ImuSample>) {};
  int ok_ticks = 0;
  Status failed;
  for (int i = 0; i < 500; ++i) {
    auto tick = rig->tick(false, none);
    if (!tick.ok()) {
      failed = tick.error();
      break;
    }
    ++ok_ticks;
  }
  ASSERT_FALSE(failed.ok()) << "the IMU answered 10 s after it was unplugged";
  EXPECT_GE(ok_ticks, 5);    // 0.1 s of rig time first
  EXPECT_LE(ok_ticks, 100);  // then the driver's resets, and it gives up
  EXPECT_NE(failed.error().message.find("MPU-6000"), std::string::npos) << failed.error().message;
}

TEST(ServiceRig, ItsCameraStampsOnTheRigsClockAndVanishesWhenAsked) {
  auto rig = make(options(0.0, true));
  ASSERT_TRUE(rig);
  EXPECT_TRUE(rig->cameras_ready());
  EXPECT_FALSE(rig->open_camera(1, 0).ok());  // one camera configured
  const TimeNs opened = rig->now_ns();
  auto camera = rig->open_camera(0, 3);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  ASSERT_TRUE((*camera)->start().ok());
  auto none = [](std::span<const ImuSample>) {};
  int frames = 0;
  TimeNs last = 0;
  Status gone;
  for (int i = 0; i < 30 && gone.ok(); ++i) {
    ASSERT_TRUE(rig->tick(false, none).ok());
    for (;;) {
      auto f = (*camera)->dequeue();
      if (!f.ok()) {
        gone = f.error();
        break;
      }
      if (!f->valid()) break;
      EXPECT_LE(f->t_ns, rig->now_ns());
      if (frames > 0) {
        EXPECT_EQ(f->t_ns - last, 50'000'000);  // 20 Hz on the rig's clock
      }
      last = f->t_ns;
      EXPECT_EQ(f->width, 320);
      ++frames;
      f->release();
    }
  }
  EXPECT_EQ(frames, 3);
  EXPECT_GE(last, opened + 150'000'000);  // the first frame a period after opening
  EXPECT_EQ(gone.error().code, Errc::kNotFound);
}

/// One row of the truth table, split into its columns.
struct TableRow {
  bool found = false;
  std::string unit, estimate, truth, error, relative, sigma, ratio;
};

TableRow table_row(const std::string& text, const std::string& name) {
  TableRow r;
  // The name, then its padding or the column's space: "accel scale x" is no row of "accel scale xy".
  const auto at = text.find("\n  " + name + " ");
  if (at == std::string::npos) return r;
  std::istringstream in(text.substr(at + 3 + name.size(), text.find('\n', at + 1) - at - 3 - name.size()));
  std::vector<std::string> t;
  for (std::string w; in >> w;) t.push_back(w);
  if (t.size() < 7) return r;
  r.found = true;
  r.unit = t[0];
  r.estimate = t[1];
  r.truth = t[2];
  r.error = t[3];
  r.relative = t[4];
  if (t[5] == "not" && t[6] == "determined") {
    r.sigma = "not determined";  // across the sigma's and the ratio's columns
    r.ratio = "-";
  } else {
    r.sigma = t[5];
    r.ratio = t[6];
  }
  return r;
}

double num(const std::string& s) { return std::strtod(s.c_str(), nullptr); }

nlohmann::json mat_json(const Eigen::Matrix3d& m) {
  return {{m(0, 0), m(0, 1), m(0, 2)}, {m(1, 0), m(1, 1), m(1, 2)}, {m(2, 0), m(2, 1), m(2, 2)}};
}
nlohmann::json vec_json(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

/// A result message written as JSON, typed as the service hands it to the rig.
session_msg::ResultSummary service_rig_result(const nlohmann::json& message) {
  auto m = session_msg::decode(message);
  EXPECT_TRUE(m.ok()) << m.error().message;
  return m.ok() ? std::get<session_msg::ResultSummary>(*m) : session_msg::ResultSummary{};
}

session_msg::Prompt service_rig_prompt(session_msg::StepId step, const std::string& text) {
  return {std::nullopt, step, text, {}, {}, std::nullopt};
}

TEST(ServiceRig, TheTruthReportWithoutResultFilesShowsEveryQuantityWithoutSigmas) {
  auto rig = make(options(0.0, false));
  ASSERT_TRUE(rig);
  EXPECT_EQ(rig->truth_report(service_rig_result(nlohmann::json{{"type", "result"}})), "");
  const nlohmann::json I = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const nlohmann::json zero = {0, 0, 0};
  const nlohmann::json result = {
      {"type", "result"},
      {"imu", {{"A_a", I}, {"A_g", I}, {"G", {zero, zero, zero}}, {"b_a", zero}, {"b_g", zero}}}};
  const std::string text = rig->truth_report(service_rig_result(result));
  // Scales, misalignments and biases of both triads; no G (none estimated) and no camera.
  EXPECT_NE(text.find("21 quantities, 0 with a sigma"), std::string::npos) << text;
  const TableRow scale = table_row(text, "accel scale x");
  ASSERT_TRUE(scale.found) << text;
  EXPECT_EQ(scale.unit, "(m/s^2)/count");
  EXPECT_EQ(scale.sigma, "not determined");
  EXPECT_EQ(scale.ratio, "-");
  const TableRow bias = table_row(text, "gyro bias z");
  ASSERT_TRUE(bias.found) << text;
  EXPECT_EQ(bias.unit, "deg/s");
  EXPECT_EQ(bias.sigma, "not determined");
  EXPECT_TRUE(table_row(text, "gyro misalignment zy").found) << text;
  EXPECT_FALSE(table_row(text, "accel misalignment zy").found) << "accel misalignment is upper-triangular";
  EXPECT_EQ(text.find("G_xx"), std::string::npos) << text;
}

TEST(ServiceRig, TheTruthTableShowsEveryEstimatedQuantityWithItsErrorAgainstTheTruthAndItsSigma) {
  const std::string dir = test::scratch_dir();
  ServiceRigOptions o = options(0.0, true);
  auto rig = make(o);
  ASSERT_TRUE(rig);
  // The biases' truth is their mean over the still and pose steps.
  auto none = [](std::span<const ImuSample>) {};
  rig->on_message(service_rig_prompt(session_msg::StepId::kStill, "Keep still"));
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(rig->tick(false, none).ok());
  rig->on_message(service_rig_prompt(session_msg::StepId::kPoses, "Turn"));
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(rig->tick(false, none).ok());
  rig->on_message(service_rig_prompt(session_msg::StepId::kMotion, "Move"));

  // The truth of the rig drawn from the seed (scales, misalignments, G do not wander), in the
  // frame of the static result, and the virtual camera's.
  const ImuModelParams p = ImuModelParams::draw(o.seed);
  const CanonicalImuModel truth = canonical_in_tedaldi_frame(p, true);
  const CameraModel camera = sim_camera_for(320, 240);
  const Eigen::Isometry3d T = CamImuSimOptions::default_T_cam_imu();

  // The estimate: the truth, off by two sigmas in the accelerometer's x scale, three in fx, two
  // in the translation's y, the time offset and the rotation about the camera's x axis.
  CanonicalImuModel est = truth;
  const double scale_x = truth.A_a(0, 0);
  est.A_a.col(0) *= 1.001;  // the scale, not the misalignments of that column
  est.b_a = truth.b_a + Eigen::Vector3d(2.0, 0.0, 0.0);
  const Eigen::Quaterniond q_true(T.rotation());
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.001, Eigen::Vector3d::UnitX()) * q_true);
  const Eigen::Vector3d t = T.translation() + Eigen::Vector3d(0.0, 0.001, 0.0);
  const double shift = kVirtualTimeshiftCamImuS + 1e-4;

  Eigen::Matrix3d m_sigma = Eigen::Matrix3d::Constant(1e-4);
  m_sigma(2, 1) = 0.0;  // a sigma the result could not compute: never shown as 0
  const nlohmann::json sigmas = {{"scale", {scale_x * 5e-4, 1e-7, 1e-7}},
                                 {"misalignment", mat_json(m_sigma)},
                                 {"bias", {1.0, 1.0, 1.0}}};
  nlohmann::json static_json = {
      {"accel", {{"sigma", sigmas}}},
      {"gyro", {{"sigma", sigmas}}},
      {"gsens", {{"mode", "estimate"}, {"G_sigma", mat_json(Eigen::Matrix3d::Constant(1e-5))}}}};
  test::write_file(dir + "/imu-static.json", static_json.dump());
  std::ostringstream cam;
  cam << "cam0:\n  camera_model: pinhole\n  intrinsics: [" << camera.intrinsics[0] + 0.3 << ", "
      << camera.intrinsics[1] << ", " << camera.intrinsics[2] << ", " << camera.intrinsics[3]
      << "]\n  distortion_model: radtan\n  distortion_coeffs: [" << camera.distortion_coeffs[0] << ", "
      << camera.distortion_coeffs[1] << ", " << camera.distortion_coeffs[2] << ", "
      << camera.distortion_coeffs[3]
      << "]\n  imucal:\n    intrinsics_sigma: [0.1, 0.1, 0.1, 0.1]\n    distortion_coeffs_sigma: [1e-4, "
         "1e-4, 1e-5, "
         "1e-5]\n";
  test::write_file(dir + "/camera-cam0.yaml", cam.str());
  const nlohmann::json camimu = {{"cameras",
                                  {{{"name", "cam0"},
                                    {"rotation_sigma_rad", {0.0005, nullptr, 0.0005}},
                                    {"translation_sigma_m", {0.0005, 0.0005, 0.0005}},
                                    {"timeshift_sigma_s", 5e-5}}}}};
  test::write_file(dir + "/camimu/result.json", camimu.dump());

  const nlohmann::json result = {{"type", "result"},
                                 {"files",
                                  {dir + "/imu-static.json", dir + "/imu-static.yaml",
                                   dir + "/camera-cam0.yaml", dir + "/camimu/result.json"}},
                                 {"imu",
                                  {{"A_a", mat_json(est.A_a)},
                                   {"b_a", vec_json(est.b_a)},
                                   {"A_g", mat_json(est.A_g)},
                                   {"b_g", vec_json(est.b_g)},
                                   {"G", mat_json(est.G)}}},
                                 {"cameras",
                                  {{{"name", "cam0"},
                                    {"t_cam_imu_m", vec_json(t)},
                                    {"q_cam_imu_wxyz", {q.w(), q.x(), q.y(), q.z()}},
                                    {"timeshift_cam_imu_s", shift},
                                    {"reprojection_rms_px", 0.05}}}}};
  const std::string text = rig->truth_report(service_rig_result(result));

  // Every estimated quantity has its row: 9 accelerometer, 12 gyroscope, 9 G, 4 intrinsics, 4
  // distortion, 3 rotation, 3 translation, the time offset.
  EXPECT_NE(text.find("\n  45 quantities, 43 with a sigma"), std::string::npos) << text;
  // The table and its notes fit 100 columns (the demo's last screen).
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) EXPECT_LE(line.size(), 100u) << line;
  for (const char* name :
       {"accel scale y", "accel misalignment xy", "accel misalignment yz", "accel bias z", "gyro scale z",
        "gyro misalignment zx", "gyro bias y", "gyro g-sensitivity G_zy", "cam0 fy", "cam0 cx", "cam0 cy",
        "cam0 distortion k1", "cam0 distortion p2", "cam0 rotation about z", "cam0 translation z"})
    EXPECT_TRUE(table_row(text, name).found) << name << "\n" << text;

  const TableRow scale = table_row(text, "accel scale x");
  ASSERT_TRUE(scale.found) << text;
  // (Estimates and truths are printed to 6 digits, errors and sigmas to 2, ratios to 0.1.)
  EXPECT_NEAR(num(scale.truth), scale_x, scale_x * 1e-5);
  EXPECT_NEAR(num(scale.error), scale_x * 1e-3, scale_x * 5e-5);
  EXPECT_EQ(scale.relative, "1.0e-03");
  EXPECT_EQ(scale.ratio, "2.0");
  EXPECT_EQ(table_row(text, "accel scale y").ratio, "0.0");
  // The accelerometer's bias in m/s^2 at the nominal sensitivity, with a sigma of one count; its
  // truth the mean over the still and pose steps, near the turn-on bias after 2 s.
  const TableRow bias = table_row(text, "accel bias x");
  const double lsb = p.accel_mps2_per_count();
  EXPECT_EQ(bias.unit, "m/s^2");
  EXPECT_NEAR(num(bias.estimate), est.b_a.x() * lsb, 1e-6);
  EXPECT_NEAR(num(bias.truth), p.accel_bias.x(), 0.01);
  const double bias_error = num(bias.estimate) - num(bias.truth);
  EXPECT_NEAR(num(bias.error), bias_error, 0.05 * std::abs(bias_error));
  EXPECT_NEAR(num(bias.sigma), lsb, 0.05 * lsb);
  EXPECT_NEAR(num(bias.ratio), bias_error / lsb, 0.06);
  const TableRow gyro_bias = table_row(text, "gyro bias x");
  EXPECT_EQ(gyro_bias.unit, "deg/s");
  EXPECT_NEAR(num(gyro_bias.truth), p.gyro_bias.x() * 180.0 / std::numbers::pi, 0.01);
  EXPECT_NEAR(num(gyro_bias.sigma), p.gyro_radps_per_count() * 180.0 / std::numbers::pi, 5e-4);
  EXPECT_EQ(table_row(text, "gyro misalignment zy").sigma, "not determined");
  EXPECT_EQ(table_row(text, "gyro misalignment zy").ratio, "-");
  EXPECT_EQ(table_row(text, "gyro g-sensitivity G_xy").unit, "(rad/s)/(m/s^2)");

  const TableRow fx = table_row(text, "cam0 fx");
  EXPECT_EQ(fx.unit, "px");
  EXPECT_NEAR(num(fx.truth), camera.intrinsics[0], 1e-3);
  EXPECT_NEAR(num(fx.error), 0.3, 1e-6);
  EXPECT_EQ(fx.ratio, "3.0");
  EXPECT_EQ(table_row(text, "cam0 distortion k2").ratio, "0.0");

  const TableRow rot_x = table_row(text, "cam0 rotation about x");
  EXPECT_EQ(rot_x.unit, "deg");
  EXPECT_NEAR(num(rot_x.error), 0.001 * 180.0 / std::numbers::pi, 1e-3);
  EXPECT_EQ(rot_x.ratio, "2.0");
  EXPECT_EQ(table_row(text, "cam0 rotation about y").sigma, "not determined");
  const TableRow ty = table_row(text, "cam0 translation y");
  EXPECT_EQ(ty.unit, "mm");
  EXPECT_NEAR(num(ty.truth), T.translation().y() * 1e3, 1e-3);
  EXPECT_NEAR(num(ty.error), 1.0, 1e-6);
  EXPECT_EQ(ty.ratio, "2.0");

  // The virtual camera stamps late: the truth of the time offset is not zero.
  const TableRow offset = table_row(text, "cam0 time offset");
  EXPECT_EQ(offset.unit, "ms");
  EXPECT_NEAR(num(offset.truth), kVirtualTimeshiftCamImuS * 1e3, 1e-9);
  EXPECT_NE(num(offset.truth), 0.0);
  EXPECT_NEAR(num(offset.error), 0.1, 1e-6);
  EXPECT_EQ(offset.ratio, "2.0");
}

}  // namespace
}  // namespace imucal::sim
