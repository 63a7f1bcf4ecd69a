// SPDX-License-Identifier: BSD-3-Clause
// The report's pieces without the CLI: kind detection, number formatting, base64, and the
// camera-IMU and camera reports of results written by their own writers (app/camimu_results,
// app/camera_results), so that a change of those schemas shows here. Drawing needs gnuplot; those
// tests skip, saying so, without it.

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/report/html.hpp"
#include "app/report/report.hpp"
#include "app/results/camera_results.hpp"
#include "app/results/camimu_results.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app::report {
namespace {

namespace fs = std::filesystem;

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

TEST(Report, DetectsTheKindFromTheContent) {
  using nlohmann::json;
  EXPECT_EQ(*detect_report_kind(json{{"static_intervals", json::array()}, {"accel", 1}, {"gyro", 1}}, "r"),
            ReportKind::kStatic);
  EXPECT_EQ(*detect_report_kind(json{{"accelerometer", 1}, {"gyroscope", 1}, {"kalibr", 1}}, "r"),
            ReportKind::kAllan);
  EXPECT_EQ(*detect_report_kind(json{{"cameras", 1}, {"imu", 1}, {"biases", 1}}, "r"), ReportKind::kCamImu);
  EXPECT_EQ(*detect_report_kind(json{{"intrinsics", 1}, {"views", 1}, {"coverage_grid", 1}}, "r"),
            ReportKind::kCamera);
  const auto unknown = detect_report_kind(json{{"accel", 1}}, "x.json");
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().code, Errc::kCorrupt);
  EXPECT_NE(unknown.error().message.find("x.json"), std::string::npos);
  EXPECT_FALSE(detect_report_kind(json::array(), "r").ok());
}

