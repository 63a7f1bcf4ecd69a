// SPDX-License-Identifier: BSD-3-Clause
// imucald as a process on the virtual rig: an operator at imucalctl's console in a terminal (a
// tmux pane) through a whole session, SIGTERM and SIGKILL in the middle of one, and replay of the
// committed fixture session.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/calibration_record.hpp"
#include "core/rig_config.hpp"
#include "core/text_format.hpp"
#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/record.hpp"
#include "drivers/storage/storage_device.hpp"
#include "log/session_log.hpp"
#include "tests/support/imucald_process.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

class Tmux {
 public:
  explicit Tmux(std::string server) : server_(std::move(server)) {}
  ~Tmux() { (void)run("kill-server"); }
  int run(const std::string& args) const {
    return std::system(("tmux -L " + server_ + " -f /dev/null " + args + " >/dev/null 2>&1").c_str());
  }
  std::string capture(const std::string& file) const {
    (void)std::system(("tmux -L " + server_ + " capture-pane -p -t op > " + file + " 2>/dev/null").c_str());
    return test::read_file(file);
  }

 private:
  std::string server_;
};

TEST(Imucald, AnOperatorAtTheConsoleRunsAWholeSessionAndTheRecordIsWritten) {
  if (std::system("tmux -V >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "tmux is not installed (apt-get install tmux): the console is not tested in a terminal";
  const std::string dir = test::scratch_dir();
  // The virtual rig is moved by the scripted operator; the keys come from the person at the console.
  // The session is started from the console itself, so its steps come from the configuration.
  const std::string config =
      test::write_config(dir, "session:\n  steps: [preflight, still, poses, solve, review, write]\n");
  test::Daemon daemon(dir, {"--sim-operator", "motion", "--time-scale", "0"}, config);
  ASSERT_TRUE(test::wait_for([&] { return daemon.ready(); }, 30)) << test::read_file(dir + "/imucald.log");
  const std::string ctl = std::string(IMUCALCTL_PATH) + " --socket " + daemon.socket();

  Tmux tmux("imucald-test-" + std::to_string(::getpid()));
  const std::string pane = dir + "/pane.txt";
  ASSERT_EQ(
      tmux.run("new-session -d -s op -x 110 -y 40 '" + ctl + " attach; echo $? > " + dir + "/exit_code'"), 0);
  auto screen = [&] { return tmux.capture(pane); };
  ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "c start a session"); })) << screen();
  ASSERT_EQ(tmux.run("send-keys -t op c"), 0);
  ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "Press c to begin"); })) << screen();
  EXPECT_TRUE(test::has(screen(), "preflight")) << screen();
  ASSERT_EQ(tmux.run("send-keys -t op c"), 0);
  // The operator sees the poses come in, then the review with its gates.
  ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "Press y to accept"); }, 300)) << screen();
  const std::string review = screen();
  EXPECT_TRUE(test::has(review, "gravity residual")) << review;
  // The header says what the session has recorded (the service's status every few seconds, also
  // while it waits for a key).
  EXPECT_TRUE(test::wait_for([&] { return test::has(screen(), "B recorded"); }, 20)) << screen();
  ASSERT_EQ(tmux.run("send-keys -t op y"), 0);
  ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "written, read back and verified"); }, 60))
      << screen();
  // The end screen names the slot and sequence the record went to, and the session's folder.
  EXPECT_TRUE(test::has(screen(), "slot A, sequence 1")) << screen();
  EXPECT_TRUE(test::has(screen(), "Session folder: ")) << screen();
  EXPECT_TRUE(test::has(screen(), "/report.html")) << screen();
  EXPECT_TRUE(test::has(screen(), "c start the next session")) << screen();
  ASSERT_EQ(tmux.run("send-keys -t op q"), 0);
  ASSERT_TRUE(test::wait_for([&] { return !test::read_file(dir + "/exit_code").empty(); }, 10));
  EXPECT_EQ(test::read_file(dir + "/exit_code"), "0\n");

  // The record is on the storage and reads back.
  const auto stored = test::run_cli({"store", "read", "--config", dir + "/rig.yaml"});
  EXPECT_EQ(stored.exit_code, 0) << stored.err;
  EXPECT_TRUE(test::has(stored.out, "static")) << stored.out;
  // The keys pressed in the terminal are in the session log.
  const std::string events = test::all_events(test::session_log(dir));
  EXPECT_TRUE(test::has(events, R"("key":"continue")")) << "continue from the console";
  EXPECT_TRUE(test::has(events, R"("key":"accept")")) << "accept from the console";
  // The poses step named the next side to turn up and sent its drawing (no sides configured:
  // the IMU's axes); on accelerated time the step passes too fast to catch on the screen.
  EXPECT_TRUE(test::has(events, "Next: Turn the rig so that the IMU's +X axis points up")) << "pose guidance";
  EXPECT_TRUE(test::has(events, R"("art":[)")) << "pose drawing";
  // The session's report was drawn while its log was still open, and says so.
  const std::string report =
      test::read_file(std::filesystem::path(test::session_log(dir)).parent_path().string() + "/report.html");
  EXPECT_TRUE(test::has(report, "still being recorded when this report was drawn")) << report.substr(0, 2000);
  EXPECT_FALSE(test::has(report, "not closed cleanly"));
  ::kill(daemon.pid(), SIGTERM);
  EXPECT_EQ(daemon.wait(), 0);
}

/// The text of the screen line that starts with `label`, with the continuation lines the
/// console wrapped it onto (a full-width line followed by one indented by two) joined back.
std::string wrapped_line(const std::string& screen, const std::string& label, std::size_t width) {
  std::vector<std::string> lines;
  std::istringstream in(screen);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    if (lines[i].rfind(label, 0) != 0) continue;
    std::string out = lines[i];
    for (std::size_t k = i;
         k + 1 < lines.size() && lines[k].size() == width && lines[k + 1].rfind("  ", 0) == 0; ++k)
      out += lines[k + 1].substr(2);
    return out;
  }
  return {};
}

