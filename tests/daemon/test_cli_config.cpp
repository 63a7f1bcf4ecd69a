// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "daemon/cli/command.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using ::testing::HasSubstr;

TEST(CliConfig, CheckPrintsNormalizedYamlThatChecksAgain) {
  auto r = test::run_cli({"config", "check", test::source_path("config/rig.yaml")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("name: sim"));
  EXPECT_THAT(r.out, HasSubstr("accel_range_g: 4"));
  EXPECT_THAT(r.out, HasSubstr("targetCols: 7"));  // the target file, inlined
  const std::string path = test::scratch_dir() + "/normalized.yaml";
  std::ofstream(path) << r.out;
  auto again = test::run_cli({"config", "check", path});
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(again.out, r.out);
}

TEST(CliConfig, CheckJson) {
  auto r = test::run_cli({"config", "check", "--json", test::source_path("config/rig-spi-example.yaml")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["imu"]["bus"], "spi");
  EXPECT_EQ(j["imu"]["spi_data_speed_hz"], 20000000);
  EXPECT_EQ(j["imu"]["data_ready"]["line"], 17);
  EXPECT_EQ(j["cameras"][0]["device"], "/dev/video0");
  EXPECT_EQ(j["storage"]["backend"], "nvmem");
}

TEST(CliConfig, InvalidConfigExitsWithInputErrorNamingKey) {
  const std::string path = test::scratch_dir() + "/bad.yaml";
  std::ofstream(path) << "name: x\nimu:\n  bus: spi\n  gyro_range_dps: 4000\n";
  auto r = test::run_cli({"config", "check", path});
  EXPECT_EQ(r.exit_code, cli::kExitInput);
  EXPECT_THAT(r.err, HasSubstr(path + ":4: imu.gyro_range_dps"));
  EXPECT_THAT(r.err, HasSubstr("250, 500, 1000, 2000"));
  EXPECT_TRUE(r.out.empty());
  auto missing = test::run_cli({"config", "check", path + ".nope"});
  EXPECT_EQ(missing.exit_code, cli::kExitInput);
  EXPECT_THAT(missing.err, HasSubstr("cannot open"));
}

}  // namespace
}  // namespace imucal
