// SPDX-License-Identifier: BSD-3-Clause
// The live view in a real browser: a frame of the virtual camera's renderer, searched by the
// detector the session uses, shrunk and sent as the session's runner and imucald send it, is
// drawn by the page in headless Chromium; the corners drawn in the screenshot are compared with
// where the renderer's own truth projects the board's corners. Skips, saying so, without
// chromium.

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "app/session/view_coverage.hpp"
#include "calib/target_detection.hpp"
#include "daemon/service/live_view_server.hpp"
#include "sim/camera_render.hpp"
#include "tests/daemon/service_test_host.hpp"
#include "tests/support/chain_views.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;

TEST(LiveViewBrowser, TheCornersThePageDrawsAreWhereTheRenderersTruthProjectsThem) {
  if (!test::on_path("chromium"))
    GTEST_SKIP() << "chromium is not installed (scripts/install-deps.sh --test)";
  const CameraModel camera = test::chain_camera(520.0, 318.0);
  const TargetDescription board = test::chain_board();
  auto renderer = sim::TargetRenderer::create(camera, board, {});
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  // The board 0.6 m ahead, turned 20 degrees about y and 10 about x, off centre.
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() =
      (Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(0.17, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  T.translation() = Eigen::Vector3d(-0.15, -0.08, 0.6);
  const Eigen::Isometry3d poses[] = {T};
  const cv::Mat image = (*renderer)->render(poses, nullptr);
  const sim::CornerTruth truth = (*renderer)->project_corners(T);
  ASSERT_EQ(truth.visible_count, 48);

  auto detector = calib::TargetDetector::create(board);
  ASSERT_TRUE(detector.ok()) << detector.error().message;
  auto obs = (*detector)->detect(calib::GrayView{image.data, image.cols, image.rows, 0});
  ASSERT_TRUE(obs.ok() && obs->ids.size() == 48u) << "the detector did not find the whole board";

  ViewFrame frame =
      app::session::make_view_frame(image.data, image.cols, image.rows, 320, obs->px, obs->ids, board);
  frame.name = "cam0";
  auto png = app::session::view_frame_png(frame);
  ASSERT_TRUE(png.ok());

  test::TestHost host;
  test::IoThread loop;
  service::LiveViewOptions options;
  options.port = 0;
  options.cameras = {"cam0"};
  options.token = "x";
  auto server = loop.call([&] { return service::LiveViewServer::create(loop.io, options, host); });
  ASSERT_TRUE(server.ok()) << server.error().message;
  loop.call([&] { (*server)->frame(frame, *png); });
  const std::string url = (*server)->url() + "?camera=0&seq=1";

  const std::string out = test::scratch_dir();
  const std::string chromium =
      "chromium --headless --no-sandbox --disable-gpu --hide-scrollbars "
      "--force-device-scale-factor=1 --virtual-time-budget=5000 --user-data-dir=" +
      out + "/profile";
  const int dom_rc = std::system(
      (chromium + " --dump-dom '" + url + "' > " + out + "/dom.html 2> " + out + "/err1").c_str());
  const int shot_rc = std::system((chromium + " --window-size=400,300 --screenshot=" + out + "/shot.png '" +
                                   url + "' > " + out + "/err2 2>&1")
                                      .c_str());
  loop.call([&] { server->reset(); });
  loop.stop();
  ASSERT_EQ(dom_rc, 0) << test::read_file(out + "/err1");
  ASSERT_EQ(shot_rc, 0) << test::read_file(out + "/err2");
  EXPECT_NE(test::read_file(out + "/dom.html").find("<title>frame-drawn 1</title>"), std::string::npos)
      << "the page did not draw the frame";

  const cv::Mat shot = cv::imread(out + "/shot.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty());
  // The image is there: the board's black and white squares.
  int dark = 0, light = 0;
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x) {
      const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);
      if (p[0] < 60 && p[1] < 60 && p[2] < 60) ++dark;
      if (p[0] > 190 && p[1] > 190 && p[2] > 190) ++light;
    }
  EXPECT_GT(dark, 2000);
  EXPECT_GT(light, 2000);
  // Each truth corner, shrunk: the centre of the magenta pixels drawn within 6 px of it.
  const double f = static_cast<double>(image.cols) / frame.width;
  double worst = 0.0;
  int found = 0;
  for (std::size_t i = 0; i < truth.px.size(); ++i) {
    const Eigen::Vector2d want((truth.px[i].x() + 0.5) / f - 0.5, (truth.px[i].y() + 0.5) / f - 0.5);
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int n = 0;
    for (int y = static_cast<int>(want.y()) - 6; y <= static_cast<int>(want.y()) + 6; ++y)
      for (int x = static_cast<int>(want.x()) - 6; x <= static_cast<int>(want.x()) + 6; ++x) {
        if (x < 0 || y < 0 || x >= shot.cols || y >= shot.rows) continue;
        const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // B, G, R
        if (p[2] > 200 && p[0] > 200 && p[1] < 90 && (Eigen::Vector2d(x, y) - want).norm() <= 6.0) {
          sum += Eigen::Vector2d(x, y);
          ++n;
        }
      }
    if (n == 0) continue;
    ++found;
    worst = std::max(worst, (sum / n - want).norm());
  }
  EXPECT_EQ(found, 48) << "corners drawn near the truth";
  EXPECT_LT(worst, 1.5) << "the farthest drawn corner from the truth, shrunk pixels";
}

}  // namespace
}  // namespace imucal
