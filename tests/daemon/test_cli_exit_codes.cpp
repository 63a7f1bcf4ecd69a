// SPDX-License-Identifier: BSD-3-Clause
// The exit codes of docs/cli.md, checked across commands for the same situation: an input that is
// missing, a folder, a FIFO, not a session log or empty exits 3 in every command that reads it (and
// never blocks); an output that exists is refused with exit 2 and left as it was; an output in a
// folder that does not exist exits 7. Nothing is written when a command refuses.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// A command that reads a FIFO without checking blocks for ever; this ends it as a failure.
constexpr unsigned kRunLimitS = 120;

using Args = std::vector<std::string>;

std::string joined(const Args& args) {
  std::string s;
  for (const auto& a : args) s += (s.empty() ? "" : " ") + a;
  return s;
}

/// `args` with every "@" replaced by `value`.
Args with(Args args, const std::string& value) {
  for (auto& a : args) {
    if (a == "@") a = value;
  }
  return args;
}

class CliExitCodes : public ::testing::Test {
 protected:
  void SetUp() override {
    work_ = test::scratch_dir();
    log_ = test::copy_fixture("static.imulog", work_);
    still_ = test::copy_fixture("still.imulog", work_);
    missing_ = work_ + "/missing.imulog";
    folder_ = work_ + "/a-folder";
    fs::create_directory(folder_);
    fifo_ = work_ + "/a-fifo";
    ASSERT_EQ(::mkfifo(fifo_.c_str(), 0600), 0);
    text_ = work_ + "/notes.txt";
    std::ofstream(text_) << "hello\n";
    empty_ = work_ + "/empty.imulog";
    std::ofstream{empty_};
    csv_ = work_ + "/imu.csv";
    std::ofstream csv(csv_);
    for (int i = 0; i < 20; ++i) csv << 0.01 * i << ",0,0,9.81,0,0,0\n";
    inputs_ = {"static.imulog", "still.imulog", "a-folder", "a-fifo", "notes.txt", "empty.imulog", "imu.csv"};
  }

  /// A calibration of the static fixture, as YAML and as JSON, for the commands that read one.
  void calibrate() {
    calibration_ = work_ + "/calibration.yaml";
    result_ = work_ + "/result.json";
    auto r = test::run_cli({"calibrate", "static", log_, "-o", calibration_, "--json", result_});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    inputs_.insert(inputs_.end(), {"calibration.yaml", "result.json"});
  }

  /// Runs `args` and checks the exit code and that the message names `path`.
  void expect_exit(const Args& args, int code, const std::string& named) {
    auto r = test::run_cli(args, kRunLimitS);
    EXPECT_EQ(r.exit_code, code) << joined(args) << "\n" << r.err;
    EXPECT_THAT(r.err, HasSubstr(fs::path(named).filename().string())) << joined(args);
    EXPECT_THAT(r.err, ::testing::Not(HasSubstr("unexpected error"))) << joined(args);
  }

  /// The files of the scratch folder other than the inputs.
  std::vector<std::string> outputs() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(work_)) {
      const std::string name = e.path().filename().string();
      if (std::find(inputs_.begin(), inputs_.end(), name) == inputs_.end()) names.push_back(name);
    }
    return names;
  }

  std::string work_, log_, still_, missing_, folder_, fifo_, text_, empty_, csv_, calibration_, result_;
  std::vector<std::string> inputs_;
};

TEST_F(CliExitCodes, AnUnusableSessionLogIsExit3InEveryCommand) {
  ASSERT_NO_FATAL_FAILURE(calibrate());
  const std::string target = test::source_path("config/checkerboard-7x6.yaml");
  const std::vector<Args> commands = {
      {"info", "@"},
      {"calibrate", "static", "@", "-o", work_ + "/static.yaml"},
      {"calibrate", "gsens", "@", "-o", work_ + "/gsens.yaml"},
      {"calibrate", "camera", "@", "--target", target, "-o", work_ + "/camera.yaml"},
      {"calibrate", "check", "@", "--calibration", calibration_},
      {"allan", "@", "-o", work_ + "/allan.yaml"},
      {"export", "euroc", "@", work_ + "/export"},
      {"replay", "@", "-o", work_ + "/replay"},
      {"report", result_, "--log", "@", "-o", work_ + "/report.html"},
  };
  for (const std::string& input : {missing_, folder_, fifo_, text_, empty_}) {
    for (const Args& command : commands) expect_exit(with(command, input), 3, input);
  }
  EXPECT_THAT(outputs(), ::testing::IsEmpty());
}

