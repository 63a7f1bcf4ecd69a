// SPDX-License-Identifier: BSD-3-Clause
// The operator console's model, renderer and keys, as text: no terminal needed.
#include <gtest/gtest.h>

#include <algorithm>
#include <tuple>
#include <utility>
#include <vector>

#include "daemon/ctl/console.hpp"

namespace imucal::ctl {
namespace {

using nlohmann::json;

json status_message(const std::string& state = "running", const std::string& step = "poses") {
  return {{"type", "status"},
          {"state", state},
          {"rig", "sim"},
          {"step", step},
          {"steps",
           {{{"name", "preflight"}, {"state", "done"}},
            {{"name", "poses"}, {"state", step == "poses" ? "active" : "done"}},
            {{"name", "solve"}, {"state", step == "solve" ? "active" : "pending"}},
            {{"name", "write"}, {"state", "skipped"}}}},
          {"elapsed_s", 12.34}};
}

/// A status as imucald sends it, with its devices, session folder and what it has recorded.
json service_status() {
  json m = status_message();
  m["devices"] = {
      {"imu",
       {{"state", "open"},
        {"sim", false},
        {"samples", 1200},
        {"faults", 1},
        {"rate_hz", 500.0},
        {"gyro_offsets", "stored bias"},
        {"error", ""}}},
      {"storage", "nvmem /sys/bus/nvmem/devices/1-00500/nvmem"},
      {"cameras", {{{"name", "cam0"}, {"state", "closed"}, {"frames", 0}, {"faults", 0}, {"error", ""}}}}};
  m["session_dir"] = "/var/lib/imucal/sessions/a";
  m["version"] = "0.1.0";
  m["recorded_bytes"] = 48'312'345;
  return m;
}

const json kPrompt{{"type", "prompt"},
                   {"step", "poses"},
                   {"text", "Turn the rig to a new orientation and hold it still"},
                   {"keys", {"continue", "redo", "abort"}}};
const json kLive{{"type", "live"},
                 {"step", "poses"},
                 {"lines", {"Still: yes  2.1 of 3.0 s", "Poses: 7 of 12"}},
                 {"progress", 0.5}};

std::string screen_after(const std::vector<json>& messages, ConsoleState state = {}) {
  for (const auto& message : messages) {
    update(state, message);
  }
  return render(state, {80});
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(Console, RendersHeaderStepsPromptLiveAndKeys) {
  const std::string screen = screen_after({status_message(), kPrompt, kLive});
  EXPECT_TRUE(has(screen, "imucal  rig sim  |  running  |  step 2 of 4: poses  |  12 s")) << screen;
  EXPECT_TRUE(has(screen, " [x] preflight\n [>] poses\n [ ] solve\n [-] write\n")) << screen;
  EXPECT_TRUE(has(screen, ">> Turn the rig to a new orientation and hold it still")) << screen;
  EXPECT_TRUE(has(screen, "   Still: yes  2.1 of 3.0 s\n   Poses: 7 of 12\n")) << screen;
  EXPECT_TRUE(has(screen, "####----") && has(screen, " 50%")) << screen;
  EXPECT_TRUE(has(screen, "c continue  r redo  a abort  R restart  q detach")) << screen;
  for (std::size_t start = 0, end; (end = screen.find('\n', start)) != std::string::npos; start = end + 1) {
    EXPECT_LE(end - start, 80u) << "every line fits the width";
  }
}

// The screen's lines: separated by '\n', the last one without.
std::vector<std::string> lines_of(const std::string& screen) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  for (std::size_t end; (end = screen.find('\n', start)) != std::string::npos; start = end + 1) {
    lines.push_back(screen.substr(start, end - start));
  }
  if (start < screen.size()) lines.push_back(screen.substr(start));
  return lines;
}

TEST(Console, LongLinesWrapInsteadOfBeingCut) {
  ConsoleState state;
  update(state, status_message());
  update(state, {{"type", "message"}, {"level", "info"}, {"text", std::string(70, 'x')}});
  update(
      state,
      {{"type", "prompt"},
       {"step", "poses"},
       {"text", "imu fault: no data-ready edge for 2 s. Press r to redo the step once fixed, or a to abort"},
       {"keys", {"redo", "abort"}}});
  const std::string screen = render(state, {30});
  for (const auto& line : lines_of(screen)) {
    EXPECT_LE(line.size(), 30u) << screen;
  }
  // Nothing is lost: every x of the message and every word of the prompt is on the screen.
  std::string joined = screen;
  joined.erase(std::remove_if(joined.begin(), joined.end(), [](char c) { return c == ' ' || c == '\n'; }),
               joined.end());
  EXPECT_TRUE(has(joined, "info:" + std::string(70, 'x') + "-")) << screen;
  EXPECT_TRUE(has(joined, "Pressrtoredothesteponcefixed,orato" + std::string("abort"))) << screen;
}

// A screen as full as a session's: nine steps, a prompt with a drawing, live figures, messages.
ConsoleState busy_console() {
  ConsoleState state;
  json steps = json::array();
  for (const char* name :
       {"preflight", "warmup", "still", "poses", "gsens", "motion", "solve", "review", "write"}) {
    steps.push_back({{"name", name}, {"state", std::string(name) == "poses" ? "active" : "pending"}});
  }
  update(state, {{"type", "status"},
                 {"state", "running"},
                 {"rig", "bench-rig-07"},
                 {"step", "poses"},
                 {"steps", steps},
                 {"elapsed_s", 100.0},
                 {"t", 500.0}});
  std::vector<std::string> art;
  for (int i = 0; i < 8; ++i) art.push_back("drawing line " + std::to_string(i));
  update(state, {{"type", "prompt"},
                 {"step", "poses"},
                 {"t", 501.0},
                 {"text",
                  "Turn the rig to a new orientation and hold it still (2.0 s); 18 poses, all directions. "
                  "Next: put the rig on its right side, left side up"},
                 {"keys", {"continue", "redo", "abort"}},
                 {"art", art}});
  for (int i = 0; i < 5; ++i) {
    update(state, {{"type", "message"},
                   {"level", "info"},
                   {"t", 502.0 + i},
                   {"text", "Pose " + std::to_string(i + 1) +
                                " captured; not yet up: right side up, bottom side up"}});
  }
  update(state, {{"type", "live"},
                 {"step", "poses"},
                 {"t", 512.0},
                 {"lines",
                  {"Still: 1.2 of 2.0 s", "Poses: 5 of 18; not yet up: right side up, bottom side up",
                   "Scale sigma: after 9 poses"}},
                 {"progress", 0.28}});
  return state;
}

TEST(Console, At80x24TheHeaderAndKeysStayAndNothingIsCut) {
  const ConsoleState state = busy_console();
  const auto lines = lines_of(render(state, {80, 24}));
  ASSERT_LE(lines.size(), 24u);
  EXPECT_EQ(lines.front().rfind("imucal  rig bench-rig-07  |  running  |  step 4 of 9: poses", 0), 0u)
      << lines.front();
  EXPECT_EQ(lines.back(), "c continue  r redo  a abort  R restart  q detach");
  for (const auto& line : lines) EXPECT_LE(line.size(), 80u) << line;
  const std::string screen = render(state, {80, 24});
  // The step list folds onto one line; the prompt, live figures and the last message stay.
  EXPECT_TRUE(has(screen, " [ ] preflight  [ ] warmup  [ ] still  [>] poses")) << screen;
  EXPECT_TRUE(has(screen, "left side up")) << screen;
  EXPECT_TRUE(has(screen, "Poses: 5 of 18")) << screen;
  EXPECT_TRUE(has(screen, "Pose 5 captured")) << screen;
  EXPECT_FALSE(has(screen, "more than fits")) << screen;
}

TEST(Console, AReviewTallerThanTheTerminalScrollsAndHidesNothing) {
  ConsoleState state;
  update(state, status_message("review", "solve"));
  json lines = json::array();
  for (int i = 1; i <= 40; ++i) lines.push_back("review line " + std::to_string(i));
  update(state, {{"type", "review"},
                 {"pass", true},
                 {"gates", {{{"name", "gravity residual"}, {"value", 1.2}, {"limit", 2.0}, {"pass", true}}}},
                 {"lines", lines}});
  update(state, {{"type", "prompt"},
                 {"step", "review"},
                 {"text", "Press y to accept"},
                 {"keys", {"accept", "reject"}}});
  const auto seen = [&] {
    std::vector<int> out;
    for (const auto& line : lines_of(render(state, {80, 24}))) {
      if (line.rfind("  review line ", 0) == 0) out.push_back(std::stoi(line.substr(14)));
    }
    return out;
  };
  auto first = lines_of(render(state, {80, 24}));
  ASSERT_LE(first.size(), 24u);
  EXPECT_EQ(first.front().rfind("imucal  rig sim  |  review", 0), 0u) << first.front();
  EXPECT_EQ(first.back(), "y accept  n reject  R restart  q detach");
  const std::string screen = render(state, {80, 24});
  EXPECT_FALSE(has(screen, "more than fits")) << screen;
  EXPECT_TRUE(has(screen, "  pass gravity residual")) << screen;
  EXPECT_TRUE(has(screen, "of 41; d: more --")) << screen;
  // d and u move the window; every line is seen on the way down, and u goes back.
  std::vector<bool> shown(41, false);
  std::vector<int> window = seen();
  ASSERT_FALSE(window.empty());
  EXPECT_EQ(window.front(), 1);
  for (int press = 0; press < 10; ++press) {
    for (int n : seen()) shown[static_cast<std::size_t>(n)] = true;
    EXPECT_FALSE(on_key(state, 'd').request.has_value());  // the console's own: nothing is sent
  }
  for (int i = 1; i <= 40; ++i) EXPECT_TRUE(shown[static_cast<std::size_t>(i)]) << "review line " << i;
  EXPECT_EQ(seen().back(), 40);
  EXPECT_TRUE(has(render(state, {80, 24}), "; u: back --"));
  for (int press = 0; press < 10; ++press) on_key(state, 'u');
  EXPECT_EQ(seen().front(), 1);
  // A terminal tall enough shows it all, without the window.
  EXPECT_FALSE(has(render(state, {80, 70}), "review rows"));
  EXPECT_FALSE(state.confirm.has_value());  // scrolling asks nothing
}

TEST(Console, At160x48EverythingShowsWithTheDrawing) {
  const std::string screen = render(busy_console(), {160, 48});
  EXPECT_LE(lines_of(screen).size(), 48u);
  EXPECT_TRUE(has(screen, " [ ] preflight\n [ ] warmup\n")) << screen;
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(has(screen, "drawing line " + std::to_string(i))) << screen;
  for (int i = 1; i <= 5; ++i) EXPECT_TRUE(has(screen, "Pose " + std::to_string(i) + " captured")) << screen;
}

TEST(Console, ElapsedTimeRunsOnBetweenStatusMessages) {
  ConsoleState state = busy_console();  // status at t = 500 s with 100 s elapsed; live at 512 s
  EXPECT_TRUE(has(render(state), "|  112 s")) << render(state);
  // No message for 3 s of wall time: the clock still moves.
  EXPECT_TRUE(has(render(state, {80, 0, 3.0}), "|  115 s")) << render(state, {80, 0, 3.0});
  // A finished session's time stands.
  update(
      state,
      {{"type", "status"}, {"state", "done"}, {"rig", "bench-rig-07"}, {"elapsed_s", 130.0}, {"t", 530.0}});
  EXPECT_TRUE(has(render(state, {80, 0, 60.0}), "|  130 s")) << render(state, {80, 0, 60.0});
}

TEST(Console, FaultsAndMessagesKeepTheLastFew) {
  ConsoleState state;
  state.max_recent = 3;
  for (int i = 0; i < 5; ++i) {
    update(state, {{"type", "message"}, {"level", "info"}, {"text", "note " + std::to_string(i)}});
  }
  update(
      state,
      {{"type", "fault"}, {"step", "poses"}, {"text", "IMU lost: no data-ready"}, {"advice", "Reconnect"}});
  const std::string screen = render(state);
  EXPECT_FALSE(has(screen, "note 2"));
  EXPECT_TRUE(
      has(screen, "info: note 3\n info: note 4\n FAULT [poses]: IMU lost: no data-ready -- Reconnect"))
      << screen;
}

TEST(Console, ReviewShowsGatesAndAcceptKeys) {
  const json review{{"type", "review"},
                    {"pass", false},
                    {"gates",
                     {{{"name", "gravity residual"}, {"value", 1.2}, {"limit", 2.0}, {"pass", true}},
                      {{"name", "pose coverage"}, {"value", 0.4}, {"limit", 0.6}, {"pass", false}}}},
                    {"lines", {"12 poses used"}}};
  const json prompt{
      {"type", "prompt"}, {"step", "review"}, {"text", "Accept?"}, {"keys", {"accept", "reject"}}};
  const std::string screen = screen_after({status_message("review", "solve"), review, prompt});
  EXPECT_TRUE(has(screen,
                  "Review: FAIL\n  pass gravity residual  1.200  (limit 2.000)\n"
                  "  FAIL pose coverage  0.400  (limit 0.600)\n  12 poses used"))
      << screen;
  EXPECT_TRUE(has(screen, "y accept  n reject  R restart  q detach")) << screen;
}

TEST(Console, GateFiguresKeepTheDecimalsTheServiceChose) {
  const json review{
      {"type", "review"},
      {"pass", true},
      {"gates",
       {{{"name", "largest scale sigma (relative, e-3)"},
         {"value", 0.3049},
         {"limit", 3.0},
         {"pass", true},
         {"digits", 2}},
        {{"name", "distinct attitudes"}, {"value", 20.0}, {"limit", 9.0}, {"pass", true}, {"digits", 0}},
        {{"name", "cam0 reprojection RMS (px)"}, {"value", nullptr}, {"limit", 1.0}, {"pass", false}}}},
      {"lines", json::array()}};
  const std::string screen = screen_after({status_message("review", "solve"), review});
  EXPECT_TRUE(has(screen, "  pass largest scale sigma (relative, e-3)  0.30  (limit 3.00)\n")) << screen;
  EXPECT_TRUE(has(screen, "  pass distinct attitudes  20  (limit 9)\n")) << screen;
  EXPECT_FALSE(has(screen, "20.000")) << screen;
  EXPECT_TRUE(has(screen, "  FAIL cam0 reprojection RMS (px)  not determined  (limit 1.000)")) << screen;
}

TEST(Console, LiveFiguresOfAnotherStepAndDoneClearTheScreen) {
  ConsoleState state;
  update(state, status_message());
  update(state, kPrompt);
  update(state, kLive);
  update(state, status_message("running", "solve"));
  EXPECT_FALSE(has(render(state), "Poses: 7 of 12"));
  update(state, {{"type", "done"},
                 {"outcome", "written"},
                 {"text", "calibration written to slot B"},
                 {"stored", "slot B, sequence 4, file /var/lib/imucal/calibration.bin"},
                 {"session_dir", "/var/lib/imucal/sessions/rig-20261128T060000Z"}});
  const std::string screen = render(state);
  EXPECT_FALSE(has(screen, ">> Turn the rig"));
  EXPECT_TRUE(has(screen,
                  "Session written: calibration written to slot B\n"
                  "Stored on: slot B, sequence 4, file /var/lib/imucal/calibration.bin\n"
                  "Session folder: /var/lib/imucal/sessions/rig-20261128T060000Z"))
      << screen;
}

TEST(Console, RefusalsAreShownAndMalformedMessagesIgnored) {
  ConsoleState state;
  update(state, {{"type", "reply"}, {"cmd", "key"}, {"ok", false}, {"error", "no step to redo"}});
  EXPECT_TRUE(has(render(state), "! key refused: no step to redo"));
  update(state, {{"type", "reply"}, {"cmd", "key"}, {"ok", true}});
  EXPECT_FALSE(has(render(state), "refused"));
  update(state, kLive);
  // Wrong types, unknown types, non-objects: no throw, nothing shown (a message that does not
  // decode is ignored whole: the live figures in force stay).
  for (const json& junk :
       {json(nullptr), json(5), json::array({1}), json{{"type", 7}}, json{{"type", "weather"}},
        json{{"type", "status"}, {"steps", "many"}, {"elapsed_s", "x"}},
        json{{"type", "live"}, {"lines", {1, "ok line"}}, {"progress", "half"}},
        json{{"type", "review"}, {"pass", "yes"}, {"gates", {{{"pass", 1}}}}}}) {
    EXPECT_NO_THROW(update(state, junk)) << junk;
    EXPECT_NO_THROW((void)render(state)) << junk;
    EXPECT_NO_THROW((void)plain_line(junk)) << junk;
  }
  EXPECT_FALSE(has(render(state), "ok line"));
  EXPECT_TRUE(has(render(state), "Poses: 7 of 12"));
}

// Before: any socket client could name itself "\x1b]0;...\x07\x1b[2J..." and the console of
// the operator showed it as it was ("another controller is attached (NAME)"): the pane retitled,
// the screen cleared, a blinking fake message drawn.
TEST(Console, TextFromTheServiceReachesTheTerminalWithoutControlCharacters) {
  const std::string hostile =
      "\x1b]0;pwned\x07\x1b[2J\x1b[5mcalibration written OK, unplug the rig\x1b[0m \xc2\x9b"
      "2J \x9b\x07";
  ConsoleState state;
  update(state, status_message());
  update(state, {{"type", "prompt"}, {"step", "poses"}, {"text", hostile}, {"keys", {"continue"}}});
  update(state, {{"type", "reply"},
                 {"cmd", "hello"},
                 {"ok", false},
                 {"error", "another controller (" + hostile + ")"}});
  const json reply{{"type", "reply"}, {"cmd", "start"}, {"ok", false}, {"error", hostile}};
  for (const std::string& text :
       {render(state), *plain_line(reply), status_text(status_message()) + render(state)}) {
    for (const char c : text) {
      const auto byte = static_cast<unsigned char>(c);
      EXPECT_FALSE(byte < 0x20 && c != '\n') << "control byte " << int(byte) << " in:\n" << text;
      EXPECT_NE(byte, 0x7F);
    }
    EXPECT_EQ(text.find("\xc2\x9b"), std::string::npos) << "C1 CSI (U+009B) in:\n" << text;
    EXPECT_EQ(text.find('\x9b'), std::string::npos) << "a lone 0x9B byte in:\n" << text;
  }
  EXPECT_TRUE(has(render(state), "calibration written OK")) << "the printable text stays";
}

// A session's end screen with long session folder and report paths.
ConsoleState end_console() {
  ConsoleState state = busy_console();
  update(state, {{"type", "done"},
                 {"outcome", "written"},
                 {"text", "The calibration was written, read back and verified."},
                 {"stored", "slot B, sequence 4, file /var/lib/imucal/calibration.bin"},
                 {"session_dir", "/var/lib/imucal/sessions/bench-rig-07-20261128T060000Z"},
                 {"reports",
                  {"/var/lib/imucal/sessions/bench-rig-07-20261128T060000Z/report.html",
                   "/var/lib/imucal/sessions/bench-rig-07-20261128T060000Z/camimu-report.html"}}});
  update(state, {{"type", "status"}, {"state", "done"}, {"rig", "bench-rig-07"}, {"elapsed_s", 300.0}});
  return state;
}

// Every line ended in '\n', the last one too: on a full 80x24 terminal the screen scrolled by one
// and the header went; on the end screen the folder and report paths were the lines cut.
TEST(Console, AFullScreenHasNoNewlineAfterItsLastLineSoTheTerminalDoesNotScroll) {
  for (const auto& [width, height] : std::vector<std::pair<int, int>>{{80, 24}, {160, 48}}) {
    for (const ConsoleState& state : {busy_console(), end_console()}) {
      const std::string screen = render(state, {width, height});
      ASSERT_FALSE(screen.empty());
      EXPECT_NE(screen.back(), '\n') << width << "x" << height << ":\n" << screen;
      // At most height - 1 newlines: the cursor stays on the last row.
      EXPECT_LT(std::count(screen.begin(), screen.end(), '\n'), height) << screen;
      EXPECT_EQ(screen.rfind("imucal  rig bench-rig-07", 0), 0u) << screen;
    }
    const std::string end = render(end_console(), {width, height});
    const std::string folder = "/var/lib/imucal/sessions/bench-rig-07-20261128T060000Z";
    std::string joined = end;  // a path longer than the width wraps: join its pieces
    joined.erase(std::remove_if(joined.begin(), joined.end(), [](char c) { return c == ' ' || c == '\n'; }),
                 joined.end());
    EXPECT_TRUE(has(joined, "Sessionfolder:" + folder)) << end;
    EXPECT_TRUE(has(joined, "Report:" + folder + "/report.html")) << end;
    EXPECT_TRUE(has(joined, "Report:" + folder + "/camimu-report.html")) << end;
  }
}

std::string key_of(ConsoleState& state, char c) {
  auto action = on_key(state, c);
  return action.request ? (*action.request).value("key", (*action.request)["cmd"].get<std::string>()) : "";
}

TEST(Console, KeysMapToRequestsAndDestructiveOnesAskFirst) {
  ConsoleState state;
  update(state, status_message());
  EXPECT_EQ(key_of(state, 'c'), "continue");  // no live figures: nothing would be cut short
  EXPECT_EQ(key_of(state, ' '), "continue");
  EXPECT_EQ(key_of(state, '\r'), "continue");
  EXPECT_EQ(key_of(state, 'r'), "redo");
  EXPECT_EQ(key_of(state, 'y'), "accept");
  EXPECT_EQ(key_of(state, 'x'), "");
  // Abort, reject and skip ask; y sends, anything else cancels.
  for (const auto& [key, question, sent] :
       std::vector<std::tuple<char, std::string, std::string>>{{'a', "Abort the session?", "abort"},
                                                               {'n', "Reject this calibration?", "reject"},
                                                               {'s', "Skip the poses step?", "skip"}}) {
    EXPECT_EQ(key_of(state, key), "") << key;
    ASSERT_TRUE(state.confirm.has_value()) << key;
    EXPECT_TRUE(has(render(state), question + " ")) << render(state);
    EXPECT_TRUE(has(render(state), "y: yes")) << render(state);
    EXPECT_EQ(key_of(state, 'n'), "") << "n answers no, it is not sent as reject";
    EXPECT_FALSE(state.confirm.has_value());
    EXPECT_TRUE(has(render(state), "Not done: " + question)) << render(state);
    EXPECT_EQ(key_of(state, key), "");
    EXPECT_EQ(key_of(state, 'y'), sent);
  }
  EXPECT_TRUE(on_key(state, 'q').detach);
  EXPECT_TRUE(on_key(state, 3).detach);  // Ctrl-C as a byte
}

TEST(Console, EndingAStepBeforeItsTimeAsksFirst) {
  ConsoleState state;
  update(state, status_message("running", "motion"));
  update(state, {{"type", "prompt"},
                 {"step", "motion"},
                 {"text", "Move the rig"},
                 {"keys", {"continue", "skip", "abort"}}});
  update(state, {{"type", "live"}, {"step", "motion"}, {"lines", {"18 of 60 s"}}, {"progress", 0.3}});
  EXPECT_EQ(key_of(state, 'c'), "");
  EXPECT_TRUE(has(render(state), "End the motion step now, at 30 %?")) << render(state);
  EXPECT_EQ(key_of(state, 'n'), "");  // no
  EXPECT_EQ(key_of(state, 'c'), "");
  EXPECT_EQ(key_of(state, 'y'), "continue");
  // Once the step's time is up, continue goes at once.
  update(state, {{"type", "live"}, {"step", "motion"}, {"lines", {"60 of 60 s"}}, {"progress", 1.0}});
  EXPECT_EQ(key_of(state, 'c'), "continue");
}

// `c` then `a` only cancelled: the question swallowed the key that was meant as a key.
TEST(Console, AQuestionTakesOneKeyAndAnotherKeyStillActs) {
  ConsoleState state;
  update(state, status_message("running", "motion"));
  update(state, {{"type", "live"}, {"step", "motion"}, {"lines", {"18 of 60 s"}}, {"progress", 0.3}});
  EXPECT_EQ(key_of(state, 'c'), "");
  ASSERT_TRUE(state.confirm.has_value());
  EXPECT_EQ(key_of(state, 'a'), "");  // declines the first question and asks the abort's
  ASSERT_TRUE(state.confirm.has_value());
  EXPECT_TRUE(has(render(state), "Abort the session?")) << render(state);
  EXPECT_EQ(key_of(state, 'y'), "abort");
  EXPECT_FALSE(state.confirm.has_value());
  EXPECT_EQ(key_of(state, 'r'), "redo");  // the next key is its own
  // n and Esc only answer.
  EXPECT_EQ(key_of(state, 's'), "");
  EXPECT_EQ(key_of(state, 27), "");
  EXPECT_FALSE(state.confirm.has_value());
  EXPECT_TRUE(has(render(state), "Not done: Skip the motion step?")) << render(state);
  EXPECT_EQ(key_of(state, 'r'), "redo");
}

// A declined "Not done" stayed on the screen through the later steps.
TEST(Console, AStepChangeClearsTheQuestionAndTheNotDoneNotice) {
  ConsoleState state;
  update(state, status_message("running", "poses"));
  EXPECT_EQ(key_of(state, 's'), "");
  EXPECT_EQ(key_of(state, 'n'), "");
  EXPECT_TRUE(has(render(state), "Not done: Skip the poses step?")) << render(state);
  update(state, status_message("running", "poses"));  // the same step: it still applies
  EXPECT_TRUE(has(render(state), "Not done: Skip the poses step?")) << render(state);
  update(state, status_message("running", "solve"));
  EXPECT_FALSE(has(render(state), "Not done")) << render(state);
  // A question still open when its step ends goes too: `y` must not skip the next step.
  EXPECT_EQ(key_of(state, 's'), "");
  ASSERT_TRUE(state.confirm.has_value());
  update(state, status_message("running", "poses"));
  EXPECT_FALSE(state.confirm.has_value());
  EXPECT_FALSE(has(render(state), "Skip the solve step?")) << render(state);
  EXPECT_EQ(key_of(state, 'y'), "accept");
}

TEST(Console, AServiceThatIsGoneLeavesTheLastScreenMarkedWithWhatToDo) {
  ConsoleState state;
  update(state, status_message("running", "poses"));
  update(state, kPrompt);
  EXPECT_EQ(key_of(state, 'a'), "");  // a question open when the service goes
  ASSERT_TRUE(state.confirm.has_value());
  service_lost(state, "imucald closed the connection");
  const std::string screen = render(state, {80, 24});
  EXPECT_FALSE(state.confirm.has_value());
  EXPECT_TRUE(has(screen, "imucald is gone")) << screen;
  EXPECT_FALSE(has(screen, "|  running")) << screen;  // the header no longer claims a live session
  EXPECT_TRUE(has(screen, "Turn the rig to a new orientation")) << screen;  // the last state stays
  // The notice, whole (the screen wraps it at 80 columns).
  EXPECT_TRUE(has(screen, "! imucald closed the connection: imucald stopped")) << screen;
  EXPECT_TRUE(has(state.notice, "session it was running ended with it")) << state.notice;
  EXPECT_TRUE(has(state.notice, "journalctl -u imucald")) << state.notice;
  EXPECT_FALSE(has(screen, "c continue")) << screen;  // no key is offered
  EXPECT_TRUE(has(screen, "run it again once imucald is back")) << screen;
  // Idle when it went: nothing about a session.
  ConsoleState idle;
  update(idle, status_message("idle", ""));
  service_lost(idle, "imucald closed the connection");
  EXPECT_FALSE(has(render(idle), "session it was running")) << render(idle);
}

TEST(Console, EndingThePosesStepIsNotOfferedBeforeTheServiceWouldAcceptIt) {
  ConsoleState state;
  update(state, status_message("running", "poses"));
  update(state, kPrompt);
  json live = kLive;
  live["figures"] = {{"poses", 7},
                     {"still", false},
                     {"missing", json::array()},
                     {"scale_sigma", 0.002},
                     {"poses_needed", 12}};
  update(state, live);
  EXPECT_EQ(key_of(state, 'c'), "");  // nothing sent, no question asked
  EXPECT_FALSE(state.confirm.has_value());
  EXPECT_TRUE(has(render(state), "Not yet: the poses step ends with at least 12 poses (7 so far)"))
      << render(state);
  live["figures"]["poses"] = 12;
  update(state, live);
  EXPECT_FALSE(has(render(state), "Not yet")) << render(state);  // no longer applies
  EXPECT_EQ(key_of(state, 'c'), "");                             // 50 %: asks first, as before
  ASSERT_TRUE(state.confirm.has_value());
  EXPECT_EQ(key_of(state, 'y'), "continue");
}

TEST(Console, AnIdleOrFinishedConsoleStartsTheNextSession) {
  ConsoleState state;
  update(
      state,
      {{"type", "status"}, {"state", "idle"}, {"rig", "sim"}, {"steps", json::array()}, {"elapsed_s", 0.0}});
  EXPECT_TRUE(has(render(state), "c start a session  q detach")) << render(state);
  EXPECT_EQ(key_of(state, 'c'), "start");
  EXPECT_EQ(key_of(state, 'r'), "");
  EXPECT_TRUE(has(render(state), "No session is running: press c to start one")) << render(state);
  update(state, status_message("done", ""));
  update(state,
         {{"type", "done"}, {"outcome", "written"}, {"text", "written"}, {"reports", {"/s/report.html"}}});
  EXPECT_TRUE(has(render(state), "Report: /s/report.html")) << render(state);
  EXPECT_TRUE(has(render(state), "c start the next session  q detach")) << render(state);
  EXPECT_EQ(key_of(state, '\r'), "start");
}

TEST(Console, RestartAbortsThenStartsWhenTheSessionHasEnded) {
  ConsoleState state;
  update(state, status_message());
  EXPECT_EQ(key_of(state, 'R'), "");
  EXPECT_TRUE(has(render(state), "Restart: abort this session and start a new one?")) << render(state);
  EXPECT_EQ(key_of(state, 'y'), "abort");
  EXPECT_TRUE(state.outbox.empty()) << "the start waits for the end of the session";
  update(state, status_message("aborted", ""));
  update(state, {{"type", "done"}, {"outcome", "aborted"}, {"text", "Aborted by the operator."}});
  ASSERT_EQ(state.outbox.size(), 1u);
  EXPECT_EQ(state.outbox.front().value("cmd", ""), "start");
  // The same steps as the session it ended (the start took the configured ones).
  EXPECT_EQ(state.outbox.front().value("steps", json()), json({"preflight", "poses", "solve", "write"}))
      << state.outbox.front();
}

TEST(Console, ObserversSendNothing) {
  ConsoleState state;
  state.observe = true;
  EXPECT_FALSE(on_key(state, 'c').request.has_value());
  EXPECT_FALSE(on_key(state, 'a').request.has_value());
  EXPECT_FALSE(on_key(state, 'y').request.has_value());
  EXPECT_TRUE(on_key(state, 'q').detach);
  EXPECT_TRUE(has(render(state), "observing"));
}

TEST(Console, PlainLinesForAPipe) {
  EXPECT_EQ(plain_line(status_message()), "status: running, step 2 of 4: poses");
  EXPECT_EQ(plain_line(kPrompt), "prompt [poses]: Turn the rig to a new orientation and hold it still");
  EXPECT_EQ(plain_line(kLive), "live [poses]: Still: yes  2.1 of 3.0 s; Poses: 7 of 12; 50%");
  EXPECT_EQ(plain_line({{"type", "done"}, {"outcome", "aborted"}, {"text", "by the operator"}}),
            "done: aborted: by the operator");
  EXPECT_EQ(
      plain_line(
          {{"type", "done"}, {"outcome", "aborted"}, {"text", "by the operator"}, {"session_dir", "/s"}}),
      "done: aborted: by the operator (session folder /s)");
  EXPECT_EQ(plain_line({{"type", "reply"}, {"cmd", "status"}, {"ok", true}}), std::nullopt);
  EXPECT_EQ(plain_line({{"type", "weather"}}), std::nullopt);
}

TEST(Console, ProgressBarClampsAndHandlesNonFinite) {
  EXPECT_EQ(progress_bar(0.5, 12), "[#####-----]  50%");
  EXPECT_EQ(progress_bar(2.0, 12), "[##########] 100%");
  EXPECT_EQ(progress_bar(-1.0, 12), "[----------]   0%");
  EXPECT_EQ(progress_bar(std::nan(""), 12), "[----------]   0%");
}

TEST(Console, StatusTextForImucalctlStatus) {
  const std::string text = status_text(status_message());
  EXPECT_TRUE(has(text, "state:   running\nrig:     sim\nstep:    step 2 of 4: poses\n")) << text;
  EXPECT_TRUE(has(text, "elapsed: 12.3 s")) << text;  // imucalctl status keeps the decimal
  // The devices in words, one line each (they were printed as raw JSON).
  const std::string devices = status_text(service_status());
  EXPECT_TRUE(
      has(devices, "imu:     open, 500 Hz, 1200 samples, 1 fault, gyro offset registers stored bias\n"))
      << devices;
  EXPECT_TRUE(has(devices, "camera:  cam0 closed, 0 frames, 0 faults\n")) << devices;
  EXPECT_TRUE(has(devices, "storage: nvmem /sys/bus/nvmem/devices/1-00500/nvmem\n")) << devices;
  EXPECT_TRUE(has(devices, "service: imucald 0.1.0\n")) << devices;
  EXPECT_FALSE(has(devices, "{")) << devices;
  EXPECT_TRUE(has(devices, "session: /var/lib/imucal/sessions/a (48.3 MB recorded)\n")) << devices;
}

// What the session has recorded shows in the header, from the service's status that comes every
// few seconds; the engine's own status at a step change (without the service's part) keeps it.
TEST(Console, TheHeaderShowsWhatTheSessionHasRecorded) {
  ConsoleState state;
  update(state, status_message());
  EXPECT_FALSE(has(render(state), "recorded")) << "nothing said yet";
  update(state, service_status());
  EXPECT_TRUE(has(render(state), "  |  48.3 MB recorded")) << render(state);
  update(state, status_message("running", "solve"));
  EXPECT_TRUE(has(render(state), "  |  48.3 MB recorded")) << render(state);
  json more = service_status();
  more["recorded_bytes"] = 2'150'000'000;
  update(state, more);
  EXPECT_TRUE(has(render(state), "  |  2.15 GB recorded")) << render(state);
}

}  // namespace
}  // namespace imucal::ctl