TEST(Report, FormatsValuesWithTheirSigmas) {
  EXPECT_EQ(with_sigma(1.0012345, 0.00023), "1.00123 &plusmn; 0.00023");
  EXPECT_EQ(with_sigma(32768.123, 1.5), "32768.1 &plusmn; 1.5");
  EXPECT_EQ(with_sigma(1.234e-5, 1.1e-6), "(1.23 &plusmn; 0.11)e-05");
  EXPECT_EQ(with_sigma(0.5, 0.0), "0.5 (fixed)");
  EXPECT_EQ(with_sigma(0.5, std::nan("")), "0.5 (&sigma; not determined)");
  // An estimated parameter whose sigma could not be computed is never shown as fixed.
  EXPECT_EQ(with_sigma(0.5, 0.0, false), "0.5 (&sigma; not determined)");
  EXPECT_EQ(with_sigma(0.5, std::nan(""), false), "0.5 (&sigma; not determined)");
  EXPECT_EQ(with_sigma(0.5, 0.0, true), "0.5 (fixed)");
  EXPECT_EQ(with_sigma(0.5, 0.1, false), with_sigma(0.5, 0.1));
  EXPECT_EQ(num(std::nan("")), "undetermined");
  EXPECT_EQ(escape("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
}

TEST(Report, Base64OfRfc4648) {
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foo"), "Zm9v");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64(std::string("\xff\x00\x80", 3)), "/wCA");
}

/// A camera-IMU result with two cameras, a bias spline and cross-correlation curves.
CamImuReport camimu_report() {
  CamImuReport r;
  r.log_path = "/data/rig.imulog";
  r.imu_stream.name = "imu0";
  r.imu_stream.units = ImuUnits::kSi;
  auto& res = r.result;
  res.model = CamImuModelKind::kExtended;
  res.imu.S_a = {0.99, 1.01, 1.0};
  res.imu.b_a = {0.38, 0.03, -0.72};
  res.imu.b_g = {0.036, 0.057, 0.066};
  res.imu_sigma.S_a = {1e-4, 2e-4, 3e-4};
  res.canonical = *canonical_from_krebs(res.imu);
  res.gravity_w = {0.01, -0.02, -9.80665};
  res.gravity_sigma_rad = {1e-4, 2e-4};
  for (int i = 0; i < 2; ++i) {
    CamImuCameraResult c;
    c.name = "cam" + std::to_string(i);
    c.stream = c.name;
    c.T_cam_imu.translation() = Eigen::Vector3d(0.031, -0.018, -0.013 + 0.1 * i);
    c.rotation_sigma_rad = {1e-3, 2e-3, 3e-3};
    c.translation_sigma_m = {1e-3, 2e-3, 4e-3};
    c.timeshift_cam_imu_s = i == 0 ? 0.0042 : -0.0031;
    c.timeshift_sigma_s = 1.4e-4;
    c.frames = 1169;
    c.corners = 49000;
    c.reprojection_rms_px = 0.12;
    // Residuals spread over a disc, a few beyond the loss's scale; cam1 has none stored (a
    // result from before they were), which the figure leaves out.
    if (i == 0) {
      for (int k = 0; k < 500; ++k)
        c.residuals_px.emplace_back(0.1F * std::cos(0.7F * k) * (k % 7) / 7.0F,
                                    0.1F * std::sin(0.7F * k) * (k % 5) / 5.0F);
      c.residuals_px.emplace_back(2.5F, -1.0F);
      c.outlier_px = 0.3;
    }
    res.cameras.push_back(c);
  }
  for (int k = 0; k < 20; ++k) {
    const double t = 0.5 * k;
    res.biases.push_back(
        {static_cast<TimeNs>(t * 1e9), res.imu.b_a * (1 + 1e-3 * t), res.imu.b_g * (1 - 1e-3 * t)});
  }
  // Measured and predicted signals of both models: the basic one off by a scale error.
  for (const char* model : {"basic", "extended"}) {
    ImuSignalFit fit;
    fit.model = model;
    const float scale = fit.model == "basic" ? 1.02F : 1.0F;
    for (int k = 0; k < 300; ++k) {
      const float t = 0.01F * static_cast<float>(k);
      const Eigen::Vector3f w(std::sin(t), std::cos(2 * t), 0.5F * std::sin(3 * t));
      const Eigen::Vector3f a(0.3F * std::cos(t), 0.2F * std::sin(t), 9.81F);
      fit.t_ns.push_back(static_cast<TimeNs>(k) * 10'000'000);
      fit.gyro_measured.push_back(w);
      fit.gyro_predicted.push_back(w / scale);
      fit.accel_measured.push_back(a);
      fit.accel_predicted.push_back(a / scale);
    }
    fit.gyro_residual_rms = Eigen::Vector3d::Constant(fit.model == "basic" ? 0.0123 : 0.0011);
    fit.accel_residual_rms = Eigen::Vector3d::Constant(fit.model == "basic" ? 0.117 : 0.04);
    res.signal_fits.push_back(fit);
  }
  res.quality.xcorr = {{{-0.01, 0.5}, {0.0, 0.9}, {0.01, 0.6}}, {{-0.01, 0.7}, {0.0, 1.0}, {0.01, 0.4}}};
  res.quality.xcorr_peak_s = {0.0042, -0.0031};
  res.quality.accel_residual_rms = {0.03, 0.04, 0.05};
  res.quality.gyro_residual_rms = {0.001, 0.0012, 0.0011};
  res.quality.accel_sigma = 0.045;
  res.quality.gyro_sigma = 0.0011;
  r.warnings = {"z rotation barely excited"};
  // The halves disagree on cam0's translation x by 6 combined sigmas; part 2 of cam1 was not solved.
  SplitCheck& sc = res.self_check;
  sc.parts = 2;
  sc.spans_s = {{0.0, 5.0}, {5.0, 10.0}};
  sc.part_errors = {"", ""};
  sc.parameters = {{"cam0 translation x", "mm", {31.0, 37.0}, {0.7, 0.7}},
                   {"cam1 time offset", "ms", {-3.1, std::nan("")}, {0.1, std::nan("")}}};
  judge_split_check(&sc);
  sc.scaled = {{"cam0", 1.7}};
  return r;
}

TEST(Report, CamImuResultFolderFromItsWriter) {
  if (!test::on_path("gnuplot")) GTEST_SKIP() << "gnuplot is not installed (Debian package gnuplot-nox)";
  const std::string dir = test::scratch_dir();
  fs::create_directories(dir + "/out");
  std::ofstream(dir + "/out/result.json") << camimu_result_json(camimu_report());
  ReportOptions o;
  o.result_path = dir + "/out";  // the command's output folder
  o.html_path = dir + "/camimu.html";
  o.png_dir = dir + "/png";
  auto s = write_report(o);
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->kind, ReportKind::kCamImu);
  EXPECT_EQ(s->figures, 7);
  EXPECT_EQ(s->png_files.size(), 7u);
  const std::string html = test::read_file(o.html_path);
  EXPECT_EQ(count(html, "src=\"data:image/svg+xml;base64,"), 7u);
  EXPECT_EQ(html.find("http://"), std::string::npos);
  // 501 of the two cameras' 98000 corners stored (cam1's list is empty), one beyond the axes.
  EXPECT_NE(html.find("501 of 98000 corners stored"), std::string::npos);
  EXPECT_NE(html.find("; 1 lie beyond the axes"), std::string::npos);
  // The residual RMS of each model, deg/s and m/s^2.
  EXPECT_NE(html.find("<td>basic</td><td>0.7047, 0.7047, 0.7047</td><td>0.117, 0.117, 0.117</td>"),
            std::string::npos);
  EXPECT_NE(html.find("300 samples shown"), std::string::npos);
  for (const char* id : {"camimu-reprojection", "camimu-imu-residuals", "camimu-xcorr", "camimu-biases",
                         "camimu-imu-fit-basic", "camimu-imu-fit-extended", "camimu-imu-fit-residuals"})
    EXPECT_NE(html.find(std::string("data-plot=\"") + id + "\""), std::string::npos) << id;
  EXPECT_NE(html.find("z rotation barely excited"), std::string::npos);
  // The cross-correlation figure marks the result beside the peak that started it.
  EXPECT_NE(html.find("the solve&#39;s result is the solid line (cam0 4.20 ms, cam1 -3.10 ms)."),
            std::string::npos);
  EXPECT_NE(html.find("4.20 &plusmn; 0.14"), std::string::npos);   // cam0's time shift, ms
  EXPECT_NE(html.find("-3.10 &plusmn; 0.14"), std::string::npos);  // cam1's
  // The self-check: its verdict, advice, scale and every part, the difference beyond the limit in bold.
  EXPECT_NE(html.find("<h2>Self-check</h2>"), std::string::npos);
  EXPECT_NE(html.find("the two halves disagree beyond their sigmas"), std::string::npos);
  EXPECT_NE(html.find("cam0's sigmas in this report are scaled by 1.7"), std::string::npos);
  EXPECT_NE(html.find("part 2 (5-10 s)"), std::string::npos);
  EXPECT_NE(html.find("<b>6.1</b>"), std::string::npos);
  EXPECT_NE(html.find("not solved"), std::string::npos);
  // Written once: a second run refuses without overwrite.
  EXPECT_EQ(write_report(o).error().code, Errc::kAlreadyExists);
}

TEST(Report, CamImuBasicModelShowsItsHeldParametersAsFixedNotUndetermined) {
  if (!test::on_path("gnuplot")) GTEST_SKIP() << "gnuplot is not installed (Debian package gnuplot-nox)";
  // The basic model holds S, M, C_bg and B_g: their sigmas are absent (NaN), and the report says
  // they were fixed rather than calling them undetermined.
  CamImuReport r = camimu_report();
  r.result.model = CamImuModelKind::kBasic;
  r.result.fixed = {"S_a", "M_a", "S_g", "M_g", "C_bg", "B_g"};
  const double nan = std::nan("");
  r.result.imu_sigma.S_a = r.result.imu_sigma.M_a = r.result.imu_sigma.S_g = r.result.imu_sigma.M_g =
      Eigen::Vector3d::Constant(nan);
  r.result.imu_sigma.C_bg = Eigen::Vector3d::Constant(nan);
  r.result.imu_sigma.B_g = Eigen::Matrix3d::Constant(nan);
  r.result.imu_sigma.b_a = {0.004, 0.003, 0.005};
  r.result.imu_sigma.b_g = {2e-4, 1e-4, 3e-4};
  const std::string dir = test::scratch_dir();
  fs::create_directories(dir + "/out");
  std::ofstream(dir + "/out/result.json") << camimu_result_json(r);
  ReportOptions o;
  o.result_path = dir + "/out";
  o.html_path = dir + "/camimu.html";
  o.png_dir = dir + "/png";
  ASSERT_TRUE(write_report(o).ok());
  const std::string html = test::read_file(o.html_path);
  const auto imu = html.find("<h2>IMU</h2>");
  ASSERT_NE(imu, std::string::npos);
  const std::string section = html.substr(imu, html.find("<h2>", imu + 4) - imu);
  EXPECT_EQ(section.find("undetermined"), std::string::npos) << section;
  EXPECT_EQ(section.find("not determined"), std::string::npos) << section;
  EXPECT_NE(section.find("deg (fixed)"), std::string::npos) << section;         // C_bg
  EXPECT_EQ(count(section, "0 (fixed); 0 (fixed); 0 (fixed)"), 3u) << section;  // B_g's rows
  // The biases are estimated: with their sigmas.
  EXPECT_NE(section.find("&plusmn;"), std::string::npos);
}

TEST(Report, CameraResultFromItsWriter) {
  if (!test::on_path("gnuplot")) GTEST_SKIP() << "gnuplot is not installed (Debian package gnuplot-nox)";
  CameraCalibrationReport r;
  r.stream.name = "cam0";
  auto& res = r.intrinsics;
  res.camera.width = 376;
  res.camera.height = 240;
  res.camera.intrinsics = {200.25, 199.75, 188.5, 117.125};
  res.camera.distortion_coeffs = {-0.28, 0.07, 0.0002, -0.0003};
  res.intrinsics_sigma = {0.1, 0.1, 0.05, 0.05};
  res.distortion_sigma = {0.001, 0.002, 1e-5, 1e-5};
  res.views_total = 3;
  res.views_used = 2;
  res.views.resize(3);
  res.views[0].rejected_because = "too few points (3)";
  res.views[1].used = res.views[2].used = true;
  res.views[1].rms_px = 0.2;
  res.views[2].rms_px = 0.3;
  res.coverage_cols = 10;
  res.coverage_rows = 6;
  res.coverage_counts.assign(60, 4);
  const std::string dir = test::scratch_dir();
  // Without corner residuals (a result from before they were stored): no scatter, a note.
  std::ofstream(dir + "/old.json") << camera_result_json(r);
  ReportOptions old;
  old.result_path = dir + "/old.json";
  old.html_path = dir + "/old.html";
  auto before = write_report(old);
  ASSERT_TRUE(before.ok()) << before.error().message;
  EXPECT_EQ(before->figures, 2);
  EXPECT_NE(test::read_file(old.html_path).find("there is no scatter of them"), std::string::npos);
  EXPECT_EQ(test::read_file(old.html_path).find("Self-check"), std::string::npos);  // not run: no section
  // The halves, which agree.
  r.self_check.parts = 2;
  r.self_check.spans_s = {{0.0, 30.0}, {30.0, 60.0}};
  r.self_check.part_errors = {"", ""};
  r.self_check.parameters = {{"cam0 fu", "px", {200.2, 200.3}, {0.1, 0.1}}};
  judge_split_check(&r.self_check);
  // With them: the used corners and the one the corner test rejected.
  res.points_used = 3;
  res.corners_rejected = 1;
  res.residuals_px = {{0.1F, -0.05F}, {-0.02F, 0.03F}, {0.0F, 0.08F}, {0.9F, 0.7F}};
  res.residual_rejected = {0, 0, 0, 1};
  std::ofstream(dir + "/camera.json") << camera_result_json(r);
  ReportOptions o;
  o.result_path = dir + "/camera.json";
  o.html_path = dir + "/camera.html";
  auto s = write_report(o);
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->kind, ReportKind::kCamera);
  EXPECT_EQ(s->figures, 3);
  const std::string html = test::read_file(o.html_path);
  EXPECT_NE(html.find("200.25 &plusmn; 0.10"), std::string::npos);
  EXPECT_EQ(count(html, "<figure class=\"plot\""), 3u);
  EXPECT_NE(html.find("data-plot=\"camera-reprojection\""), std::string::npos);
  EXPECT_NE(html.find("4 of 4 stored"), std::string::npos);
  EXPECT_NE(html.find("<h2>Self-check</h2>"), std::string::npos);
  EXPECT_NE(html.find("the two halves agree within their sigmas"), std::string::npos);
  EXPECT_NE(html.find("part 2 (30-60 s)"), std::string::npos);
}

}  // namespace
}  // namespace imucal::app::report