TEST_F(CliExitCodes, AnUnusableInputFileIsExit3InEveryCommand) {
  const std::string target = test::source_path("config/checkerboard-7x6.yaml");
  const std::vector<Args> commands = {
      {"calibrate", "camimu", log_, "--camera", "@", "-o", work_ + "/camimu"},
      {"calibrate", "camera", log_, "--target", "@", "-o", work_ + "/camera.yaml"},
      {"calibrate", "check", log_, "--calibration", "@"},
      {"calibrate", "static", log_, "--gsens", "fix", "@", "-o", work_ + "/static.yaml"},
      {"calibrate", "gsens", log_, "--imu-intrinsics", "@", "-o", work_ + "/gsens.yaml"},
      {"import", "csv", "@", "--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6", "--units", "si", "-o",
       work_ + "/csv.imulog"},
      {"import", "ascii", "--accel", "@", "--gyro", text_, "--units", "si", "-o", work_ + "/ascii.imulog"},
      {"import", "euroc", "@", "-o", work_ + "/euroc.imulog"},
      {"report", "@", "-o", work_ + "/report.html"},
      {"sim", "static", "--seed", "1", "--truth", "@", "-o", work_ + "/sim.imulog"},
      {"sim", "camimu", "--seed", "1", "--target", "@", "-o", work_ + "/sim.imulog"},
      {"record", "--sim", "--config", "@", "-o", work_ + "/record.imulog"},
      {"config", "check", "@"},
  };
  for (const std::string& input : {missing_, folder_, fifo_}) {
    for (const Args& command : commands) expect_exit(with(command, input), 3, input);
  }
  EXPECT_THAT(outputs(), ::testing::IsEmpty());
}

TEST_F(CliExitCodes, AnOutputThatExistsIsExit2AndKept) {
  ASSERT_NO_FATAL_FAILURE(calibrate());
  const std::string existing = work_ + "/existing";
  const std::vector<Args> commands = {
      {"calibrate", "static", log_, "-o", "@"},
      {"calibrate", "gsens", log_, "-o", "@"},
      {"allan", still_, "-o", "@"},
      {"import", "csv", csv_, "--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6", "--units", "si", "-o", "@"},
      {"export", "euroc", log_, "@"},
      {"report", result_, "-o", "@"},
      {"sim", "still", "--seed", "1", "--duration", "2", "-o", "@"},
      {"record", "--sim", "--config", test::source_path("config/rig.yaml"), "--duration", "1", "-o", "@"},
  };
  for (const Args& command : commands) {
    std::ofstream(existing) << "keep me\n";
    auto r = test::run_cli(with(command, existing), kRunLimitS);
    EXPECT_EQ(r.exit_code, 2) << joined(command) << "\n" << r.err;
    EXPECT_EQ(test::read_file(existing), "keep me\n") << joined(command);
  }
}