// The whole session at an operator's 80x24 terminal and at 160x48: the review, taller than 24
// rows, scrolls with d so that every line of it is seen before y; the end screen keeps the header
// first and the keys last, and its session folder and report paths are whole (wrapped, never cut).
TEST(Imucald, TheEndScreenAt80x24And160x48ShowsTheFolderAndTheReportsWhole) {
  if (std::system("tmux -V >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "tmux is not installed (apt-get install tmux): the console is not tested in a terminal";
  for (const auto& [columns, rows] : std::vector<std::pair<std::size_t, int>>{{80, 24}, {160, 48}}) {
    SCOPED_TRACE(std::to_string(columns) + "x" + std::to_string(rows));
    const std::string dir = test::scratch_dir() + "/" + std::to_string(columns);
    std::filesystem::create_directories(dir);
    const std::string config =
        test::write_config(dir, "session:\n  steps: [preflight, still, poses, solve, review, write]\n");
    test::Daemon daemon(dir, {"--sim-operator", "motion", "--time-scale", "0"}, config);
    ASSERT_TRUE(test::wait_for([&] { return daemon.ready(); }, 30)) << test::read_file(dir + "/imucald.log");
    const std::string ctl = std::string(IMUCALCTL_PATH) + " --socket " + daemon.socket();
    Tmux tmux("imucald-end-" + std::to_string(::getpid()) + "-" + std::to_string(columns));
    const std::string pane = dir + "/pane.txt";
    ASSERT_EQ(tmux.run("new-session -d -s op -x " + std::to_string(columns) + " -y " + std::to_string(rows) +
                       " '" + ctl + " attach; echo $? > " + dir + "/exit_code'"),
              0);
    auto screen = [&] { return tmux.capture(pane); };
    ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "c start a session"); })) << screen();
    ASSERT_EQ(tmux.run("send-keys -t op c"), 0);
    ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "Press c to begin"); })) << screen();
    ASSERT_EQ(tmux.run("send-keys -t op c"), 0);
    ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "y accept"); }, 300)) << screen();
    // Every line the write stores is seen, scrolling where the review does not fit.
    std::string seen = screen();
    for (int press = 0; press < 12 && test::has(screen(), "d: more"); ++press) {
      ASSERT_EQ(tmux.run("send-keys -t op d"), 0);
      std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the console redraws at once
      seen += screen();
    }
    for (const char* part :
         {"Accel bias: ", "Gyro bias: ", "Accel scale against nominal", "Gyro scale against nominal",
          "Accel misalignment (mrad): yz ", "Gyro misalignment (mrad): yz ", "G-sensitivity",
          "Static intervals ", "Stored calibration: none; this is the first"})
      EXPECT_TRUE(test::has(seen, part)) << part << "\n" << seen;
    if (rows == 24) {
      EXPECT_TRUE(test::has(seen, "-- review rows 1-")) << seen;  // it did not fit
    }
    ASSERT_EQ(tmux.run("send-keys -t op y"), 0);
    ASSERT_TRUE(test::wait_for([&] { return test::has(screen(), "c start the next session"); }, 60))
        << screen();
    const std::string end = screen();
    std::vector<std::string> lines;
    std::istringstream in(end);
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    while (!lines.empty() && lines.back().empty()) lines.pop_back();  // the pane's rows below the screen
    ASSERT_FALSE(lines.empty());
    EXPECT_EQ(lines.front().rfind("imucal  rig ", 0), 0u) << end;  // the header was not scrolled away
    EXPECT_TRUE(test::has(lines.back(), "q detach")) << end;
    EXPECT_LE(lines.size(), static_cast<std::size_t>(rows)) << end;
    const std::string folder = std::filesystem::path(test::session_log(dir)).parent_path().string();
    EXPECT_EQ(wrapped_line(end, "Session folder: ", columns), "Session folder: " + folder) << end;
    const std::string report = wrapped_line(end, "Report: ", columns);
    ASSERT_FALSE(report.empty()) << end;
    EXPECT_TRUE(std::filesystem::is_regular_file(report.substr(8))) << report << "\n" << end;
    EXPECT_TRUE(test::has(report, folder)) << report;
    ASSERT_EQ(tmux.run("send-keys -t op q"), 0);
    ASSERT_TRUE(test::wait_for([&] { return !test::read_file(dir + "/exit_code").empty(); }, 10));
    ::kill(daemon.pid(), SIGTERM);
    EXPECT_EQ(daemon.wait(), 0);
  }
}

TEST(Imucald, SigtermEndsTheSessionCleanlyAndLeavesTheStoredRecordAlone) {
  const std::string dir = test::scratch_dir();
  // At 20x real time the session is in its warm-up or still start a few seconds in.
  test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "20", "--start", "default"});
  ASSERT_TRUE(test::wait_for([&] { return !test::session_log(dir).empty(); }, 30))
      << test::read_file(dir + "/imucald.log");
  std::this_thread::sleep_for(std::chrono::seconds(2));
  ::kill(daemon.pid(), SIGTERM);
  EXPECT_EQ(daemon.wait(), 0) << test::read_file(dir + "/imucald.log");
  auto reader = log::SessionLogReader::open(test::session_log(dir));
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  const std::string events = test::all_events(test::session_log(dir));
  EXPECT_TRUE(test::has(events, R"("type":"stop")")) << events.substr(0, 2000);
  EXPECT_TRUE(test::has(events, R"("outcome":"aborted")"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/eeprom.bin")) << "nothing was written to the storage";
}

TEST(Imucald, SigkillDuringTheRecordingLeavesAReadableLog) {
  const std::string dir = test::scratch_dir();
  test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "20", "--start", "default"});
  ASSERT_TRUE(test::wait_for([&] { return !test::session_log(dir).empty(); }, 30))
      << test::read_file(dir + "/imucald.log");
  std::this_thread::sleep_for(std::chrono::seconds(3));
  ::kill(daemon.pid(), SIGKILL);
  EXPECT_EQ(daemon.wait(), 128 + SIGKILL);
  auto reader = log::SessionLogReader::open(test::session_log(dir));
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->health().complete);
  auto id = (*reader)->find_imu_stream();
  ASSERT_TRUE(id.ok());
  auto n = (*reader)->imu_count(*id);
  ASSERT_TRUE(n.ok());
  // 3 s at 20x real time and 200 Hz is about 12000 samples; the last commit interval may be lost.
  EXPECT_GT(*n, 2000);
  EXPECT_TRUE(test::has(test::all_events(test::session_log(dir)), R"("type":"prompt")"));
}

