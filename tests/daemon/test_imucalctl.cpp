// SPDX-License-Identifier: BSD-3-Clause
// imucalctl as a process against a test server: the commands, their errors and exit codes, the
// console on a pipe, and the console in a real terminal (a tmux pane) with keys pressed.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>

#include "daemon/ctl/client.hpp"
#include "tests/daemon/service_test_host.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::service {
namespace {

using nlohmann::json;
using test::TestService;

struct Outcome {
  int exit_code = -1;
  std::string out;
  std::string err;
};

struct Process {
  pid_t pid = -1;
  std::string out_path;
  std::string err_path;
};

// Starts imucalctl with `args`, stdin from /dev/null, output to files in `dir`; as user nobody
// when `as_nobody` (to meet the socket's permissions as an operator would).
Process spawn(const std::vector<std::string>& args, const std::string& dir, bool as_nobody = false) {
  Process process{-1, dir + "/out", dir + "/err"};
  std::vector<std::string> argv_strings{IMUCALCTL_PATH};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& arg : argv_strings) {
    argv.push_back(arg.data());
  }
  argv.push_back(nullptr);
  process.pid = ::fork();
  if (process.pid == 0) {
    const int in = ::open("/dev/null", O_RDONLY);
    const int out = ::open(process.out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0666);
    const int err = ::open(process.err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0666);
    ::dup2(in, 0);
    ::dup2(out, 1);
    ::dup2(err, 2);
    if (as_nobody && (::setgid(65534) != 0 || ::setuid(65534) != 0)) {
      ::_exit(126);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return process;
}

Outcome finish(const Process& process) {
  Outcome run;
  int status = 0;
  const bool exited =
      TestService::wait_for([&] { return ::waitpid(process.pid, &status, WNOHANG) == process.pid; });
  if (!exited) {
    ::kill(process.pid, SIGKILL);
    ::waitpid(process.pid, &status, 0);
  }
  run.exit_code = exited && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.out = test::read_file(process.out_path);
  run.err = test::read_file(process.err_path);
  return run;
}

Outcome imucalctl(const std::vector<std::string>& args, bool as_nobody = false) {
  return finish(spawn(args, test::scratch_dir(), as_nobody));
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

class Imucalctl : public ::testing::Test {
 protected:
  Imucalctl() : service(options()) {}
  ControlServerOptions options() const {
    ControlServerOptions options;
    options.path = dir.socket();
    return options;
  }
  test::SocketDir dir;
  TestService service;
};

TEST_F(Imucalctl, StatusAsTextAndJson) {
  ASSERT_TRUE(service.ok()) << service.error;
  const Outcome text = imucalctl({"--socket", dir.socket(), "status"});
  EXPECT_EQ(text.exit_code, 0) << text.err;
  EXPECT_TRUE(has(text.out, "state:   running\nrig:     sim\nstep:    step 3 of 4: poses")) << text.out;
  const Outcome as_json = imucalctl({"--socket", dir.socket(), "status", "--json"});
  EXPECT_EQ(as_json.exit_code, 0) << as_json.err;
  EXPECT_EQ(json::parse(as_json.out), session_msg::encode(service.host.status()));
}

TEST_F(Imucalctl, SocketFromTheEnvironment) {
  ASSERT_TRUE(service.ok()) << service.error;
  ::setenv("IMUCAL_SOCKET", dir.socket().c_str(), 1);
  const Outcome run = imucalctl({"status"});
  ::unsetenv("IMUCAL_SOCKET");
  EXPECT_EQ(run.exit_code, 0) << run.err;
}

TEST_F(Imucalctl, StartAbortAcceptReachTheHost) {
  ASSERT_TRUE(service.ok()) << service.error;
  const Outcome started = imucalctl({"--socket", dir.socket(), "start", "--steps", "poses,solve"});
  EXPECT_EQ(started.exit_code, 0);
  EXPECT_TRUE(has(started.out, "session started")) << "start printed nothing";
  EXPECT_EQ(imucalctl({"--socket", dir.socket(), "start"}).exit_code, 0);
  EXPECT_EQ(imucalctl({"--socket", dir.socket(), "abort"}).exit_code, 0);
  EXPECT_EQ(imucalctl({"--socket", dir.socket(), "accept"}).exit_code, 0);
  EXPECT_EQ(service.host.starts(), (std::vector<std::vector<std::string>>{{"poses", "solve"}, {}}));
  EXPECT_EQ(service.host.keys(), (std::vector<std::string>{"abort", "accept"}));
}

TEST_F(Imucalctl, AnotherControllerIsNamedInTheError) {
  ASSERT_TRUE(service.ok()) << service.error;
  auto console = ctl::Connection::open(dir.socket());
  ASSERT_TRUE(console.ok());
  ASSERT_TRUE(console->request({{"cmd", "hello"}, {"client", "bench console"}, {"role", "controller"}}).ok());
  const Outcome run = imucalctl({"--socket", dir.socket(), "abort"});
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_TRUE(has(run.err, "another controller is attached (bench console)")) << run.err;
  EXPECT_TRUE(service.host.keys().empty());
}

TEST_F(Imucalctl, NoServiceSaysHowToCheck) {
  const Outcome run = imucalctl({"--socket", dir.path + "/absent.sock", "status"});
  EXPECT_EQ(run.exit_code, 3);
  EXPECT_TRUE(has(run.err, "is imucald running? systemctl status imucald")) << run.err;
}

TEST_F(Imucalctl, PermissionDeniedNamesTheGroup) {
  ASSERT_TRUE(service.ok()) << service.error;
  if (::geteuid() == 0) {
    // Root passes every permission check: run imucalctl as nobody, who may enter the folder
    // but is neither the socket's owner nor in its group.
    ASSERT_EQ(::chmod(dir.path.c_str(), 0755), 0);
  } else {
    ASSERT_EQ(::chmod(dir.socket().c_str(), 0), 0);  // not even the owner may connect now
  }
  const Outcome run = imucalctl({"--socket", dir.socket(), "status"}, ::geteuid() == 0);
  EXPECT_EQ(run.exit_code, 4) << run.err;
  EXPECT_TRUE(has(run.err, "permission denied") && has(run.err, "usermod -aG imucal")) << run.err;
}

TEST_F(Imucalctl, BadCommandLineIsExitCode2) {
  EXPECT_EQ(imucalctl({"--socket", dir.socket(), "frobnicate"}).exit_code, 2);
  EXPECT_EQ(imucalctl({}).exit_code, 2);
  // A socket path no Unix socket can have (sun_path holds 107 bytes), given or from the
  // environment, is a command-line error that says why.
  const std::string long_path = "/tmp/" + std::string(200, 'x');
  const Outcome given = imucalctl({"--socket", long_path, "status"});
  EXPECT_EQ(given.exit_code, 2) << given.err;
  EXPECT_TRUE(has(given.err, "a Unix socket takes at most 107")) << given.err;
  ::setenv("IMUCAL_SOCKET", long_path.c_str(), 1);
  const Outcome from_env = imucalctl({"status"});
  ::unsetenv("IMUCAL_SOCKET");
  EXPECT_EQ(from_env.exit_code, 2) << from_env.err;
  EXPECT_TRUE(has(from_env.err, "(IMUCAL_SOCKET)")) << from_env.err;
}

// A typo said "A subcommand is required" and nothing else.
TEST_F(Imucalctl, AMistypedCommandNamesTheNearestOne) {
  const Outcome typo = imucalctl({"--socket", dir.socket(), "stauts"});
  EXPECT_EQ(typo.exit_code, 2);
  EXPECT_TRUE(has(typo.err, "unknown command 'stauts'; did you mean 'status'?")) << typo.err;
  EXPECT_TRUE(has(typo.err, "status, start, abort, accept, attach")) << typo.err;
  EXPECT_TRUE(has(imucalctl({"atach"}).err, "did you mean 'attach'?"));
  const Outcome far = imucalctl({"frobnicate"});
  EXPECT_EQ(far.exit_code, 2);
  EXPECT_TRUE(has(far.err, "unknown command 'frobnicate'")) << far.err;
  EXPECT_FALSE(has(far.err, "did you mean")) << far.err;
}

TEST_F(Imucalctl, VersionAndHelpWithExamples) {
  const Outcome version = imucalctl({"--version"});
  EXPECT_EQ(version.exit_code, 0) << version.err;
  EXPECT_EQ(version.out.rfind("imucalctl ", 0), 0u) << version.out;
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{{"--help"},
                                                                                    {"status", "--help"},
                                                                                    {"start", "--help"},
                                                                                    {"abort", "--help"},
                                                                                    {"accept", "--help"},
                                                                                    {"attach", "--help"}}) {
    const Outcome help = imucalctl(args);
    EXPECT_EQ(help.exit_code, 0) << args[0];
    EXPECT_TRUE(has(help.out, "Example")) << args[0] << ":\n" << help.out;
    EXPECT_TRUE(has(help.out, "  imucalctl ")) << args[0] << ":\n" << help.out;
  }
}

TEST_F(Imucalctl, AttachOnAPipePrintsOneLinePerMessage) {
  ASSERT_TRUE(service.ok()) << service.error;
  const Process process = spawn({"--socket", dir.socket(), "attach", "--observe"}, test::scratch_dir());
  auto output = [&] { return test::read_file(process.out_path); };
  ASSERT_TRUE(TestService::wait_for([&] { return has(output(), "status: running"); })) << output();
  service.broadcast(
      {{"type", "prompt"}, {"step", "poses"}, {"text", "Hold it still"}, {"keys", json::array()}});
  service.broadcast({{"type", "live"}, {"step", "poses"}, {"lines", {"Poses: 7 of 12"}}, {"progress", 0.25}});
  ASSERT_TRUE(TestService::wait_for([&] { return has(output(), "Poses: 7 of 12; 25%"); })) << output();
  service.close();  // the service goes away: imucalctl says so and exits 1
  const Outcome run = finish(process);
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_TRUE(has(run.out, "status: running, step 3 of 4: poses\nprompt [poses]: Hold it still\n"))
      << run.out;
  EXPECT_TRUE(has(run.err, "imucald closed the connection")) << run.err;
}

// --- the console in a terminal -------------------------------------------------------------

bool have_tmux() { return std::system("tmux -V >/dev/null 2>&1") == 0; }

class Tmux {
 public:
  explicit Tmux(std::string server) : server_(std::move(server)) {}
  ~Tmux() { (void)run("kill-server"); }
  Tmux(const Tmux&) = delete;
  Tmux& operator=(const Tmux&) = delete;

  int run(const std::string& args) const {
    return std::system(("tmux -L " + server_ + " -f /dev/null " + args + " >/dev/null 2>&1").c_str());
  }
  std::string capture(const std::string& file) const {
    (void)std::system(("tmux -L " + server_ + " capture-pane -p -t ctl > " + file + " 2>/dev/null").c_str());
    return test::read_file(file);
  }

 private:
  std::string server_;
};

TEST_F(Imucalctl, AttachInATerminalShowsThePromptAndSendsKeys) {
  if (!have_tmux()) {
    GTEST_SKIP() << "tmux is not installed (apt-get install tmux): the console is not tested in a terminal";
  }
  ASSERT_TRUE(service.ok()) << service.error;
  service.host.set_snapshot_extra({{{"type", "prompt"},
                                    {"step", "poses"},
                                    {"text", "Turn the rig and hold it still"},
                                    {"keys", {"continue", "redo", "abort"}}}});
  const std::string scratch = test::scratch_dir();
  const std::string capture = scratch + "/pane.txt";
  Tmux tmux("imucal-test-" + std::to_string(::getpid()));
  // The pane's exit status is kept in a file: remain-on-exit would keep the pane, not the code.
  const std::string command = std::string(IMUCALCTL_PATH) + " --socket " + dir.socket() +
                              " attach; echo $? > " + scratch + "/exit_code";
  ASSERT_EQ(tmux.run("new-session -d -s ctl -x 100 -y 40 '" + command + "'"), 0);
  auto screen = [&] { return tmux.capture(capture); };
  ASSERT_TRUE(TestService::wait_for([&] { return has(screen(), ">> Turn the rig and hold it still"); }))
      << screen();
  EXPECT_TRUE(has(screen(), "rig sim  |  running  |  step 3 of 4: poses")) << screen();
  EXPECT_TRUE(has(screen(), "c continue  r redo  a abort  R restart  q detach")) << screen();

  service.broadcast(
      {{"type", "live"}, {"step", "poses"}, {"lines", {"Still: yes  2.1 of 3.0 s"}}, {"progress", 0.5}});
  ASSERT_TRUE(TestService::wait_for([&] { return has(screen(), "Still: yes  2.1 of 3.0 s"); })) << screen();
  EXPECT_TRUE(has(screen(), "50%")) << screen();

  // Half-way through the step, c asks before it ends the step early.
  ASSERT_EQ(tmux.run("send-keys -t ctl c"), 0);
  ASSERT_TRUE(TestService::wait_for([&] { return has(screen(), "End the poses step now, at 50 %?"); }))
      << screen();
  EXPECT_TRUE(service.host.keys().empty());
  ASSERT_EQ(tmux.run("send-keys -t ctl y"), 0);
  ASSERT_TRUE(
      TestService::wait_for([&] { return service.host.keys() == std::vector<std::string>{"continue"}; }));
  ASSERT_EQ(tmux.run("send-keys -t ctl a"), 0);
  ASSERT_TRUE(TestService::wait_for([&] { return has(screen(), "Abort the session?"); })) << screen();
  ASSERT_EQ(tmux.run("send-keys -t ctl y"), 0);
  ASSERT_TRUE(TestService::wait_for([&] { return service.host.keys().size() == 2; }));
  EXPECT_EQ(service.host.keys().back(), "abort");

  ASSERT_EQ(tmux.run("send-keys -t ctl q"), 0);
  ASSERT_TRUE(TestService::wait_for([&] { return !test::read_file(scratch + "/exit_code").empty(); }));
  EXPECT_EQ(test::read_file(scratch + "/exit_code"), "0\n");
  EXPECT_TRUE(TestService::wait_for([&] { return service.clients() == 0; }))
      << "detaching closes the connection";
}

// The console at 80x24 as an operator's terminal: the header and keys stay on screen with a
// long prompt, its drawing and messages; at 160x48 the drawing shows; an idle service is
// started from the console.
TEST_F(Imucalctl, ConsoleAt80x24And160x48AndStartFromTheConsole) {
  if (!have_tmux()) {
    GTEST_SKIP() << "tmux is not installed (apt-get install tmux): the console is not tested in a terminal";
  }
  ASSERT_TRUE(service.ok()) << service.error;
  const json art = {"       ___________",   "      /   LEFT    /|",
                    "     /___________/ |", "     |           | |  right: BOTTOM",
                    "     |   FRONT   | |", "     | (to you)  | /",
                    "     |___________|/",  "   ===================  table"};
  service.host.set_snapshot_extra(
      {{{"type", "prompt"},
        {"step", "poses"},
        {"text",
         "Turn the rig to a new orientation and hold it still (2.0 s); 18 poses, all directions. Next: put "
         "the rig on its right side, left side up"},
        {"keys", {"continue", "redo", "abort"}},
        {"art", art}},
       {{"type", "message"},
        {"level", "info"},
        {"text", "Pose 1 captured; not yet up: left side up, right side up"}},
       {{"type", "message"},
        {"level", "info"},
        {"text", "Pose 2 captured; not yet up: left side up, right side up"}}});
  const std::string scratch = test::scratch_dir();
  const std::string capture = scratch + "/pane.txt";
  for (const auto& [columns, rows] : std::vector<std::pair<int, int>>{{80, 24}, {160, 48}}) {
    Tmux tmux("imucal-test-" + std::to_string(::getpid()) + "-" + std::to_string(columns));
    const std::string command = std::string(IMUCALCTL_PATH) + " --socket " + dir.socket() + " attach";
    ASSERT_EQ(tmux.run("new-session -d -s ctl -x " + std::to_string(columns) + " -y " + std::to_string(rows) +
                       " '" + command + "'"),
              0);
    auto screen = [&] { return tmux.capture(capture); };
    ASSERT_TRUE(TestService::wait_for([&] { return has(screen(), "left side up"); })) << screen();
    const std::string text = screen();
    std::vector<std::string> lines;
    for (std::size_t start = 0, end; (end = text.find('\n', start)) != std::string::npos; start = end + 1) {
      lines.push_back(text.substr(start, end - start));
    }
    ASSERT_FALSE(lines.empty());
    EXPECT_TRUE(has(lines.front(), "imucal  rig sim  |  running  |  step 3 of 4: poses")) << text;
    EXPECT_TRUE(has(text, "c continue  r redo  a abort  R restart  q detach")) << text;
    EXPECT_TRUE(has(text, "Pose 2 captured")) << text;
    if (columns == 160) {
      EXPECT_TRUE(has(text, "/   LEFT    /|")) << text;
      EXPECT_TRUE(has(text, "|   FRONT   | |")) << text;
    }
    ASSERT_EQ(tmux.run("send-keys -t ctl q"), 0);
    ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 0; }));
  }

  // An idle service: the console offers the start, and c starts a session.
  service.host.set_status(
      {{"type", "status"}, {"state", "idle"}, {"rig", "sim"}, {"steps", json::array()}, {"elapsed_s", 0.0}});
  service.host.set_snapshot_extra({});
  Tmux tmux("imucal-test-" + std::to_string(::getpid()) + "-idle");
  const std::string command = std::string(IMUCALCTL_PATH) + " --socket " + dir.socket() + " attach";
  ASSERT_EQ(tmux.run("new-session -d -s ctl -x 80 -y 24 '" + command + "'"), 0);
  auto screen = [&] { return tmux.capture(capture); };
  ASSERT_TRUE(TestService::wait_for([&] { return has(screen(), "c start a session  q detach"); }))
      << screen();
  ASSERT_EQ(tmux.run("send-keys -t ctl c"), 0);
  ASSERT_TRUE(TestService::wait_for([&] { return service.host.starts().size() == 1; })) << screen();
  ASSERT_EQ(tmux.run("send-keys -t ctl q"), 0);
}

}  // namespace
}  // namespace imucal::service
