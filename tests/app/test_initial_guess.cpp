// SPDX-License-Identifier: BSD-3-Clause
// nominal_guess: initial guesses from the stream description or given values.

#include <gtest/gtest.h>

#include "app/initial_guess.hpp"

namespace imucal::app {
namespace {

ImuStreamInfo raw_stream(int accel_fs_g, int gyro_fs_dps) {
  ImuStreamInfo info;
  info.units = ImuUnits::kRaw;
  info.accel_full_scale_g = accel_fs_g;
  info.gyro_full_scale_dps = gyro_fs_dps;
  return info;
}

TEST(NominalGuess, SiStreamUsesItsConversion) {
  auto g = nominal_guess(ImuStreamInfo{}, {});
  ASSERT_TRUE(g.ok());
  ASSERT_TRUE(g->accel.has_value());
  EXPECT_TRUE(g->accel->scale.isOnes());
  EXPECT_TRUE(g->gyro.scale.isOnes());
}

TEST(NominalGuess, RawStreamWithFullScaleUsesItsNominalConversion) {
  ImuStreamInfo info = raw_stream(2, 250);
  info.accel.scale = Eigen::Vector3d::Constant(9.80665 / 16384);
  info.gyro.scale = Eigen::Vector3d::Constant(1.3323e-4);
  auto g = nominal_guess(info, {});
  ASSERT_TRUE(g.ok());
  EXPECT_DOUBLE_EQ(g->accel->scale[0], 9.80665 / 16384);
  EXPECT_DOUBLE_EQ(g->gyro.scale[2], 1.3323e-4);
}

TEST(NominalGuess, RawAccelWithoutScaleIsLeftToTheEllipsoidFit) {
  NominalOverrides given;
  given.gyro_scale = Eigen::Vector3d::Constant(1e-4);
  auto g = nominal_guess(raw_stream(0, 0), given);
  ASSERT_TRUE(g.ok());
  EXPECT_FALSE(g->accel.has_value());
  EXPECT_DOUBLE_EQ(g->gyro.scale[1], 1e-4);
}

TEST(NominalGuess, RefusesARawGyroWithoutScale) {
  auto g = nominal_guess(raw_stream(2, 0), {});
  ASSERT_FALSE(g.ok());
  EXPECT_EQ(g.error().code, Errc::kInvalidArgument);
  EXPECT_NE(g.error().message.find("raw counts"), std::string::npos);
  EXPECT_EQ(g.error().message.find("--"), std::string::npos) << "no CLI flags in library messages";
}

TEST(NominalGuess, GivenValuesReplaceTheNominalOnes) {
  ImuStreamInfo info = raw_stream(2, 250);
  info.accel.offset = Eigen::Vector3d(1, 2, 3);
  NominalOverrides given;
  given.accel_scale = Eigen::Vector3d(1e-3, 2e-3, 3e-3);
  auto g = nominal_guess(info, given);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->accel->scale, Eigen::Vector3d(1e-3, 2e-3, 3e-3));
  EXPECT_EQ(g->accel->offset, Eigen::Vector3d(1, 2, 3));  // not given: kept
}

TEST(ChooseGravity, GivenThenLatitudeThenStandard) {
  const GravityChoice given = choose_gravity(9.81, 45.0, 0.0);
  EXPECT_EQ(given.mps2, 9.81);
  EXPECT_EQ(given.source, "given");
  EXPECT_FALSE(given.standard_assumed);
  const GravityChoice wgs = choose_gravity(std::nullopt, 45.0, 100.0);
  EXPECT_NEAR(wgs.mps2, 9.8059, 1e-3);  // normal gravity at 45 deg, less 0.3 mGal/m
  EXPECT_EQ(wgs.source.rfind("WGS-84 normal gravity at latitude 45", 0), 0u) << wgs.source;
  const GravityChoice standard = choose_gravity(std::nullopt, std::nullopt, 0.0);
  EXPECT_EQ(standard.mps2, kStandardGravity);
  EXPECT_EQ(standard.source, "standard gravity");
  EXPECT_TRUE(standard.standard_assumed);
}

}  // namespace
}  // namespace imucal::app