TEST(Imucald, ReplayOfTheFixtureSessionReachesItsLoggedResult) {
  const auto r = test::run_cli({"replay", test::source_path("fixtures/service-session.imulog"), "-o",
                                test::scratch_dir() + "/replay", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_TRUE(test::has(r.out, R"("same": true)")) << r.out;
  EXPECT_TRUE(test::has(r.out, R"("max_difference": 0.0)")) << r.out;
  EXPECT_TRUE(test::has(r.out, R"("outcome": "written")")) << r.out;
}

// A session log altered or cut short is not replayed as if it were whole: a field of the wrong
// type, an event that is not JSON, an input stamped long after the last sample or a truncated
// file is damage (exit 3, naming the event), a missing or changed result is a difference
// (exit 5), and an output that is a file is a command-line error (exit 2).
TEST(Imucald, ReplayOfAnAlteredLogSaysSoInItsExitCode) {
  const std::string dir = test::scratch_dir();
  struct Case {
    const char* what;
    std::string sql;
    int exit_code;
    const char* message;
  };
  const std::vector<Case> cases = {
      {"a key that is a number",
       "update events set message=json_set(message,'$.key',5) where json_extract(message,'$.type')='key'", 3,
       "\"key\" is number, not a string"},
      {"an applied solve whose id is text",
       "update events set message=json_set(message,'$.id','x') where "
       "json_extract(message,'$.type')='applied'",
       3, "\"id\" is string, not an integer"},
      {"a written event whose where is a number",
       "update events set message=json_set(message,'$.where',12) where "
       "json_extract(message,'$.type')='written'",
       3, "\"where\" is number, not a string"},
      {"a written event whose ok is text",
       "update events set message=json_set(message,'$.ok','yes') where "
       "json_extract(message,'$.type')='written'",
       3, "\"ok\" is string"},
      {"a type that is a number",
       "update events set message=json_set(message,'$.type',7) where rowid=(select min(rowid) from events "
       "where "
       "kind='session' and json_extract(message,'$.type')='status')",
       3, "has no type"},
      {"an event that is not JSON",
       "update events set message='{oops' where rowid=(select max(rowid) from events where kind='session')",
       3, "is not a JSON object"},
      {"the result event missing", "delete from events where json_extract(message,'$.type')='result'", 5,
       "differs from the live one"},
      {"the result replaced",
       "update events set message=json_set(message,'$.imu','none') where "
       "json_extract(message,'$.type')='result'",
       5, "differs from the live one"},
      {"the write's outcome stamped at the end of time",
       "update events set t_ns=9223372036854775807 where json_extract(message,'$.type')='written'", 3,
       "after the recording's last sample"},
  };
  for (const Case& c : cases) {
    const std::string case_dir = dir + "/" + std::to_string(&c - cases.data());
    std::filesystem::create_directories(case_dir);
    const std::string log = test::copy_fixture("service-session.imulog", case_dir);
    ASSERT_TRUE(test::run_sql(log, c.sql)) << c.what;
    const auto r = test::run_cli({"replay", log, "-o", case_dir + "/replay"});
    EXPECT_EQ(r.exit_code, c.exit_code) << c.what << ": " << r.err << r.out;
    EXPECT_TRUE(test::has(r.err, c.message)) << c.what << ": " << r.err;
    EXPECT_FALSE(test::has(r.err, "unexpected")) << c.what << ": " << r.err;
  }
  // An invalid rig configuration inside the log is damage of the log, not a command-line error.
  {
    const std::string case_dir = dir + "/config";
    std::filesystem::create_directories(case_dir);
    const std::string log = test::copy_fixture("service-session.imulog", case_dir);
    ASSERT_TRUE(test::run_sql(log, "update metadata set value='{\"imu\": 5}' where key='rig_config'"));
    const auto r = test::run_cli({"replay", log, "-o", case_dir + "/replay"});
    EXPECT_EQ(r.exit_code, 3) << r.err;
    EXPECT_TRUE(test::has(r.err, "rig_config")) << r.err;
    ASSERT_TRUE(test::run_sql(
        log,
        "update metadata set value='{\"target\": {\"target_type\": \"dartboard\"}}' where key='rig_config'"));
    const auto camera =
        test::run_cli({"calibrate", "camera", "--self-check", "0", log, "-o", case_dir + "/camera.yaml"});
    EXPECT_EQ(camera.exit_code, 3) << camera.err;
    EXPECT_TRUE(test::has(camera.err, "rig_config")) << camera.err;
  }
  // Cut short: the reader finds the damage that info reports.
  const std::string cut_dir = dir + "/cut";
  std::filesystem::create_directories(cut_dir);
  const std::string cut = test::copy_fixture("service-session.imulog", cut_dir);
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) * 2 / 3);
  auto r = test::run_cli({"replay", cut, "-o", cut_dir + "/replay"});
  EXPECT_EQ(r.exit_code, 3) << r.err << r.out;
  EXPECT_TRUE(test::has(r.err, "is damaged")) << r.err;
  // -o naming a file.
  test::write_file(dir + "/a-file", "x");
  r = test::run_cli({"replay", test::source_path("fixtures/service-session.imulog"), "-o", dir + "/a-file"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_TRUE(test::has(r.err, "is not a folder")) << r.err;
  EXPECT_EQ(test::read_file(dir + "/a-file"), "x");
}

TEST(Imucald, ReplayRefusesALogThatIsNoServiceSession) {
  const auto r = test::run_cli({"replay", test::source_path("fixtures/static.imulog")});
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_TRUE(test::has(r.err, "no service session")) << r.err;
}

// A socket mode that is not octal permission bits with read and write for the owner is refused
// before anything starts (a socket nobody can use, setuid bits, trailing garbage).
TEST(Imucald, SocketModesThatAreNotPermissionBitsAreRefused) {
  const std::string dir = test::scratch_dir();
  for (const char* mode : {"0999", "7777", "0666x", "", "0066", "12345"}) {
    const std::string cmd = std::string(IMUCALD_PATH) + " --config " + dir + "/none.yaml --socket " + dir +
                            "/s.sock --state-dir " + dir + " --socket-mode '" + mode + "' 2>" + dir + "/err";
    const int rc = std::system(cmd.c_str());
    EXPECT_EQ(WEXITSTATUS(rc), 2) << mode;
    EXPECT_TRUE(test::has(test::read_file(dir + "/err"), "is not a socket mode"))
        << mode << ": " << test::read_file(dir + "/err");
  }
}

/// The SPI example configuration with every device node under `dir`, where none of them exists.
std::string write_absent_device_config(const std::string& dir) {
  std::string text = test::read_file(test::source_path("config/rig-spi-example.yaml"));
  for (const std::string& from :
       std::vector<std::string>{"device: /dev/spidev0.0", "chip: gpiochip0", "device: /dev/video0",
                                "path: /sys/bus/nvmem/devices/1-00500/nvmem"}) {
    const auto at = text.find(from);
    if (at == std::string::npos) {
      ADD_FAILURE() << from << " is no longer in config/rig-spi-example.yaml";
      continue;
    }
    const std::string key = from.substr(0, from.find(' '));
    // A V4L2 camera needs a /dev/video node name; no machine has this many.
    const std::string to =
        from == "device: /dev/video0" ? "/dev/video987" : dir + "/absent-" + std::to_string(at);
    text.replace(at, from.size(), key + " " + to);
  }
  const std::string path = dir + "/absent.yaml";
  std::ofstream(path) << text;
  return path;
}

int run_status(const std::string& cmd) {
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// The first install's restart loop: --check passed a configuration whose devices are all missing.
TEST(Imucald, CheckExits69WhenAConfiguredDeviceIsAbsentUnlessTheyMayAppearLater) {
  const std::string dir = test::scratch_dir();
  const std::string config = write_absent_device_config(dir);
  const std::string base =
      std::string(IMUCALD_PATH) + " --config " + config + " --state-dir " + dir + " --check";
  EXPECT_EQ(run_status(base + " >" + dir + "/out 2>" + dir + "/err"), 69) << test::read_file(dir + "/err");
  const std::string err = test::read_file(dir + "/err");
  for (const char* key : {"imu.device", "imu.data_ready.chip", "cameras[0].device", "storage.path"})
    EXPECT_TRUE(test::has(err, key)) << key << ": " << err;
  EXPECT_TRUE(test::has(err, "--devices-may-appear-later")) << err;

  EXPECT_EQ(run_status(base + " --devices-may-appear-later >" + dir + "/out 2>" + dir + "/err"), 0)
      << test::read_file(dir + "/err");
  EXPECT_TRUE(test::has(test::read_file(dir + "/out"), "Not on this machine yet: imu.device"))
      << test::read_file(dir + "/out");
}

// The service itself: exit 69, which the unit's RestartPreventExitStatus= names, not 1.
TEST(Imucald, TheServiceExits69WhenTheImuDeviceIsAbsentAnd1WhenItMayAppearLater) {
  const std::string dir = test::scratch_dir();
  const std::string config = write_absent_device_config(dir);
  const std::string socket = test::short_socket_path();
  const std::string base =
      std::string(IMUCALD_PATH) + " --config " + config + " --socket " + socket + " --state-dir " + dir;
  EXPECT_EQ(run_status(base + " 2>" + dir + "/err"), 69) << test::read_file(dir + "/err");
  EXPECT_TRUE(test::has(test::read_file(dir + "/err"), "the IMU's device is not on this machine: imu.device"))
      << test::read_file(dir + "/err");
  EXPECT_EQ(run_status(base + " --devices-may-appear-later 2>" + dir + "/err"), 1)
      << test::read_file(dir + "/err");
}

/// The value of `key=` in a unit file's text (the last one), or "".
std::string unit_value(const std::string& unit, const std::string& key) {
  std::string value;
  std::istringstream in(unit);
  for (std::string line; std::getline(in, line);)
    if (line.rfind(key + "=", 0) == 0) value = line.substr(key.size() + 1);
  return value;
}

// RestartSec=2 with systemd's default limit (5 starts in 10 s) could never trip: 284 restarts in
// 11 minutes. The limit's interval must hold its burst of starts, and the "device absent" and
// "configuration unusable" statuses must not be restarted at all.
TEST(Imucald, TheUnitDoesNotRestartOnAbsentDevicesAndItsStartLimitCanTrip) {
  const std::string unit = test::read_file(test::source_path("systemd/imucald.service.in"));
  ASSERT_FALSE(unit.empty());
  std::istringstream prevent(unit_value(unit, "RestartPreventExitStatus"));
  std::vector<std::string> codes{std::istream_iterator<std::string>(prevent), {}};
  EXPECT_NE(std::find(codes.begin(), codes.end(), "69"), codes.end());
  EXPECT_NE(std::find(codes.begin(), codes.end(), "78"), codes.end());
  const std::string interval = unit_value(unit, "StartLimitIntervalSec");
  const std::string burst = unit_value(unit, "StartLimitBurst");
  const std::string restart_sec = unit_value(unit, "RestartSec");
  ASSERT_FALSE(interval.empty()) << "no StartLimitIntervalSec= (systemd's default is 10 s)";
  ASSERT_FALSE(burst.empty()) << "no StartLimitBurst=";
  ASSERT_FALSE(restart_sec.empty());
  // Each start takes at least RestartSec; allow one more second per start for the start itself.
  EXPECT_GT(std::stod(interval), std::stod(burst) * (std::stod(restart_sec) + 1.0));
}

TEST(Imucald, AMissingConfigurationIsAClearError) {
  const std::string dir = test::scratch_dir();
  const std::string cmd = std::string(IMUCALD_PATH) + " --config " + dir + "/none.yaml --socket " + dir +
                          "/s.sock --state-dir " + dir + " 2>" + dir + "/err";
  const int rc = std::system(cmd.c_str());
  EXPECT_NE(WEXITSTATUS(rc), 0);
  EXPECT_TRUE(test::has(test::read_file(dir + "/err"), "cannot open the rig configuration"))
      << test::read_file(dir + "/err");
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(Imucald, TheReviewShowsTheChangeToTheStoredCalibration) {
  const std::string dir = test::scratch_dir();
  for (int run = 0; run < 2; ++run) {
    test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "0", "--start",
                              "preflight,warmup,still,poses,solve,review,write", "--exit-after-session",
                              "--seed", std::to_string(21 + run)});
    ASSERT_EQ(daemon.wait(), 0) << test::read_file(dir + "/imucald.log");
  }
  std::vector<std::string> logs;
  for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(dir) / "state" / "sessions"))
    logs.push_back((e.path() / "session.imulog").string());
  std::sort(logs.begin(), logs.end());
  ASSERT_EQ(logs.size(), 2u);
  EXPECT_TRUE(test::has(test::all_events(logs[0]), "Stored calibration: none; this is the first"));
  const std::string second = test::all_events(logs[1]);
  // One name per slot: A and B, as `imucal store` and the end screen say (it was "slot 0" here).
  EXPECT_TRUE(test::has(second, "Change to the stored calibration (sequence 1 in slot A"))
      << second.substr(0, 3000);
  EXPECT_FALSE(test::has(second, "in slot 0")) << second.substr(0, 3000);
  EXPECT_TRUE(test::has(second, R"("difference_to_stored":{"b_a")"));
  // The change in the units the correction outputs (counts only beside them, on raw input).
  for (const auto& [what, unit] :
       {std::pair{"  accel bias ", " m/s^2"}, std::pair{"  gyro bias ", " deg/s"}}) {
    const std::size_t at = second.find(what);
    ASSERT_NE(at, std::string::npos) << what;
    const std::string line = second.substr(at, second.find('"', at) - at);
    EXPECT_TRUE(test::has(line, unit)) << line;
  }
  // And the second write went to the other slot.
  const auto stored = test::run_cli({"store", "read", "--config", dir + "/rig.yaml"});
  EXPECT_TRUE(test::has(stored.out, "sequence 2")) << stored.out;
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

/// Column `column` (0 unit, 1 estimate, 2 truth, 3 error, 4 relative error) of the row `name` of
/// the table in sim-truth.txt, as a number.
double truth_figure(const std::string& text, const std::string& name, int column) {
  const auto at = text.find("\n  " + name + " ");
  if (at == std::string::npos) return NAN;
  std::istringstream in(text.substr(at + 3 + name.size()));
  std::string word;
  for (int i = 0; i <= column; ++i) in >> word;
  return std::strtod(word.c_str(), nullptr);
}

TEST(Imucald, TheMotionStepRecordsTheCameraAndTheRecordHoldsTheCameraImuCalibration) {
  const std::string dir = test::scratch_dir();
  // A small camera at 10 Hz and a 30 s motion step keep the test short; the protocol is the
  // shipped one otherwise.
  const std::string config = test::write_config(dir, "session:\n  poses: 12\n  motion_s: 30\n",
                                                "    width: 320\n    height: 240\n    rate_hz: 10\n");
  // A calibration stored before, with cam0 5 mm and 1 ms away from what the session will find:
  // the review shows the change, read from the stored record as typed fields.
  CalibrationRecord before;
  before.imu.input_units = "raw";
  CameraRecord old_cam;
  old_cam.name = "cam0";
  old_cam.T_cam_imu.topRightCorner<3, 1>() = Eigen::Vector3d(0.005, 0.0, 0.0);
  old_cam.timeshift_cam_imu_s = 0.001;
  before.cameras.push_back(old_cam);
  {
    auto rig = load_rig_config(config);
    ASSERT_TRUE(rig.ok()) << rig.error().message;
    auto dev = drivers::open_storage_device(rig->storage, drivers::StorageAccess::kWrite);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    auto store = drivers::CalibrationStore::open(**dev, static_cast<std::uint64_t>(rig->storage.offset_bytes),
                                                 static_cast<std::uint64_t>(rig->storage.size_bytes));
    ASSERT_TRUE(store.ok()) << store.error().message;
    ASSERT_TRUE(store->write(nlohmann::json::to_cbor(calibration_record_json(before))).ok());
  }
  test::Daemon daemon(
      dir, {"--sim-operator", "full", "--time-scale", "0", "--start", "default", "--exit-after-session"},
      config);
  ASSERT_EQ(daemon.wait(), 0) << test::read_file(dir + "/imucald.log");
  const std::string log = test::session_log(dir);
  const std::string session = std::filesystem::path(log).parent_path().string();

  // The motion step's own log: the IMU and the camera's frames, the camera streaming only then.
  auto motion = log::SessionLogReader::open(session + "/motion.imulog");
  ASSERT_TRUE(motion.ok()) << motion.error().message;
  EXPECT_TRUE((*motion)->health().complete);
  auto cam = (*motion)->find_camera_stream("cam0");
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  auto frames = (*motion)->frame_count(*cam);
  ASSERT_TRUE(frames.ok());
  EXPECT_GE(*frames, 290);  // 30 s at 10 Hz
  EXPECT_LE(*frames, 320);
  const std::string events = test::all_events(log);
  EXPECT_TRUE(test::has(events, R"("step":"motion")")) << "the motion step ran";
  EXPECT_TRUE(test::has(events, "Target seen in")) << "live detection figures";
  // The review shows what the write will store of the camera, in true units with sigmas.
  EXPECT_TRUE(test::has(events, "cam0 T_cam_imu: rotation vector ")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, " deg (sigma about the camera's x y z ")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, " mm\"")) << "the translation with its sigmas, in mm";
  EXPECT_TRUE(test::has(events, "  time offset ")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, "  intrinsics (pinhole-radtan, ")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, "  distortion: k1 ")) << events.substr(0, 3000);
  // The record stored before held no intrinsics: the change says so instead of inventing one.
  EXPECT_TRUE(test::has(events, "; intrinsics not in the stored record")) << events.substr(0, 3000);

  // The record on the storage holds the camera, T_cam_imu near the virtual camera's mounting.
  const auto stored = test::run_cli({"store", "read", "--config", config, "--json"});
  ASSERT_EQ(stored.exit_code, 0) << stored.err;
  EXPECT_TRUE(test::has(stored.out, R"("T_cam_imu")")) << stored.out.substr(0, 2000);
  // Every camera-IMU parameter the session estimated is stored with a sigma, none a zero.
  const auto record = nlohmann::json::parse(stored.out, nullptr, false);
  ASSERT_FALSE(record.is_discarded());
  {
    // The change to the record stored before, as the review said it: the new translation less
    // the old, in mm, and the time offset's change in ms.
    auto now = calibration_record_from_json(record["calibration"]);
    ASSERT_TRUE(now.ok()) << now.error().message;
    ASSERT_FALSE(now->cameras.empty());
    const Eigen::Vector3d dt =
        1e3 * (now->cameras[0].T_cam_imu.topRightCorner<3, 1>() - old_cam.T_cam_imu.topRightCorner<3, 1>());
    const std::string change = "  cam0: translation " + fixed(dt.x(), 2) + " " + fixed(dt.y(), 2) + " " +
                               fixed(dt.z(), 2) + " mm (" + fixed(dt.norm(), 2) + " mm), rotation ";
    EXPECT_TRUE(test::has(events, change)) << change << "\n" << events.substr(0, 3000);
    const double dshift = 1e3 * (now->cameras[0].timeshift_cam_imu_s - old_cam.timeshift_cam_imu_s);
    EXPECT_TRUE(test::has(events, " deg, time offset " + fixed(dshift, 3) + " ms")) << events.substr(0, 3000);
  }
  ASSERT_FALSE(record["calibration"]["cameras"].empty());
  for (const auto& c : record["calibration"]["cameras"]) {
    for (const char* key : {"rotation_sigma_rad", "translation_sigma_m"}) {
      ASSERT_EQ(c[key].size(), 3u) << key;
      for (const auto& v : c[key]) {
        ASSERT_TRUE(v.is_number()) << key << " " << c.dump();
        EXPECT_GT(v.get<double>(), 0.0) << key;
      }
    }
    ASSERT_TRUE(c["timeshift_sigma_s"].is_number()) << c.dump();
    EXPECT_GT(c["timeshift_sigma_s"].get<double>(), 0.0);
    // The intrinsics the extrinsics were found with, each with the camera step's sigma.
    ASSERT_TRUE(c.contains("camera")) << c.dump();
    for (const char* key : {"intrinsics_sigma", "distortion_coeffs_sigma"}) {
      ASSERT_EQ(c["camera"][key].size(),
                c["camera"][std::string(key).substr(0, std::string(key).size() - 6)].size())
          << key;
      for (const auto& v : c["camera"][key]) {
        ASSERT_TRUE(v.is_number()) << key << " " << c.dump();
        EXPECT_GT(v.get<double>(), 0.0) << key;
      }
    }
  }
  EXPECT_EQ(record["calibration"]["version"], 3);
  // The final table beside the virtual camera's truth: translation (mm), rotation (deg) and the
  // time offset (ms; the virtual camera stamps 4 ms late) found.
  const std::string truth = test::read_file(session + "/sim-truth.txt");
  for (const std::string axis : {"x", "y", "z"}) {
    EXPECT_LT(std::abs(truth_figure(truth, "cam0 translation " + axis, 3)), 5.0) << truth;
    EXPECT_LT(std::abs(truth_figure(truth, "cam0 rotation about " + axis, 3)), 0.1) << truth;
  }
  EXPECT_EQ(truth_figure(truth, "cam0 time offset", 2), -4.0) << truth;
  EXPECT_LT(std::abs(truth_figure(truth, "cam0 time offset", 3)), 0.5) << truth;
  EXPECT_LT(std::abs(truth_figure(truth, "cam0 fx", 4)), 0.01) << truth;  // relative error

  // Replay reaches the same camera-IMU result from the two logs.
  const auto r = test::run_cli({"replay", log, "-o", dir + "/replay", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_TRUE(test::has(r.out, R"("same": true)")) << r.out;
  EXPECT_TRUE(std::filesystem::exists(dir + "/replay/camimu/calibration.yaml"));

  // A later session of the IMU only keeps the stored cameras, and its review says so.
  test::Daemon imu_only(
      dir,
      {"--sim-operator", "full", "--time-scale", "0", "--start",
       "preflight,warmup,still,poses,solve,review,write", "--exit-after-session", "--seed", "5"},
      config);
  ASSERT_EQ(imu_only.wait(), 0) << test::read_file(dir + "/imucald.log");
  const auto after = test::run_cli({"store", "read", "--config", config, "--json"});
  ASSERT_EQ(after.exit_code, 0) << after.err;
  const auto kept = nlohmann::json::parse(after.out, nullptr, false);
  ASSERT_FALSE(kept.is_discarded());
  EXPECT_EQ(kept["sequence"], record["sequence"].get<int>() + 1);
  EXPECT_EQ(kept["calibration"]["cameras"], record["calibration"]["cameras"]);
  EXPECT_TRUE(test::has(after.out, "cameras kept from the stored record (sequence"))
      << after.out.substr(0, 3000);
  std::string review_events;
  for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(dir) / "state" / "sessions"))
    review_events += test::all_events((e.path() / "session.imulog").string());
  EXPECT_TRUE(test::has(review_events, "Cameras: cameras kept from the stored record"));
}

