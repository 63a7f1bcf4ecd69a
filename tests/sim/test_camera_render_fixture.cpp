// SPDX-License-Identifier: BSD-3-Clause
// The committed camera-IMU fixture (fixtures/camimu.imulog, `imucal sim camimu --seed 104`) was
// rendered by the checkerboard path of the renderer: re-rendering its first frames must give
// the stored pixels exactly. A change to the renderer that moves a single grey level of the
// checkerboard fails here, so the fixture and the figures measured on it stay valid.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <span>
#include <vector>

#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "sim/camera_render.hpp"
#include "sim/camimu.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::sim {
namespace {

// The fixture's command line and the salt of the camera noise stream in sim/camimu.cpp.
constexpr std::uint64_t kFixtureSeed = 104;
constexpr std::uint64_t kNoiseSubstream = 0xCA3E7A;
// The still start (40 frames) and the first 1.5 s of the ramp into the motion, where frames get
// motion-blurred sub-exposures; the noise stream runs through all of them in order.
constexpr int kFrames = 70;

Eigen::Isometry3d pose_of(const RigState& s) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = s.q_world_body.toRotationMatrix();
  T.translation() = s.p_world_body;
  return T;
}

TEST(CameraRenderFixture, CheckerboardFramesAreReproducedExactly) {
  const std::string path = test::source_path("fixtures/camimu.imulog");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "fixture " << path << " is missing";
  auto reader = log::SessionLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  auto cam_id = (*reader)->find_camera_stream("cam0");
  ASSERT_TRUE(cam_id.ok()) << cam_id.error().message;

  CamImuSimOptions o;  // the fixture uses the defaults
  o.seed = kFixtureSeed;
  auto motion = CheckerboardMotion::create(o.motion, o.seed);
  ASSERT_TRUE(motion.ok()) << motion.error().message;
  const Eigen::Isometry3d T_world_board = (*motion)->T_world_board(o.target);
  CameraRenderOptions render_opt;
  render_opt.noise_sigma_dn = o.noise_sigma_dn;
  render_opt.supersampling = o.supersampling;
  render_opt.optics_blur_sigma_px = o.optics_blur_sigma_px;
  auto renderer = CheckerboardRenderer::create(o.camera, o.target, render_opt);
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  auto T_cam_board_at = [&](TimeNs t_imu_ns) {
    return o.T_cam_imu * pose_of((*motion)->at(t_imu_ns)).inverse() * T_world_board;
  };

  Rng noise(Rng::substream(o.seed, kNoiseSubstream));
  const TimeNs shift_ns = s_to_ns(o.timeshift_cam_imu_s);
  int frames = 0, blurred = 0, differing = 0;
  std::vector<Eigen::Isometry3d> subs;
  auto visited = (*reader)->for_each_frame(*cam_id, log::kTimeMin, log::kTimeMax, [&](const CameraFrame& f) {
    const TimeNs t_open = f.t_ns + shift_ns - o.exposure_ns / 2;
    const int n_sub =
        (*renderer)->sub_exposures_needed(T_cam_board_at(t_open), T_cam_board_at(t_open + o.exposure_ns));
    subs.clear();
    for (int i = 0; i < n_sub; ++i) {
      const double s = (i + 0.5) / n_sub;
      subs.push_back(T_cam_board_at(t_open + static_cast<TimeNs>(std::llround(s * o.exposure_ns))));
    }
    blurred += n_sub > 1 ? 1 : 0;
    const cv::Mat image = (*renderer)->render(subs, &noise);
    // WebP stores grey as colour; the frames were grey, so the gray conversion gives them back.
    auto stored = log::decode_image(f.data, log::ReadMode::kGray8);
    EXPECT_TRUE(stored.ok()) << stored.error().message;
    if (!stored.ok()) return false;
    EXPECT_EQ(stored->width, image.cols);
    EXPECT_EQ(stored->height, image.rows);
    EXPECT_EQ(stored->channels, 1);
    int bad = 0, max_diff = 0;
    for (int r = 0; r < image.rows; ++r) {
      const std::uint8_t* a = image.ptr<std::uint8_t>(r);
      const std::uint8_t* b = stored->data.data() + static_cast<std::size_t>(r) * stored->row_bytes();
      for (int c = 0; c < image.cols; ++c) {
        bad += a[c] != b[c] ? 1 : 0;
        max_diff = std::max(max_diff, std::abs(int{a[c]} - int{b[c]}));
      }
    }
    EXPECT_EQ(bad, 0) << "frame " << frames << " (t " << f.t_ns << " ns) differs in " << bad
                      << " pixels, by up to " << max_diff << " grey levels";
    differing += bad > 0 ? 1 : 0;
    return ++frames < kFrames;
  });
  ASSERT_TRUE(visited.ok()) << visited.error().message;
  EXPECT_EQ(frames, kFrames);
  EXPECT_GE(blurred, 10) << "the compared frames should include motion-blurred ones";
  EXPECT_EQ(differing, 0);
}

}  // namespace
}  // namespace imucal::sim
