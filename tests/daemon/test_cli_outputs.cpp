// SPDX-License-Identifier: BSD-3-Clause
// No output of a command may name any of its inputs, whatever --force says, nor another of its
// outputs; and no command replaces a device, FIFO or socket. Each case is refused before any work,
// with exit 2 and a message that says what to do, and the input is left byte for byte.

#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using test::read_file;
using test::run_cli;

struct Case {
  std::vector<std::string> args;
  std::string input;    // must be left as it was
  std::string message;  // in the refusal
};

// Before: `calibrate thermal --scale-from P -o P --force` turned the session log P into YAML,
// `calibrate static --thermal T -o T` and `--gsens fix G -o G` replaced their inputs, `-o X
// --json X` kept only the JSON, and `import` and `record` wrote their log over a file they read.
TEST(CliOutputs, NoOutputNamesAnInputOrAnotherOutputWhateverForceSays) {
  const std::string dir = test::scratch_dir();
  const std::string still = test::copy_fixture("still.imulog", dir);
  fs::create_directories(dir + "/p");
  const std::string poses = test::copy_fixture("static.imulog", dir + "/p");
  const std::string thermal = dir + "/thermal.yaml";
  test::write_file(thermal, "thermal model: kept\n");
  const std::string gsens = dir + "/gsens.yaml";
  test::write_file(gsens, "G: kept\n");
  const std::string accel = dir + "/acc.txt";
  test::write_file(accel, "0 0 0 9.81\n0.01 0 0 9.81\n");
  const std::string gyro = dir + "/gyro.txt";
  test::write_file(gyro, "0 0 0 0\n0.01 0 0 0\n");
  const std::string csv = dir + "/imu.csv";
  test::write_file(csv, "0,0,0,9.81,0,0,0\n0.01,0,0,9.81,0,0,0\n");
  const std::string rig = dir + "/rig.yaml";
  test::write_file(rig, "name: kept\n");
  const std::string out = dir + "/out.yaml";
  const std::string input_rule =
      "is an input of this command; write the result to another file (--force never";

  const std::vector<Case> cases = {
      {{"calibrate", "thermal", still, "--scale-from", poses, "-o", poses, "--force"}, poses, input_rule},
      {{"calibrate", "static", poses, "--thermal", thermal, "-o", thermal, "--force"}, thermal, input_rule},
      {{"calibrate", "static", poses, "--gsens", "fix", gsens, "--json", gsens, "--force"},
       gsens,
       input_rule},
      {{"calibrate", "static", poses, "--gsens", "fix", gsens, "-o", gsens, "--force"}, gsens, input_rule},
      {{"calibrate", "static", poses, "-o", out, "--json", out}, poses, "-o and --json name the same file"},
      {{"calibrate", "static", poses, "-o", out, "--json", dir + "/./out.yaml"}, poses, "name the same file"},
      {{"calibrate", "gsens", poses, "-o", out, "--json", out}, poses, "-o and --json name the same file"},
      {{"allan", still, "-o", out, "--json", out, "--allow-motion"},
       still,
       "-o and --json name the same file"},
      {{"import", "ascii", "--accel", accel, "--gyro", gyro, "--units", "si", "-o", accel, "--force"},
       accel,
       input_rule},
      {{"import", "csv", csv, "--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6", "--units", "si", "-o", csv,
        "--force"},
       csv,
       input_rule},
      {{"export", "euroc", poses, dir + "/p", "--force"}, poses, "holds " + poses},
      {{"record", "--config", rig, "--sim", "-o", rig, "--force"}, rig, input_rule},
  };
  for (const Case& c : cases) {
    const std::string before = read_file(c.input);
    ASSERT_FALSE(before.empty()) << c.input;
    auto r = run_cli(c.args);
    std::string line;
    for (const auto& a : c.args) line += a + " ";
    EXPECT_EQ(r.exit_code, 2) << line << "\n" << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << line << "\n" << r.err;
    EXPECT_TRUE(read_file(c.input) == before) << line << ": the input was changed";
    EXPECT_FALSE(fs::exists(out)) << line;
  }
}

// Before: with --force, `sim` replaced a FIFO at LOG.truth.yaml (exit 0), and a --truth input
// named LOG.truth.yaml was replaced by the new truth.
TEST(CliOutputs, SimNeverReplacesAFifoOrItsTruthInput) {
  const std::string dir = test::scratch_dir();
  const std::string fifo = dir + "/a.truth.yaml";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto r = run_cli({"sim", "still", "--seed", "1", "--duration", "2", "-o", dir + "/a.imulog", "--force"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(fifo + " exists and is not a regular file"), std::string::npos) << r.err;
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  EXPECT_FALSE(fs::exists(dir + "/a.imulog"));

  // A socket, and a device node (root only), at LOG.truth.yaml: the same refusal.
  char short_dir[] = "/tmp/imucal-sim-XXXXXX";  // sun_path holds 107 bytes: the scratch folder is deeper
  ASSERT_NE(::mkdtemp(short_dir), nullptr);
  const std::string socket_path = std::string(short_dir) + "/s.truth.yaml";
  const int sock = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(sock, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", socket_path.c_str());
  ASSERT_EQ(::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0) << std::strerror(errno);
  std::vector<std::string> specials = {socket_path};
  const std::string device = dir + "/d.truth.yaml";
  if (::mknod(device.c_str(), S_IFCHR | 0600, makedev(1, 3)) == 0) {  // /dev/null's numbers
    specials.push_back(device);
  } else {
    std::printf("device-node case not run: mknod needs root (%s)\n", std::strerror(errno));
  }
  for (const std::string& special : specials) {
    const std::string log = special.substr(0, special.size() - std::string(".truth.yaml").size()) + ".imulog";
    r = run_cli({"sim", "still", "--seed", "1", "--duration", "2", "-o", log, "--force"});
    EXPECT_EQ(r.exit_code, 2) << special << ": " << r.err;
    EXPECT_NE(r.err.find(special + " exists and is not a regular file"), std::string::npos) << r.err;
    struct stat sst {};
    ASSERT_EQ(::lstat(special.c_str(), &sst), 0);
    EXPECT_TRUE(S_ISSOCK(sst.st_mode) || S_ISCHR(sst.st_mode)) << special << " was replaced";
    EXPECT_FALSE(fs::exists(log));
  }
  ::close(sock);
  fs::remove_all(short_dir);

  const std::string truth = dir + "/b.truth.yaml";
  fs::copy_file(test::source_path("fixtures/still.truth.yaml"), truth);
  const std::string before = read_file(truth);
  r = run_cli({"sim", "still", "--seed", "1", "--duration", "2", "--truth", truth, "-o", dir + "/b.imulog",
               "--force"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is an input of this command"), std::string::npos) << r.err;
  EXPECT_TRUE(read_file(truth) == before);
  EXPECT_FALSE(fs::exists(dir + "/b.imulog"));
}

}  // namespace
}  // namespace imucal