TEST(Imucald, ACameraLostInTheMotionStepStopsItAndKeepsWhatWasRecorded) {
  const std::string dir = test::scratch_dir();
  const std::string config = test::write_config(dir, "session:\n  poses: 12\n  motion_s: 30\n",
                                                "    width: 320\n    height: 240\n    rate_hz: 10\n");
  // The scripted operator aborts on a fault (a script cannot plug a cable back in).
  test::Daemon daemon(dir,
                      {"--sim-operator", "full", "--time-scale", "0", "--start", "default",
                       "--exit-after-session", "--sim-unplug-camera", "50"},
                      config);
  EXPECT_EQ(daemon.wait(), 1) << test::read_file(dir + "/imucald.log");
  const std::string log = test::session_log(dir);
  const std::string events = test::all_events(log);
  EXPECT_TRUE(test::has(events, R"("source":"cam0")")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, "disconnected"));
  EXPECT_TRUE(test::has(events, "press r to redo the step")) << "the way to continue";
  EXPECT_TRUE(test::has(events, R"("outcome":"aborted")"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/eeprom.bin")) << "the storage is untouched";
  // Every frame the camera gave before it vanished is in the motion log, which is complete.
  auto motion =
      log::SessionLogReader::open(std::filesystem::path(log).parent_path().string() + "/motion.imulog");
  ASSERT_TRUE(motion.ok()) << motion.error().message;
  EXPECT_TRUE((*motion)->health().complete);
  auto cam = (*motion)->find_camera_stream("cam0");
  ASSERT_TRUE(cam.ok());
  auto frames = (*motion)->frame_count(*cam);
  ASSERT_TRUE(frames.ok());
  EXPECT_EQ(*frames, 50);
}

TEST(Imucald, PreflightFailsAStorageTheServiceCannotWrite) {
  const std::string dir = test::scratch_dir();
  // A folder that does not exist: not writable even for root, which the tests may run as.
  std::string config = test::write_config(dir);
  {
    std::string text = test::read_file(config);
    text = std::regex_replace(text, std::regex("path: " + dir + "/eeprom.bin"),
                              "path: " + dir + "/none/eeprom.bin");
    std::ofstream(config) << text;
  }
  test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "0", "--start", "default"}, config);
  ASSERT_TRUE(
      test::wait_for([&] { return test::has(test::all_events(test::session_log(dir)), "not writable"); }, 60))
      << test::read_file(dir + "/imucald.log") << test::all_events(test::session_log(dir)).substr(0, 3000);
  const std::string events = test::all_events(test::session_log(dir));
  EXPECT_TRUE(test::has(events, "cannot create " + dir + "/none/eeprom.bin")) << events.substr(0, 3000);
  EXPECT_FALSE(test::has(events, R"("step":"warmup")"))
      << "the session does not go on past a failed preflight";
  ::kill(daemon.pid(), SIGTERM);
  EXPECT_EQ(daemon.wait(), 0);
}

