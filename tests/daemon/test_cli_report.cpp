// SPDX-License-Identifier: BSD-3-Clause
// imucal report: the HTML report of the static calibration of the committed fixture (with and
// without its log), of an Allan analysis, the PNG figures, the errors, and the page in a
// headless browser. Tests that need gnuplot or chromium skip, saying so, where they are missing.

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using test::run_cli;

#define REQUIRE_GNUPLOT()                                                                                \
  if (!test::on_path("gnuplot"))                                                                         \
  GTEST_SKIP() << "gnuplot is not installed (Debian package gnuplot-nox, scripts/install-deps.sh): the " \
                  "report's figures cannot be drawn"

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

/// The static result of the fixture, computed once for the suite.
class CliReport : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // One folder per process: ctest runs each test in its own process, several at once, and a
    // shared folder removed by one while another reads it made tests skip at random.
    dir_ = (fs::path(IMUCAL_TEST_TMP) / ("CliReport.shared." + std::to_string(::getpid()))).string();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    const auto r = run_cli({"calibrate", "static", test::source_path("fixtures/static.imulog"), "-o",
                            dir_ + "/static.yaml", "--json", dir_ + "/static.json"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static std::string log() { return test::source_path("fixtures/static.imulog"); }
  static std::string result() { return dir_ + "/static.json"; }
  static std::string dir_;
};
std::string CliReport::dir_;

/// Checks a report page: self-contained, with `figures` figures each embedded as an SVG.
void expect_page(const std::string& html, std::size_t figures) {
  EXPECT_EQ(html.find("http://"), std::string::npos) << "the report refers to the network";
  EXPECT_EQ(html.find("https://"), std::string::npos) << "the report refers to the network";
  EXPECT_EQ(html.find("src=\"file:"), std::string::npos);
  EXPECT_EQ(count(html, "<figure class=\"plot\""), figures);
  EXPECT_EQ(count(html, "src=\"data:image/svg+xml;base64,"), figures);
  EXPECT_NE(html.find("data-plots=\"" + std::to_string(figures) + "\""), std::string::npos);
}

TEST_F(CliReport, StaticWithLogHasEveryFigureAndThePngs) {
  REQUIRE_GNUPLOT();
  const std::string out = test::scratch_dir();
  const auto r =
      run_cli({"report", result(), "--log", log(), "-o", out + "/report.html", "--png-dir", out + "/png"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("6 figures"), std::string::npos) << r.out;
  const std::string html = test::read_file(out + "/report.html");
  expect_page(html, 6);
  for (const char* id : {"static-accel-signal", "static-gyro-signal", "static-gravity-magnitude",
                         "static-gravity-direction", "static-pose-directions", "static-threshold-search"}) {
    EXPECT_NE(html.find(std::string("data-plot=\"") + id + "\""), std::string::npos) << id;
    const std::string png = test::read_file(out + "/png/" + id + ".png");
    ASSERT_GT(png.size(), 1000u) << id;
    EXPECT_EQ(png.substr(1, 3), "PNG") << id;
  }
  EXPECT_EQ(std::distance(fs::directory_iterator(out + "/png"), fs::directory_iterator{}), 6);
  // Content from the result and the log: the parameters with sigmas, the session.
  EXPECT_NE(html.find("&plusmn;"), std::string::npos);
  EXPECT_NE(html.find("Gyroscope g-sensitivity"), std::string::npos);
  // The interval count of the result (the calibration decides it, not the report).
  const auto j = nlohmann::json::parse(test::read_file(result()));
  EXPECT_NE(html.find(std::to_string(j["static_intervals"].size()) + " static intervals"), std::string::npos);
  EXPECT_NE(html.find("closed cleanly"), std::string::npos);
  EXPECT_EQ(html.find("not closed cleanly"), std::string::npos);
}

TEST_F(CliReport, StaticWithoutLogHasTheResultsFiguresOnly) {
  REQUIRE_GNUPLOT();
  const std::string out = test::scratch_dir();
  const auto r = run_cli({"report", result(), "-o", out + "/report.html"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("no --log"), std::string::npos) << r.out;
  expect_page(test::read_file(out + "/report.html"), 1);
  EXPECT_FALSE(fs::exists(out + "/png"));
}

TEST_F(CliReport, AllanCurvesWithFits) {
  REQUIRE_GNUPLOT();
  const std::string out = test::scratch_dir();
  const auto a =
      run_cli({"allan", test::source_path("fixtures/still.imulog"), "--json", out + "/allan.json"});
  ASSERT_EQ(a.exit_code, 0) << a.err;
  const auto r = run_cli({"report", out + "/allan.json", "-o", out + "/allan.html", "--png-dir", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string html = test::read_file(out + "/allan.html");
  expect_page(html, 2);
  EXPECT_NE(html.find("noise density"), std::string::npos);
  EXPECT_GT(test::read_file(out + "/allan-gyro.png").size(), 1000u);
  EXPECT_GT(test::read_file(out + "/allan-accel.png").size(), 1000u);
}

TEST_F(CliReport, ThermalModelWithItsCurvesBandsAndWhatCompensationLeaves) {
  REQUIRE_GNUPLOT();
  const std::string out = test::scratch_dir();
  const auto sim = run_cli({"sim", "still", "--seed", "3", "--duration", "1800", "--imu-rate", "10",
                            "--temp-profile", "warmup", "--temp-start", "20", "--temp-final", "50",
                            "--temp-coeffs", "2", "-o", out + "/warm.imulog"});
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  const auto t = run_cli({"calibrate", "thermal", out + "/warm.imulog", "-o", out + "/thermal.yaml"});
  ASSERT_EQ(t.exit_code, 0) << t.err;
  // The YAML itself is the report's input, and the log gives the session section.
  const auto r = run_cli({"report", out + "/thermal.yaml", "--log", out + "/warm.imulog", "-o",
                          out + "/thermal.html", "--png-dir", out + "/png"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("thermal calibration"), std::string::npos) << r.out;
  const std::string html = test::read_file(out + "/thermal.html");
  expect_page(html, 4);
  for (const char* id : {"thermal-gyro", "thermal-gyro-after", "thermal-accel", "thermal-accel-after"}) {
    EXPECT_NE(html.find(std::string("data-plot=\"") + id + "\""), std::string::npos) << id;
    EXPECT_GT(test::read_file(out + "/png/" + id + ".png").size(), 1000u) << id;
  }
  EXPECT_NE(html.find("c<sub>1</sub> = "), std::string::npos);
  EXPECT_NE(html.find("&plusmn;"), std::string::npos);
  EXPECT_NE(html.find("before, "), std::string::npos);  // the RMS before and after compensation
  EXPECT_NE(html.find("deg C (the model is valid over this range only)"), std::string::npos);
}

TEST_F(CliReport, RefusesMissingUnknownAndForeignInputs) {
  const std::string out = test::scratch_dir();
  auto r = run_cli({"report", out + "/none.json", "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
  std::ofstream(out + "/text.json") << "not json";
  r = run_cli({"report", out + "/text.json", "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("is not JSON"), std::string::npos) << r.err;
  std::ofstream(out + "/other.json") << "{\"a\": 1}";
  r = run_cli({"report", out + "/other.json", "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("no result imucal writes"), std::string::npos) << r.err;
  // A camchain without imucal's figures (as Kalibr writes it) is named so (calibrate camera -o's
  // own is drawn: CliCalibrateChain).
  std::ofstream(out + "/camchain.yaml")
      << "cam0:\n  camera_model: pinhole\n  intrinsics: [400, 400, 320, 240]\n";
  r = run_cli({"report", out + "/camchain.yaml", "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("camchain.yaml"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("is a camchain without imucal's figures"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out + "/r.html"));
}

TEST_F(CliReport, RefusesALogTheResultDidNotComeFrom) {
  REQUIRE_GNUPLOT();
  const std::string out = test::scratch_dir();
  const auto r = run_cli(
      {"report", result(), "--log", test::source_path("fixtures/still.imulog"), "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("not samples of"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out + "/r.html"));
}

TEST_F(CliReport, RefusesOutputsItMayNotWrite) {
  const std::string out = test::scratch_dir();
  std::ofstream(out + "/exists.html") << "old";
  auto r = run_cli({"report", result(), "-o", out + "/exists.html"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--force"), std::string::npos) << r.err;
  EXPECT_EQ(test::read_file(out + "/exists.html"), "old");
  r = run_cli({"report", result(), "-o", result()});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  if (!test::on_path("gnuplot")) return;
  r = run_cli({"report", result(), "-o", out + "/no/such/folder/r.html"});
  EXPECT_EQ(r.exit_code, 7) << r.err;
  EXPECT_NE(r.err.find("could not write"), std::string::npos) << r.err;
}

/// Runs the CLI with PATH set to `path` (restored afterwards).
test::CommandResult run_with_path(const std::string& path, const std::vector<std::string>& args) {
  const std::string saved = std::getenv("PATH") ? std::getenv("PATH") : "";
  ::setenv("PATH", path.c_str(), 1);
  auto r = run_cli(args);
  ::setenv("PATH", saved.c_str(), 1);
  return r;
}

TEST_F(CliReport, NamesThePackageWhenGnuplotIsMissing) {
  const std::string out = test::scratch_dir();
  fs::create_directories(out + "/empty");
  const auto r = run_with_path(out + "/empty", {"report", result(), "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("gnuplot-nox"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out + "/r.html"));
}

TEST_F(CliReport, ShowsWhatGnuplotSaidWhenItFails) {
  const std::string out = test::scratch_dir();
  // A gnuplot that starts (--version) but fails on every script, as a broken installation would.
  const std::string fake = out + "/bin/gnuplot";
  fs::create_directories(out + "/bin");
  std::ofstream(fake) << "#!/bin/sh\n[ \"$1\" = --version ] && { echo 'gnuplot 5.4'; exit 0; }\n"
                         "echo 'line 3: unknown terminal type (test)' >&2\nexit 1\n";
  fs::permissions(fake, fs::perms::owner_all);
  const auto r = run_with_path(out + "/bin:/usr/bin:/bin", {"report", result(), "-o", out + "/r.html"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("unknown terminal type (test)"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out + "/r.html"));
}

// A result whose data for a figure are empty or absurd (1e308) still gets its report: the
// figure gives way to a note, a warning names it, and the exit code is 0, not 1.
TEST_F(CliReport, AFigureWithNothingToPlotIsANoteNotAFailure) {
  REQUIRE_GNUPLOT();
  const std::string out = test::scratch_dir();
  auto j = nlohmann::json::parse(test::read_file(result()));
  ASSERT_TRUE(j.contains("threshold_search"));
  auto huge = j;
  for (auto& row : huge["threshold_search"])
    for (auto& [key, value] : row.items())
      if (value.is_number()) value = 1e308;
  auto empty = j;
  empty["threshold_search"] = nlohmann::json::array();
  for (const auto& [name, doc] : {std::pair{"huge", huge}, std::pair{"empty", empty}}) {
    const std::string in = out + "/" + name + ".json";
    test::write_file(in, doc.dump());
    const auto r = run_cli({"report", in, "-o", out + "/" + name + ".html"});
    EXPECT_EQ(r.exit_code, 0) << name << ": " << r.err;
    EXPECT_NE(r.err.find("warning: figure 'Static detector threshold search' not drawn"), std::string::npos)
        << name << ": " << r.err;
    EXPECT_EQ(r.err.find(".gp"), std::string::npos) << "gnuplot's script is no message: " << r.err;
    const std::string html = test::read_file(out + "/" + name + ".html");
    EXPECT_NE(html.find("<figure class=\"plot missing\" id=\"fig-static-threshold-search\">"),
              std::string::npos)
        << name;
  }
}

/// The browser: every figure decodes (the page marks each one), and the screenshot shows them.
TEST_F(CliReport, RendersInAHeadlessBrowser) {
  REQUIRE_GNUPLOT();
  if (!test::on_path("chromium"))
    GTEST_SKIP() << "chromium is not installed (scripts/install-deps.sh --test)";
  const std::string out = test::scratch_dir();
  auto r = run_cli({"report", result(), "--log", log(), "-o", out + "/report.html"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string url = "file://" + fs::absolute(out + "/report.html").string();
  const std::string chromium =
      "chromium --headless --no-sandbox --disable-gpu --user-data-dir=" + out + "/profile";
  ASSERT_EQ(
      std::system((chromium + " --dump-dom " + url + " > " + out + "/dom.html 2> " + out + "/err1").c_str()),
      0)
      << test::read_file(out + "/err1");
  const std::string dom = test::read_file(out + "/dom.html");
  EXPECT_EQ(count(dom, "data-rendered=\"1\""), 6u) << "a figure did not decode in the browser";
  EXPECT_NE(dom.find("data-plots-rendered=\"6\""), std::string::npos);

  ASSERT_EQ(std::system((chromium + " --hide-scrollbars --window-size=1200,4000 --screenshot=" + out +
                         "/shot.png " + url + " > " + out + "/err2 2>&1")
                            .c_str()),
            0)
      << test::read_file(out + "/err2");
  const cv::Mat shot = cv::imread(out + "/shot.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty());
  EXPECT_EQ(shot.cols, 1200);
  // Not blank, and the plots' lines are there: pixels of the report's blue (#0072b2, BGR) appear
  // only in figures.
  cv::Mat gray, ink, blue;
  cv::cvtColor(shot, gray, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(gray < 200), shot.total() / 200) << "the page looks blank";
  cv::inRange(shot, cv::Scalar(150, 85, 0), cv::Scalar(210, 140, 40), blue);
  EXPECT_GT(cv::countNonZero(blue), 500) << "no plot line in the screenshot";
}

}  // namespace
}  // namespace imucal
