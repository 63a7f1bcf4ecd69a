// SPDX-License-Identifier: BSD-3-Clause
// The camera modules load through the program's module loader and work across the boundary:
// libimucal_aravis.so streams Aravis's fake camera, libimucal_libcamera.so starts libcamera.

#include <gtest/gtest.h>
#include <poll.h>
#include <stdlib.h>

#include <algorithm>
#include <string>

#include "app/module_loader.hpp"
#include "core/version.hpp"
#include "drivers/camera/aravis/aravis_module.hpp"
#include "drivers/camera/libcamera/libcamera_module.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using drivers::camera::AravisModuleApi;
using drivers::camera::LibcameraModuleApi;

TEST(CameraModules, TheAravisModuleOpensAndStreamsTheFakeCamera) {
  test::ScopedModuleDir dir(IMUCAL_MODULE_BUILD_DIR);
  auto api =
      app::load_module<AravisModuleApi>(drivers::camera::kAravisModule, drivers::camera::kAravisModuleEntry);
  ASSERT_TRUE(api.ok()) << api.error().message;
  EXPECT_STREQ((*api)->header.version, kVersion);
  EXPECT_EQ((*api)->header.abi, kModuleAbi);
  const auto ids = (*api)->list(true);
  EXPECT_NE(std::find(ids.begin(), ids.end(), "Fake_1"), ids.end());

  drivers::camera::AravisOptions options;
  options.fake_interface = true;
  auto unknown = (*api)->open("NoSuchCamera-0000", options);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().code, Errc::kNotFound);

  auto cam = (*api)->open("Fake_1", options);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  drivers::camera::Camera& camera = **cam;
  EXPECT_STREQ(camera.backend(), "aravis");
  ASSERT_TRUE(camera.set_format({64, 48, "Mono8", 100.0}).ok());
  ASSERT_TRUE(camera.start().ok());
  drivers::camera::Frame frame;
  const TimeNs deadline = monotonic_now_ns() + 5 * kNsPerSecond;
  while (!frame.valid() && monotonic_now_ns() < deadline) {
    pollfd p{camera.fd(), POLLIN, 0};
    (void)::poll(&p, 1, 100);
    auto next = camera.dequeue();
    ASSERT_TRUE(next.ok()) << next.error().message;
    frame = std::move(*next);
  }
  ASSERT_TRUE(frame.valid()) << "no frame through the module within 5 s";
  EXPECT_EQ(frame.width, 64);
  EXPECT_EQ(frame.data.size(), 64u * 48u);
  frame.release();  // the module's release action requeues the buffer
  EXPECT_TRUE(camera.stop().ok());
  EXPECT_EQ(camera.counters().frames, 1u);
}

TEST(CameraModules, TheLibcameraModuleStartsLibcamera) {
  test::ScopedModuleDir dir(IMUCAL_MODULE_BUILD_DIR);
  auto api = app::load_module<LibcameraModuleApi>(drivers::camera::kLibcameraModule,
                                                  drivers::camera::kLibcameraModuleEntry);
  ASSERT_TRUE(api.ok()) << api.error().message;
  auto ids = (*api)->list();
  ASSERT_TRUE(ids.ok()) << ids.error().message;
  auto cam = (*api)->open("/base/no/such/camera@0", {});
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.error().code, Errc::kNotFound);
  if (ids->empty()) {
    EXPECT_NE(cam.error().message.find("no cameras found"), std::string::npos) << cam.error().message;
  }
}

}  // namespace
}  // namespace imucal