/// Writes `payload` as the next record of the rig's storage region, as a writer of that
/// version of imucal would.
void store_payload(const RigConfig& rig, const std::vector<std::uint8_t>& payload) {
  auto dev = drivers::open_storage_device(rig.storage, drivers::StorageAccess::kWrite);
  ASSERT_TRUE(dev.ok()) << dev.error().message;
  auto store = drivers::CalibrationStore::open(**dev, static_cast<std::uint64_t>(rig.storage.offset_bytes),
                                               static_cast<std::uint64_t>(rig.storage.size_bytes));
  ASSERT_TRUE(store.ok()) << store.error().message;
  ASSERT_TRUE(store->write(payload).ok());
}

// A record a newer imucal wrote (its payload's version, or its slot's framing) is named at the
// preflight with what to do, before anything is recorded. Before: a newer payload left the
// operator at "fix it and press r"; a newer framing passed and the session's write, at its end,
// was refused.
TEST(Imucald, PreflightNamesARecordOfANewerImucalAndWhatToDo) {
  for (const bool framing : {false, true}) {
    SCOPED_TRACE(framing ? "a newer framing" : "a newer payload");
    const std::string dir = test::scratch_dir();
    const std::string config = test::write_config(dir);
    auto rig = load_rig_config(config);
    ASSERT_TRUE(rig.ok()) << rig.error().message;
    {
      nlohmann::json record = calibration_record_json(CalibrationRecord{});
      if (!framing) record["version"] = kCalibrationRecordVersion + 1;
      ASSERT_NO_FATAL_FAILURE(store_payload(*rig, nlohmann::json::to_cbor(record)));  // slot A
    }
    if (framing) {
      // Slot A's header: format version 7, its CRC (bytes 20..23 over 0..19) resealed.
      std::string bytes = test::read_file(rig->storage.path);
      const auto at = static_cast<std::size_t>(rig->storage.offset_bytes);
      bytes[at + 4] = 7;
      const std::uint32_t crc = drivers::crc32(
          std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(bytes.data()) + at, 20));
      for (int i = 0; i < 4; ++i)
        bytes[at + 20 + static_cast<std::size_t>(i)] = static_cast<char>(crc >> (8 * i));
      std::ofstream(rig->storage.path, std::ios::binary) << bytes;
    }
    const std::string before = test::read_file(rig->storage.path);
    test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "0", "--start", "default"}, config);
    ASSERT_TRUE(test::wait_for(
        [&] { return test::has(test::all_events(test::session_log(dir)), "update imucal on the rig"); }, 60))
        << test::read_file(dir + "/imucald.log") << test::all_events(test::session_log(dir)).substr(0, 3000);
    const std::string events = test::all_events(test::session_log(dir));
    EXPECT_TRUE(test::has(events, framing ? "written by a newer imucal" : "a newer imucal wrote it"))
        << events.substr(0, 3000);
    EXPECT_FALSE(test::has(events, "Fix it and press r")) << "the generic advice instead of what to do";
    EXPECT_FALSE(test::has(events, R"("step":"warmup")"))
        << "the session does not go on past a failed preflight";
    ::kill(daemon.pid(), SIGTERM);
    EXPECT_EQ(daemon.wait(), 0);
    EXPECT_EQ(test::read_file(rig->storage.path), before) << "the newer record is untouched";
  }
}

