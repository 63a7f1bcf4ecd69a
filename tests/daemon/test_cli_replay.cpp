// SPDX-License-Identifier: BSD-3-Clause
// imucal replay on altered copies of the service-session fixture: the comparison with the live
// session's result covers every key of both, and what the log holds (its steps, its stamps) is
// judged as the log's content (exit 3), not as the command line (exit 2) or as a match (exit 0).

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using ::testing::HasSubstr;

std::string session_copy(const std::string& dir) { return test::copy_fixture("service-session.imulog", dir); }

// Before: an emptied result ("imu": {}, "cameras": []) compared equal (only the keys it holds
// were compared), exit 0.
TEST(CliReplay, AnEmptiedLiveResultDiffers) {
  const std::string dir = test::scratch_dir();
  const std::string log = session_copy(dir);
  ASSERT_TRUE(test::run_sql(log,
                            "update events set message=json_set(message,'$.imu',json('{}')) where "
                            "json_extract(message,'$.type')='result'"));
  auto r = test::run_cli({"replay", log, "-o", dir + "/replay"});
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_THAT(r.err, HasSubstr("the results differ"));
}

// Before: a step the engine does not know, written into the log's session start, exited 2 (a
// command-line error); and a done event stamped at INT64_MAX was replayed as the same session.
TEST(CliReplay, WhatTheLogHoldsIsJudgedAsTheLogs) {
  const std::string dir = test::scratch_dir();
  const std::string log = session_copy(dir);
  ASSERT_TRUE(test::run_sql(log,
                            "update events set message=json_set(message,'$.steps[1]','bogus') where "
                            "json_extract(message,'$.event')='start'"));
  auto r = test::run_cli({"replay", log, "-o", dir + "/replay"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_THAT(r.err, HasSubstr("bogus"));
  EXPECT_THAT(r.err, HasSubstr("cannot be replayed"));

  std::filesystem::create_directories(dir + "/late");
  const std::string late = test::copy_fixture("service-session.imulog", dir + "/late");
  ASSERT_TRUE(test::run_sql(late,
                            "update events set t_ns=9223372036854775807 where "
                            "json_extract(message,'$.type')='done'"));
  r = test::run_cli({"replay", late, "-o", dir + "/replay-late"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_THAT(r.err, HasSubstr("after the recording's last sample"));
}

// Before: a session killed before its end (no done event) was reported as "outcome written vs ".
TEST(CliReplay, ALiveSessionWithoutAnOutcomeIsNamed) {
  const std::string dir = test::scratch_dir();
  const std::string log = session_copy(dir);
  ASSERT_TRUE(test::run_sql(log, "delete from events where json_extract(message,'$.type')='done'"));
  auto r = test::run_cli({"replay", log, "-o", dir + "/replay"});
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_THAT(r.err, HasSubstr("none logged: the live session was killed or stopped before its end"));
}

}  // namespace
}  // namespace imucal
