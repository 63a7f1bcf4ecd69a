// The operator console's model, renderer and keys, as text: no terminal needed.
#include <gtest/gtest.h>

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
            {{"name", "extra"}, {"state", "skipped"}}}},
          {"elapsed_s", 12.34}};
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
  EXPECT_TRUE(has(screen, "imucal  rig sim  |  running  |  step 2 of 4: poses  |  12.3 s")) << screen;
  EXPECT_TRUE(has(screen, " [x] preflight\n [>] poses\n [ ] solve\n [-] extra\n")) << screen;
  EXPECT_TRUE(has(screen, ">> Turn the rig to a new orientation and hold it still")) << screen;
  EXPECT_TRUE(has(screen, "   Still: yes  2.1 of 3.0 s\n   Poses: 7 of 12\n")) << screen;
  EXPECT_TRUE(has(screen, "####----") && has(screen, " 50%")) << screen;
  EXPECT_TRUE(has(screen, "c continue  r redo  a abort  q detach")) << screen;
  for (std::size_t start = 0, end; (end = screen.find('\n', start)) != std::string::npos; start = end + 1) {
    EXPECT_LE(end - start, 80u) << "every line fits the width";
  }
}

TEST(Console, LinesAreCutToTheWidth) {
  ConsoleState state;
  update(state, status_message());
  update(state, {{"type", "message"}, {"level", "info"}, {"text", std::string(300, 'x')}});
  const std::string screen = render(state, {30});
  for (std::size_t start = 0, end; (end = screen.find('\n', start)) != std::string::npos; start = end + 1) {
    EXPECT_LE(end - start, 30u) << screen;
  }
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
  EXPECT_TRUE(has(screen, "y accept  n reject  q detach")) << screen;
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
  // Wrong types, unknown types, non-objects: no throw, nothing shown.
  for (const json& junk :
       {json(nullptr), json(5), json::array({1}), json{{"type", 7}}, json{{"type", "weather"}},
        json{{"type", "status"}, {"steps", "many"}, {"elapsed_s", "x"}},
        json{{"type", "live"}, {"lines", {1, "ok line"}}, {"progress", "half"}},
        json{{"type", "review"}, {"pass", "yes"}, {"gates", {{{"pass", 1}}}}}}) {
    EXPECT_NO_THROW(update(state, junk)) << junk;
    EXPECT_NO_THROW((void)render(state)) << junk;
    EXPECT_NO_THROW((void)plain_line(junk)) << junk;
  }
  EXPECT_TRUE(has(render(state), "ok line"));
}

TEST(Console, KeysMapToRequestsAndAbortAsksFirst) {
  ConsoleState state;
  auto key_of = [&](char c) {
    auto action = on_key(state, c);
    return action.request ? (*action.request).value("key", (*action.request)["cmd"].get<std::string>()) : "";
  };
  EXPECT_EQ(key_of('c'), "continue");
  EXPECT_EQ(key_of(' '), "continue");
  EXPECT_EQ(key_of('\r'), "continue");
  EXPECT_EQ(key_of('r'), "redo");
  EXPECT_EQ(key_of('y'), "accept");
  EXPECT_EQ(key_of('n'), "reject");
  EXPECT_EQ(key_of('s'), "skip");
  EXPECT_EQ(key_of('x'), "");
  EXPECT_EQ(key_of('a'), "");  // asks
  EXPECT_TRUE(state.confirm_abort);
  EXPECT_TRUE(has(render(state), "Abort the session? y: yes"));
  EXPECT_EQ(key_of('n'), "");  // not aborted, and 'n' is not sent as reject here
  EXPECT_FALSE(state.confirm_abort);
  EXPECT_EQ(key_of('a'), "");
  EXPECT_EQ(key_of('y'), "abort");
  EXPECT_TRUE(on_key(state, 'q').detach);
  EXPECT_TRUE(on_key(state, 3).detach);  // Ctrl-C as a byte
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
  EXPECT_TRUE(has(text, "elapsed: 12.3 s")) << text;
}

}  // namespace
}  // namespace imucal::ctl