// A storage region the service cannot read, met at a session's preflight: a FIFO at
// storage.path (before: the event loop blocked in its open, for good) and a record whose payload
// nests 200,000 levels deep in a 1 MiB region (before: a stack overflow). Each is named at the
// preflight, the service still answers, and it ends cleanly with the storage as it was.
TEST(Imucald, AStorageItCannotReadIsNamedAtThePreflightAndTheServiceStillAnswers) {
  for (const bool fifo : {true, false}) {
    SCOPED_TRACE(fifo ? "a FIFO at storage.path" : "a deeply nested record");
    const std::string dir = test::scratch_dir();
    std::string config = test::write_config(dir);
    {
      std::string text = test::read_file(config);
      text = std::regex_replace(text, std::regex("size_bytes: 8192"), "size_bytes: 1048576");
      test::write_file(config, text);
    }
    auto rig = load_rig_config(config);
    ASSERT_TRUE(rig.ok()) << rig.error().message;
    if (fifo) {
      ASSERT_EQ(::mkfifo(rig->storage.path.c_str(), 0600), 0);
    } else {
      std::vector<std::uint8_t> nested(200'000, 0x81);  // an array of one item, 200,000 deep
      nested.push_back(0x00);
      ASSERT_NO_FATAL_FAILURE(store_payload(*rig, nested));
    }
    const std::string before = fifo ? std::string() : test::read_file(rig->storage.path);
    test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "0", "--start", "default"}, config);
    const char* named = fifo ? "is not a regular file" : "deeper than 32 levels";
    ASSERT_TRUE(
        test::wait_for([&] { return test::has(test::all_events(test::session_log(dir)), named); }, 60))
        << test::read_file(dir + "/imucald.log") << test::all_events(test::session_log(dir)).substr(0, 3000);
    EXPECT_FALSE(test::has(test::all_events(test::session_log(dir)), R"("step":"warmup")"))
        << "the session does not go on past a failed preflight";
    const std::string out = dir + "/status.txt";
    EXPECT_EQ(std::system((std::string(IMUCALCTL_PATH) + " --socket " + daemon.socket() + " status > " + out +
                           " 2>&1")
                              .c_str()),
              0)
        << test::read_file(out);
    ::kill(daemon.pid(), SIGTERM);
    EXPECT_EQ(daemon.wait_for_exit(30), 0) << test::read_file(dir + "/imucald.log");
    if (fifo) {
      EXPECT_TRUE(std::filesystem::is_fifo(rig->storage.path));
    } else {
      EXPECT_EQ(test::read_file(rig->storage.path), before) << "the record is untouched";
    }
  }
}

