// SPDX-License-Identifier: BSD-3-Clause
// Detections read back from a log or the detection cache are a file's content: a point id the
// target does not have is never used to index its points. The set is not trusted, the frames are
// searched again, and a warning says why.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <string>

#include "app/results/camera_results.hpp"
#include "calib/target_detection.hpp"
#include "log/session_log.hpp"
#include "log/target_detections.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;
using test::scratch_dir;

// Before: the stored set was taken as it was, and its id 4000000 reached the solvers
// (`calibrate camera` refused with "an observation holds point id 4000000", exit 2;
// `calibrate camimu` indexed the target's points with it: SIGSEGV).
TEST(CliStoredDetections, AnIdTheTargetDoesNotHaveMakesTheFramesBeSearchedAgain) {
  const std::string dir = scratch_dir();
  const std::string log = test::copy_fixture("camimu.imulog", dir);
  auto reader = log::SessionLogReader::open(log);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  auto stream = (*reader)->find_camera_stream();
  ASSERT_TRUE(stream.ok());
  auto frames = (*reader)->frame_count(*stream);
  ASSERT_TRUE(frames.ok());
  auto target = app::target_from_log_metadata((*reader)->metadata());
  ASSERT_TRUE(target.ok()) << target.error().message;
  const int points = target->target.point_count();
  reader->reset();

  log::DetectionSet set;
  set.target_key = app::detection_key(target->target, calib::DetectionOptions{});
  set.frames = *frames;
  calib::TargetObservation o;
  o.t_ns = 1'000'000'000;
  o.width = 640;
  o.height = 480;
  for (int id = 0; id < 6; ++id) {
    o.ids.push_back(id);
    o.px.emplace_back(100.0 + 10 * id, 100.0);
  }
  o.ids.push_back(4'000'000);
  o.px.emplace_back(200.0, 200.0);
  set.detections.push_back({o.t_ns, app::encode_detection(o)});
  ASSERT_TRUE(log::write_target_detections(log, *stream, set).ok());

  auto r = run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", dir + "/cam.yaml", "--no-cache"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string expected =
      "stored detections not used (the frames are searched again): the detection at "
      "t_ns 1000000000 holds point id 4000000, outside the target's " +
      std::to_string(points) + " points";
  EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
  const YAML::Node q = YAML::LoadFile(dir + "/cam.yaml")["cam0"]["imucal"];
  EXPECT_GE(q["views_used"].as<int>(), 100);
}

}  // namespace
}  // namespace imucal
