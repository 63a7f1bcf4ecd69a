// SPDX-License-Identifier: BSD-3-Clause
// The libcamera backend without a camera (this machine has none): the camera manager starts,
// the list is reported, an unknown id is refused clearly. Streaming needs a sensor or a UVC
// camera and is not exercised here (docs/cameras.md).

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "drivers/camera/libcamera/libcamera_camera.hpp"

namespace imucal::drivers::camera {
namespace {

TEST(Libcamera, TheCameraManagerStartsAndListsTheCameras) {
  auto ids = list_libcamera_cameras();
  ASSERT_TRUE(ids.ok()) << ids.error().message;
  std::printf("libcamera cameras: %zu\n", ids->size());
  // A second call shares or restarts the one manager a process may have.
  auto again = list_libcamera_cameras();
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(*again, *ids);
}

TEST(Libcamera, AnUnknownIdIsNotFoundAndSaysWhatWasFound) {
  auto ids = list_libcamera_cameras();
  ASSERT_TRUE(ids.ok()) << ids.error().message;
  auto cam = open_libcamera_camera("/base/no/such/camera@0");
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.error().code, Errc::kNotFound);
  EXPECT_NE(cam.error().message.find("/base/no/such/camera@0"), std::string::npos) << cam.error().message;
  if (ids->empty()) {
    EXPECT_NE(cam.error().message.find("no cameras found"), std::string::npos) << cam.error().message;
  } else {
    EXPECT_NE(cam.error().message.find((*ids)[0]), std::string::npos) << cam.error().message;
  }
}

TEST(Libcamera, NegativeBufferCountsAreRefused) {
  LibcameraOptions options;
  options.buffers = -1;
  auto cam = open_libcamera_camera("any", options);
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.error().code, Errc::kInvalidArgument);
}

TEST(Libcamera, OpensTheFirstCameraWhenThereIsOne) {
  auto ids = list_libcamera_cameras();
  ASSERT_TRUE(ids.ok()) << ids.error().message;
  if (ids->empty()) GTEST_SKIP() << "libcamera finds no camera on this machine";
  auto cam = open_libcamera_camera((*ids)[0]);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  auto formats = (*cam)->formats();
  ASSERT_TRUE(formats.ok()) << formats.error().message;
  EXPECT_FALSE(formats->empty());
  EXPECT_STREQ((*cam)->backend(), "libcamera");
  EXPECT_EQ((*cam)->timestamp_meaning(), TimestampMeaning::kStartOfExposure);
}

}  // namespace
}  // namespace imucal::drivers::camera
