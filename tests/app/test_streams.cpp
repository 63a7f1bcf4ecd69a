// SPDX-License-Identifier: BSD-3-Clause
// load_imu_stream: the damage policy, stream selection and the damage warning.

#include <gtest/gtest.h>

#include "app/streams.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::app {
namespace {

TEST(LoadImuStream, ReadsTheFirstStreamOfAHealthyLog) {
  auto loaded = load_imu_stream(test::source_path("fixtures/static.imulog"), "", DamagePolicy::kRefuse);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->info.name, "imu0");
  EXPECT_EQ(loaded->samples.size(), 18744u);
  EXPECT_FALSE(loaded->damaged());
  EXPECT_EQ(loaded->damage_warning(), "");
}

TEST(LoadImuStream, RefusesADamagedLogUnlessAllowed) {
  const std::string path = test::source_path("fixtures/broken-truncated.imulog");
  auto refusal = load_imu_stream(path, "", DamagePolicy::kRefuse);
  ASSERT_FALSE(refusal.ok());
  ASSERT_EQ(refusal.error().remedies.size(), 1u);
  EXPECT_EQ(refusal.error().remedies[0].option, "allow_damaged");
  EXPECT_EQ(refusal.error().code, Errc::kCorrupt);
  EXPECT_EQ(refusal.error().message.rfind(path + " is damaged (", 0), 0u) << refusal.error().message;
  // The library says what is wrong; the way out (a flag) is the caller's to add.
  EXPECT_EQ(refusal.error().message.find("--allow-damaged"), std::string::npos);

  auto allowed = load_imu_stream(path, "", DamagePolicy::kAllow);
  ASSERT_TRUE(allowed.ok()) << allowed.error().message;
  EXPECT_TRUE(allowed->damaged());
  EXPECT_EQ(allowed->samples.size(), 3631u);
  EXPECT_EQ(allowed->damage_warning().rfind("the log is damaged (the file is truncated", 0), 0u)
      << allowed->damage_warning();
}

TEST(LoadImuStream, ErrorsNameTheLog) {
  const std::string path = test::source_path("fixtures/static.imulog");
  auto missing_stream = load_imu_stream(path, "imu7", DamagePolicy::kRefuse);
  ASSERT_FALSE(missing_stream.ok());
  EXPECT_TRUE(missing_stream.error().remedies.empty());
  EXPECT_EQ(missing_stream.error().code, Errc::kNotFound);
  EXPECT_EQ(missing_stream.error().message.rfind("no IMU stream in " + path + ": ", 0), 0u);

  auto missing_log = load_imu_stream(test::scratch_dir() + "/none.imulog", "", DamagePolicy::kAllow);
  ASSERT_FALSE(missing_log.ok());
  EXPECT_EQ(missing_log.error().code, Errc::kNotFound);
  EXPECT_EQ(missing_log.error().message.rfind("cannot read ", 0), 0u);
}

}  // namespace
}  // namespace imucal::app