// A session asked for as soon as the service listens, before the chip streams (its resets take
// 200 ms of rig time: 10 s of wall time at a time scale of 0.02), starts with the first samples,
// and its preflight finds the chip streaming. Before: the preflight's self-test could not run
// ("call poll() until it streams") and the IMU failed its check.
TEST(Imucald, ASessionStartedRightAfterTheServiceListensStartsWithTheFirstSamples) {
  const std::string dir = test::scratch_dir();
  test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "0.02"});
  ASSERT_TRUE(test::wait_for([&] { return daemon.ready(); }, 30)) << test::read_file(dir + "/imucald.log");
  const std::string out = dir + "/start.txt";
  EXPECT_EQ(std::system((std::string(IMUCALCTL_PATH) + " --socket " + daemon.socket() +
                         " start --steps preflight,still > " + out + " 2>&1")
                            .c_str()),
            0)
      << test::read_file(out);
  ASSERT_TRUE(test::wait_for(
      [&] { return test::has(test::all_events(test::session_log(dir)), R"("type":"preflight")"); }, 120))
      << test::read_file(dir + "/imucald.log");
  const std::string events = test::all_events(test::session_log(dir));
  EXPECT_FALSE(test::has(events, "until it streams")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, "self-test passed")) << events.substr(0, 3000);
  ::kill(daemon.pid(), SIGTERM);
  EXPECT_EQ(daemon.wait(), 0);
}

/// The stored record's gyro bias (counts), from `imucal store read --json`.
std::vector<double> stored_gyro_bias(const std::string& config) {
  const auto r = test::run_cli({"store", "read", "--config", config, "--json"});
  const auto doc = nlohmann::json::parse(r.out, nullptr, false);
  if (doc.is_discarded() || !doc.contains("calibration")) return {};
  return doc["calibration"]["imu"]["b_g"].get<std::vector<double>>();
}

