// SPDX-License-Identifier: BSD-3-Clause
// The session log's messages against core/session_messages.hpp: every event of a log recorded by
// an earlier build decodes, and encodes back to the bytes the log holds.
#include <gtest/gtest.h>

#include <map>
#include <string>

#include "core/session_messages.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

TEST(SessionLogMessages, TheRecordedSessionsEventsDecodeAndEncodeToTheSameBytes) {
  auto reader = log::SessionLogReader::open(test::source_path("fixtures/service-session.imulog"));
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  auto events = (*reader)->events();
  ASSERT_TRUE(events.ok()) << events.error().message;
  std::map<std::string, int> kinds;
  for (const auto& e : *events) {
    if (e.kind == "frame") {
      auto frame = session_msg::parse_frame_event(e.message);
      ASSERT_TRUE(frame.ok()) << e.message << ": " << frame.error().message;
      EXPECT_EQ(session_msg::dump(*frame), e.message);
      continue;
    }
    if (e.kind != "session") continue;
    auto message = session_msg::parse(e.message);
    ASSERT_TRUE(message.ok()) << e.message << ": " << message.error().message;
    EXPECT_EQ(session_msg::dump(*message), e.message);
    ++kinds[session_msg::type_name(*message)];
  }
  // The session's whole course is there: inputs, solves, the result and the end.
  for (const char* kind : {"session", "status", "preflight", "prompt", "live", "message", "key", "pose",
                           "solve", "applied", "result", "review", "written", "done"}) {
    EXPECT_GT(kinds[kind], 0) << kind;
  }
}

}  // namespace
}  // namespace imucal