namespace imucal::ctl {
namespace {

/// The motion step's live figures with each camera's coverage, as imucald sends them.
nlohmann::json motion_live_with_coverage() {
  std::vector<std::int64_t> cam0(48, 0), cam1(48, 0);
  cam0[0] = 40;  // the top left cell, most seen
  cam0[9] = 10;  // one down and right: a quarter of the most
  cam1[47] = 5;  // the bottom right cell
  auto cov = [](const std::vector<std::int64_t>& cells, double x, int views) {
    return nlohmann::json{{"cols", 8}, {"rows", 6}, {"cells", cells}, {"views", views},
                          {"x", x},    {"y", 0.25}, {"size", 0.5},    {"skew", 0.0}};
  };
  return {{"type", "live"},
          {"step", "motion"},
          {"lines", {"18 of 60 s"}},
          {"progress", 0.3},
          {"figures",
           {{"gyro_rms_dps", {30.0, 20.0, 10.0}},
            {"frames", 400},
            {"frames_seen", 300},
            {"camera_frames", {200, 200}},
            {"camera_frames_seen", {160, 140}},
            {"frames_seen_by_every_camera", 120},
            {"coverage", {cov(cam0, 0.714, 12), cov(cam1, 1.0, 9)}}}}};
}

TEST(Console, TheMotionStepShowsWhereEachCameraSawTheTarget) {
  ConsoleState state;
  update(state, status_message("running", "motion"));
  update(state, motion_live_with_coverage());
  const std::string screen = render(state, {80});
  EXPECT_TRUE(has(screen, "where the target was seen:  cam0        cam1")) << screen;
  // Row 1: the most-seen cell '#', nothing else in cam0's first row; cam1's empty.
  EXPECT_TRUE(has(screen, "|#       |  |        |")) << screen;
  // Row 2: a cell seen a quarter as often as the most: '.'.
  EXPECT_TRUE(has(screen, "| .      |  |        |")) << screen;
  EXPECT_TRUE(has(screen, "|        |  |       #|")) << screen;
  EXPECT_TRUE(has(screen, "cam0: across 71%, down 25%, size 50%, tilt 0% (12 views)")) << screen;
  EXPECT_TRUE(has(screen, "cam1: across 100%, down 25%, size 50%, tilt 0% (9 views)")) << screen;
  // A short screen keeps the spans and drops the grid first.
  const std::string small = render(state, {80, 14});
  EXPECT_TRUE(has(small, "cam0: across 71%")) << small;
}

}  // namespace
}  // namespace imucal::ctl