TEST_F(CliExitCodes, AnOutputInAFolderThatDoesNotExistIsExit7) {
  const std::string nowhere = work_ + "/no-such-folder/out";
  const std::vector<Args> commands = {
      {"calibrate", "static", log_, "-o", "@"},
      {"allan", still_, "-o", "@"},
      {"import", "csv", csv_, "--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6", "--units", "si", "-o", "@"},
      {"export", "euroc", log_, "@"},
      {"sim", "still", "--seed", "1", "--duration", "2", "-o", "@"},
  };
  for (const Args& command : commands) expect_exit(with(command, nowhere), 7, nowhere);
  EXPECT_FALSE(fs::exists(work_ + "/no-such-folder"));
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

/// The codes of the exit code table in docs/cli.md ("| code | meaning |").
std::vector<int> documented_codes() {
  const std::string doc = test::read_file(test::source_path("docs/cli.md"));
  std::vector<int> codes;
  const auto table = doc.find("| code | meaning |");
  if (table == std::string::npos) return codes;
  std::istringstream lines(doc.substr(table));
  std::string line;
  std::getline(lines, line);  // header
  std::getline(lines, line);  // |---|---|
  while (std::getline(lines, line) && line.rfind("| ", 0) == 0) codes.push_back(std::stoi(line.substr(2)));
  return codes;
}

// The table of docs/cli.md walked: every documented code is produced by at least one case, each
// case by the code the table gives it, and no case but the documented incomplete installation
// exits 1 ("unexpected").
TEST_F(CliExitCodes, EveryDocumentedCodeIsProducedByACase) {
  const std::vector<int> codes = documented_codes();
  ASSERT_EQ(codes, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7})) << "docs/cli.md's exit code table changed";
  const std::string no_modules = work_ + "/no-modules";
  fs::create_directories(no_modules);
  // A replay whose live session logged no result: the replay differs.
  const std::string session = test::copy_fixture("service-session.imulog", work_);
  ASSERT_TRUE(test::run_sql(session, "delete from events where json_extract(message,'$.type')='result'"));
  struct Case {
    int code;
    Args args;
    const char* module_dir = nullptr;  // IMUCAL_MODULE_DIR for the run
  };
  const std::vector<Case> cases = {
      {0, {"info", log_}},
      {1, {"calibrate", "static", log_, "-o", work_ + "/m.yaml"}, no_modules.c_str()},
      {2, {"info"}},
      {2, {"info", log_, "--no-such-option"}},
      {3, {"info", missing_}},
      {4, {"calibrate", "static", still_, "-o", work_ + "/still.yaml"}},
      {5, {"replay", session, "-o", work_ + "/replay"}},
      {6,
       {"record", "--config", test::source_path("config/rig-spi-example.yaml"), "-o", work_ + "/r.imulog",
        "--duration", "1"}},
      {7, {"calibrate", "static", log_, "-o", work_ + "/no/such/folder/x.yaml"}},
  };
  std::vector<int> produced;
  for (const Case& c : cases) {
    if (c.module_dir) ::setenv("IMUCAL_MODULE_DIR", c.module_dir, 1);
    const auto r = test::run_cli(c.args, kRunLimitS);
    if (c.module_dir) ::unsetenv("IMUCAL_MODULE_DIR");
    EXPECT_EQ(r.exit_code, c.code) << joined(c.args) << "\n" << r.err;
    EXPECT_THAT(r.err, ::testing::Not(HasSubstr("unexpected error"))) << joined(c.args);
    if (c.code == 1) {
      EXPECT_THAT(r.err, HasSubstr("libimucal_solve.so")) << r.err;
    }
    produced.push_back(r.exit_code);
  }
  for (int code : codes)
    EXPECT_NE(std::find(produced.begin(), produced.end(), code), produced.end()) << "no case exits " << code;
}