TEST(Imucald, TheStoredGyroBiasGoesIntoTheOffsetRegistersAndSessionsSeeTheChipWithout) {
  const std::string dir = test::scratch_dir();
  std::string config = test::write_config(dir);
  {
    std::string text = test::read_file(config);
    text = std::regex_replace(text, std::regex("(path: " + dir + "/eeprom.bin)"),
                              "$1\n  program_gyro_offsets: true");
    std::ofstream(config) << text;
  }
  const std::vector<std::string> session = {"--sim-operator",
                                            "full",
                                            "--time-scale",
                                            "0",
                                            "--start",
                                            "preflight,warmup,still,poses,solve,review,write",
                                            "--exit-after-session",
                                            "--seed",
                                            "5"};
  {
    test::Daemon first(dir, session, config);
    ASSERT_EQ(first.wait(), 0) << test::read_file(dir + "/imucald.log");
  }
  const std::vector<double> b1 = stored_gyro_bias(config);
  ASSERT_EQ(b1.size(), 3u);

  // At start the service programs the stored bias: at +-500 deg/s one register count is two
  // output counts, against the bias.
  {
    test::Daemon idle(dir, {"--seed", "5"}, config);
    ASSERT_TRUE(test::wait_for([&] { return idle.ready(); }, 30)) << test::read_file(dir + "/imucald.log");
    const std::string status = dir + "/status.json";
    ASSERT_EQ(std::system(
                  (std::string(IMUCALCTL_PATH) + " --socket " + idle.socket() + " status --json > " + status)
                      .c_str()),
              0);
    const std::string expected =
        "[" + std::to_string(std::lround(-b1[0] / 2)) + " " + std::to_string(std::lround(-b1[1] / 2)) + " " +
        std::to_string(std::lround(-b1[2] / 2)) + "] from the stored gyro bias (sequence 1)";
    EXPECT_TRUE(test::has(test::read_file(status), expected))
        << test::read_file(status) << "\nexpected " << expected;
    ::kill(idle.pid(), SIGTERM);
    EXPECT_EQ(idle.wait(), 0);
  }

  // A session clears them first: it calibrates the chip as it powers up, and finds the same bias.
  for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(dir) / "state" / "sessions"))
    std::filesystem::rename(e.path(), dir + "/first-session");
  test::Daemon second(dir, session, config);
  ASSERT_EQ(second.wait(), 0) << test::read_file(dir + "/imucald.log");
  EXPECT_TRUE(test::has(test::all_events(test::session_log(dir)),
                        "gyro offset registers [0 0 0] from cleared (power-up zero)"));
  const std::vector<double> b2 = stored_gyro_bias(config);
  ASSERT_EQ(b2.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(b2[i], b1[i], 0.05) << "axis " << i;
}

TEST(Imucald, AnImuLostMidSessionStopsTheStepAndKeepsWhatWasRecorded) {
  const std::string dir = test::scratch_dir();
  // 40 s into the session: in the poses step. The scripted operator aborts on a fault.
  test::Daemon daemon(dir, {"--sim-operator", "full", "--time-scale", "0", "--start",
                            "preflight,warmup,still,poses,solve,review,write", "--exit-after-session",
                            "--sim-unplug-imu", "40"});
  EXPECT_EQ(daemon.wait(), 1) << test::read_file(dir + "/imucald.log");
  const std::string log = test::session_log(dir);
  const std::string events = test::all_events(log);
  EXPECT_TRUE(test::has(events, R"("type":"fault")")) << events.substr(0, 3000);
  EXPECT_TRUE(test::has(events, R"("source":"imu")"));
  EXPECT_TRUE(test::has(events, "press r to redo the step"));
  EXPECT_TRUE(test::has(events, R"("outcome":"aborted")"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/eeprom.bin")) << "the storage is untouched";
  auto reader = log::SessionLogReader::open(log);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  auto id = (*reader)->find_imu_stream();
  ASSERT_TRUE(id.ok());
  auto n = (*reader)->imu_count(*id);
  ASSERT_TRUE(n.ok());
  EXPECT_GT(*n, 7000) << "the samples before the loss (40 s at 197 Hz) are kept";
  EXPECT_LT(*n, 8200);
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(Imucald, AnUpgradeDuringASessionWaitsForItsEndThenTheServiceExits75ForSystemdToRestartIt) {
  // A package upgrade renames the new program over the running one. Under systemd (NOTIFY_SOCKET
  // set) imucald notices; a session in progress runs on with the modules it loaded when it
  // started, and once it has ended imucald exits 75, which the unit's Restart=on-failure restarts
  // into the new version.
  namespace fs = std::filesystem;
  const std::string dir = test::scratch_dir();
  fs::create_directories(dir + "/bin");
  const std::string program = dir + "/bin/imucald";
  fs::copy_file(IMUCALD_PATH, program);
  const std::string notify = test::short_socket_path();
  const int sock = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(sock, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, notify.c_str(), sizeof addr.sun_path - 1);
  ASSERT_EQ(::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  const std::string socket = test::short_socket_path();
  std::vector<std::string> args = {program,
                                   "--config",
                                   test::write_config(dir),
                                   "--socket",
                                   socket,
                                   "--state-dir",
                                   dir + "/state",
                                   "--sim",
                                   "-q",
                                   "--sim-operator",
                                   "full",
                                   "--time-scale",
                                   "5",
                                   "--start",
                                   "default"};
  const pid_t pid = ::fork();
  if (pid == 0) {
    (void)!std::freopen((dir + "/imucald.log").c_str(), "w", stderr);
    ::setenv("NOTIFY_SOCKET", notify.c_str(), 1);
    ::setenv("IMUCAL_MODULE_DIR", fs::path(IMUCALD_PATH).parent_path().c_str(), 1);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    std::_Exit(127);
  }
  const auto log = [&] { return test::read_file(dir + "/imucald.log"); };
  ASSERT_TRUE(test::wait_for([&] { return !test::session_log(dir).empty(); }, 30)) << log();
  // The upgrade: a new file renamed over the program (and over nothing the session needs now).
  fs::copy_file(IMUCALD_PATH, program + ".new");
  fs::rename(program + ".new", program);
  ASSERT_TRUE(test::wait_for(
      [&] { return test::has(log(), "restarts into the new version when the session ends"); }, 15))
      << log();
  int status = 0;
  EXPECT_EQ(::waitpid(pid, &status, WNOHANG), 0) << "the session was cut short: " << log();
  // The session ends (aborted by the operator); then the service exits 75.
  EXPECT_EQ(
      std::system((std::string(IMUCALCTL_PATH) + " --socket " + socket + " abort > /dev/null 2>&1").c_str()),
      0);
  bool exited = test::wait_for([&] { return ::waitpid(pid, &status, WNOHANG) == pid; }, 20);
  if (!exited) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
  }
  ::close(sock);
  ASSERT_TRUE(exited) << log();
  ASSERT_TRUE(WIFEXITED(status)) << log();
  EXPECT_EQ(WEXITSTATUS(status), 75) << log();
  EXPECT_TRUE(test::has(log(), "its program was replaced (an upgrade) and no session runs")) << log();
  auto reader = log::SessionLogReader::open(test::session_log(dir));
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
}

}  // namespace
}  // namespace imucal