// A typo said "A subcommand is required" and nothing else.
TEST(CliUnknownCommand, AMistypedCommandNamesTheNearestOneAtEachLevel) {
  const auto top = test::run_cli({"calibrat"});
  EXPECT_EQ(top.exit_code, 2) << top.err;
  EXPECT_NE(top.err.find("unknown command 'calibrat'; did you mean 'calibrate'?"), std::string::npos)
      << top.err;
  const auto nested = test::run_cli({"calibrate", "statc"});
  EXPECT_EQ(nested.exit_code, 2) << nested.err;
  EXPECT_NE(nested.err.find("did you mean 'static'?"), std::string::npos) << nested.err;
  const auto far = test::run_cli({"frobnicate"});
  EXPECT_EQ(far.exit_code, 2) << far.err;
  EXPECT_EQ(far.err.find("did you mean"), std::string::npos) << far.err;
  EXPECT_NE(far.err.find("unknown command 'frobnicate'"), std::string::npos) << far.err;
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

/// The example lines ("  imucal ...") of a help text's "Examples:" block: each names a command
/// that exists and only options that command's own help lists (a renamed command or option fails
/// here, not in a user's shell). Returns the examples' commands.
std::vector<std::vector<std::string>> check_examples(const std::string& help, const std::string& where) {
  std::vector<std::vector<std::string>> commands;
  const std::size_t at = help.find("Examples:\n");
  if (at == std::string::npos) {
    ADD_FAILURE() << where << ": no examples\n" << help;
    return commands;
  }
  std::istringstream lines(help.substr(at + 10));
  std::string line;
  while (std::getline(lines, line) && line.rfind("  imucal ", 0) == 0) {
    std::istringstream words(line.substr(0, line.find('#')));
    std::string word;
    words >> word;  // "imucal"
    std::vector<std::string> command, options;
    while (words >> word) {
      if (word.rfind("-", 0) == 0) {
        options.push_back(word);
      } else if (options.empty() && word.find('.') == std::string::npos &&
                 word.find('/') == std::string::npos) {
        command.push_back(word);  // a subcommand: before any option, not a file name
      }
    }
    commands.push_back(command);
    std::vector<std::string> args = command;
    args.push_back("--help");
    const auto sub = test::run_cli(args);
    EXPECT_EQ(sub.exit_code, 0) << where << ": " << line << "\n" << sub.err;
    // As the help lists an option: "  -o,--output TEXT", "  --duration FLOAT".
    const auto listed = [&](const std::string& o) {
      return sub.out.find(" " + o + ",") != std::string::npos ||
             sub.out.find(" " + o + " ") != std::string::npos ||
             sub.out.find("," + o + " ") != std::string::npos;
    };
    for (const auto& o : options)
      EXPECT_TRUE(listed(o)) << where << ": " << line << ": " << o << " is not an option of that command";
  }
  return commands;
}

/// The subcommands a help text lists under "Subcommands:".
std::vector<std::string> subcommands_of(const std::string& help) {
  std::vector<std::string> names;
  const std::size_t at = help.find("Subcommands:\n");
  if (at == std::string::npos) return names;
  std::istringstream lines(help.substr(at + 13));
  std::string line;
  while (std::getline(lines, line) && line.rfind("  ", 0) == 0) {
    if (line.size() > 2 && line[2] != ' ') names.push_back(line.substr(2, line.find(' ', 2) - 2));
  }
  return names;
}

// `imucal --help` ends with examples of the commands a newcomer starts with.
TEST(CliHelp, TheExamplesOfImucalsHelpNameRealCommandsAndOptions) {
  const auto help = test::run_cli({"--help"});
  ASSERT_EQ(help.exit_code, 0) << help.err;
  EXPECT_GE(check_examples(help.out, "imucal --help").size(), 5u) << help.out;
}

// Every command's own --help ends with examples of that command (not only the root's), and
// every example runs as written as far as its command and options go. Before, 23 of the 24
// commands had no example of themselves (most showed the root's, whose first, `imucal sim static
// -o static.imulog`, failed: --seed was required).
TEST(CliHelp, EveryCommandsHelpHasExamplesOfItselfThatNameRealOptions) {
  std::vector<std::vector<std::string>> pending = {{}};
  int leaves = 0;
  while (!pending.empty()) {
    const std::vector<std::string> path = pending.back();
    pending.pop_back();
    std::vector<std::string> args = path;
    args.push_back("--help");
    const auto help = test::run_cli(args);
    ASSERT_EQ(help.exit_code, 0) << help.err;
    const auto subs = subcommands_of(help.out);
    for (const auto& sub : subs) {
      auto next = path;
      next.push_back(sub);
      pending.push_back(next);
    }
    if (!subs.empty()) continue;
    ++leaves;
    std::string name;
    for (const auto& w : path) name += (name.empty() ? "" : " ") + w;
    const auto commands = check_examples(help.out, "imucal " + name + " --help");
    EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [&](const auto& c) { return c == path; }))
        << "imucal " << name << " --help has no example of itself:\n"
        << help.out;
  }
  EXPECT_EQ(leaves, 27);  // import bag and rosbag2, export bag among them
  // The root's first example, run as written: the virtual rig's recording needs no seed.
  const std::string dir = test::scratch_dir();
  const auto sim = test::run_cli({"sim", "static", "-o", dir + "/static.imulog"});
  EXPECT_EQ(sim.exit_code, 0) << sim.err;
}

}  // namespace
}  // namespace imucal
