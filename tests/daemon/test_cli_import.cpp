// SPDX-License-Identifier: BSD-3-Clause
#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "daemon/cli/command.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

void write(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

/// Static MPU-6000 at +-2 g / +-250 dps, 200 Hz, imu_tk-style files.
void write_ascii(const fs::path& dir, bool si) {
  std::string acc, gyr;
  for (int i = 0; i < 400; ++i) {
    const double t = 0.005 * i;
    char buf[128];
    if (si) {
      std::snprintf(buf, sizeof buf, "%.3f %.5f %.5f %.5f\n", t, 0.01 * (i % 3), -0.02, 9.81);
    } else {
      std::snprintf(buf, sizeof buf, "%.3f %d %d %d\n", t, 10 + i % 3, -20, 16384 + i % 4);
    }
    acc += buf;
    std::snprintf(buf, sizeof buf, si ? "%.3f 0.001 0.002 0.003\n" : "%.3f -5 6 7\n", t);
    gyr += buf;
  }
  write(dir / "acc.txt", acc);
  write(dir / "gyr.txt", gyr);
}

TEST(CliImport, AsciiRawAndSi) {
  const fs::path dir = test::scratch_dir();
  write_ascii(dir / "raw", false);
  auto raw =
      test::run_cli({"import", "ascii", "--accel", (dir / "raw/acc.txt").string(), "--gyro",
                     (dir / "raw/gyr.txt").string(), "--units", "raw", "--accel-scale",
                     "0.0006,0.0006,0.0006", "--gyro-offset=-5,6,7", "-o", (dir / "raw.imulog").string()});
  ASSERT_EQ(raw.exit_code, 0) << raw.err;
  EXPECT_THAT(raw.out, HasSubstr("imported 400 IMU samples (200 Hz"));
  EXPECT_THAT(raw.out, HasSubstr("raw counts kept"));
  auto reader = log::SessionLogReader::open((dir / "raw.imulog").string());
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  const ImuStreamInfo& info = (*reader)->imu_streams().begin()->second;
  EXPECT_EQ(info.units, ImuUnits::kRaw);
  EXPECT_EQ(info.accel.scale, Eigen::Vector3d::Constant(0.0006));
  EXPECT_EQ(info.gyro.offset, Eigen::Vector3d(-5, 6, 7));

  write_ascii(dir / "si", true);
  auto si =
      test::run_cli({"import", "ascii", "--accel", (dir / "si/acc.txt").string(), "--gyro",
                     (dir / "si/gyr.txt").string(), "--units", "si", "-o", (dir / "si.imulog").string()});
  ASSERT_EQ(si.exit_code, 0) << si.err;

  // The same SI files declared raw: refused, naming the flag.
  auto wrong =
      test::run_cli({"import", "ascii", "--accel", (dir / "si/acc.txt").string(), "--gyro",
                     (dir / "si/gyr.txt").string(), "--units", "raw", "-o", (dir / "w.imulog").string()});
  EXPECT_EQ(wrong.exit_code, cli::kExitInput);
  EXPECT_THAT(wrong.err, HasSubstr("--units si"));
  EXPECT_FALSE(fs::exists(dir / "w.imulog"));
}

// An output path that is not a regular file (here a FIFO; a device node the same) is never
// replaced, --force or not, by any command that writes; and a log that a recorder is writing
// (its writer's lock held) is not replaced by an import.
TEST(CliImport, OutputsThatAreNotFilesOrAreLiveLogsAreRefused) {
  const fs::path dir = test::scratch_dir();
  write_ascii(dir / "si", true);
  const std::string fifo = (dir / "fifo").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  const std::vector<std::string> ascii = {
      "import",  "ascii", "--accel", (dir / "si/acc.txt").string(), "--gyro", (dir / "si/gyr.txt").string(),
      "--units", "si"};
  auto with = [](std::vector<std::string> args, std::initializer_list<std::string> more) {
    args.insert(args.end(), more);
    return args;
  };
  for (const auto& args :
       {with(ascii, {"-o", fifo, "--force"}),
        std::vector<std::string>{"sim", "still", "--seed", "3", "--duration", "1", "-o", fifo, "--force"}}) {
    const auto r = test::run_cli(args);
    EXPECT_EQ(r.exit_code, cli::kExitUsage) << args[0] << " " << args[1] << ": " << r.err;
    EXPECT_THAT(r.err, HasSubstr("not a regular file"));
    struct stat st {};
    ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
    EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced by " << args[0] << " " << args[1];
  }
  // A result file (calibrate static's -o goes through the same check as every result writer).
  const std::string log = (dir / "a.imulog").string();
  ASSERT_EQ(test::run_cli(with(ascii, {"-o", log})).exit_code, 0);
  auto r = test::run_cli({"calibrate", "static", log, "-o", fifo, "--force"});
  EXPECT_EQ(r.exit_code, cli::kExitUsage) << r.err;
  EXPECT_THAT(r.err, HasSubstr("not a regular file"));

  // A live log: a child holds the writer's lock (as `record` does) while import is asked to
  // replace it with --force.
  const std::string before = test::read_file(log);
  {
    const test::WriterLockHolder writer(log);
    ASSERT_TRUE(writer.held());
    r = test::run_cli(with(ascii, {"-o", log, "--force"}));
  }
  EXPECT_EQ(r.exit_code, cli::kExitIo) << r.err;
  EXPECT_THAT(r.err, HasSubstr("is being written by process"));
  EXPECT_EQ(test::read_file(log), before) << "the live log was replaced";
}

TEST(CliImport, CsvAndOverwriteRefusal) {
  const fs::path dir = test::scratch_dir();
  std::string csv = "t_ns\tgx\tgy\tgz\tax\tay\taz\n";
  for (int i = 0; i < 100; ++i) {
    csv += std::to_string(5'000'000LL * i) + "\t0.01\t0.02\t0.03\t0.1\t0.2\t9.8\n";
  }
  write(dir / "d.tsv", csv);
  const std::vector<std::string> args = {"import",
                                         "csv",
                                         (dir / "d.tsv").string(),
                                         "--columns",
                                         "t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6",
                                         "--time-unit",
                                         "ns",
                                         "--delimiter",
                                         "tab",
                                         "--skip-header",
                                         "1",
                                         "--units",
                                         "si",
                                         "-o",
                                         (dir / "d.imulog").string()};
  auto r = test::run_cli(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("imported 100 IMU samples (200 Hz"));
  const std::string before = test::read_file((dir / "d.imulog").string());
  auto again = test::run_cli(args);
  EXPECT_EQ(again.exit_code, cli::kExitUsage);
  EXPECT_THAT(again.err, HasSubstr("already exists; pass --force"));
  EXPECT_EQ(test::read_file((dir / "d.imulog").string()), before);
  auto forced_args = args;
  forced_args.push_back("--force");
  EXPECT_EQ(test::run_cli(forced_args).exit_code, 0);

  write(dir / "bad.csv", "0,1,2,3,4,5,6\n0.005,1,2,3,4,5,6\n0.01,1,2,3,4,5\n");
  auto bad = test::run_cli({"import", "csv", (dir / "bad.csv").string(), "--columns",
                            "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6", "--units", "raw", "-o",
                            (dir / "b.imulog").string()});
  EXPECT_EQ(bad.exit_code, cli::kExitInput);
  EXPECT_THAT(bad.err, HasSubstr("bad.csv:3: has 6 columns"));
  EXPECT_FALSE(fs::exists(dir / "b.imulog"));
  for (const auto& e : fs::directory_iterator(dir)) {
    EXPECT_EQ(e.path().filename().string().find(".partial-"), std::string::npos) << e.path();
  }
}

TEST(CliImport, EurocRoundTripThroughTheCli) {
  const fs::path dir = test::scratch_dir();
  std::string csv =
      "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
      "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
  for (int i = 0; i < 50; ++i) {
    csv += std::to_string(1'000'000'000LL + 5'000'000LL * i) + ",0.1,-0.2,0.30000000000000004,1e-3,2.5," +
           std::to_string(9.80665 + 1e-5 * i) + "\n";
  }
  write(dir / "in/mav0/imu0/data.csv", csv);
  auto imp = test::run_cli({"import", "euroc", (dir / "in").string(), "-o", (dir / "a.imulog").string()});
  ASSERT_EQ(imp.exit_code, 0) << imp.err;
  auto exp = test::run_cli({"export", "euroc", (dir / "a.imulog").string(), (dir / "out").string()});
  ASSERT_EQ(exp.exit_code, 0) << exp.err;
  EXPECT_THAT(exp.out, HasSubstr("exported 50 IMU samples"));
  const std::string exported = test::read_file((dir / "out/mav0/imu0/data.csv").string());
  EXPECT_THAT(exported, HasSubstr("1000000000,0.1,-0.2,0.30000000000000004,0.001,2.5,"));
  auto exp2 = test::run_cli({"export", "euroc", (dir / "a.imulog").string(), (dir / "out").string()});
  EXPECT_EQ(exp2.exit_code, cli::kExitUsage);
  EXPECT_THAT(exp2.err, HasSubstr("--force"));
  // --force replaces an earlier export, never a dataset from elsewhere (here the input folder
  // with a ground-truth folder beside the IMU's).
  exp2 = test::run_cli({"export", "euroc", (dir / "a.imulog").string(), (dir / "out").string(), "--force"});
  EXPECT_EQ(exp2.exit_code, 0) << exp2.err;
  write(dir / "in/mav0/state_groundtruth_estimate0/data.csv", "#timestamp\n1\n");
  auto downloaded =
      test::run_cli({"export", "euroc", (dir / "a.imulog").string(), (dir / "in").string(), "--force"});
  EXPECT_EQ(downloaded.exit_code, cli::kExitUsage) << downloaded.err;
  EXPECT_THAT(downloaded.err, HasSubstr("not an earlier imucal export"));
  EXPECT_TRUE(fs::exists(dir / "in/mav0/state_groundtruth_estimate0/data.csv"));
  EXPECT_TRUE(fs::exists(dir / "in/mav0/imu0/data.csv"));
  auto missing =
      test::run_cli({"import", "euroc", (dir / "nope").string(), "-o", (dir / "n.imulog").string()});
  EXPECT_EQ(missing.exit_code, cli::kExitInput);
  EXPECT_THAT(missing.err, HasSubstr("not a folder"));
}

TEST(CliImport, UsageErrors) {
  const fs::path dir = test::scratch_dir();
  write_ascii(dir, false);
  auto r = test::run_cli({"import", "ascii", "--accel", (dir / "acc.txt").string(), "--gyro",
                          (dir / "gyr.txt").string(), "--units", "raw", "--accel-scale", "1,2", "-o",
                          (dir / "x.imulog").string()});
  EXPECT_EQ(r.exit_code, cli::kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--accel-scale"));
  auto cols = test::run_cli({"import", "csv", (dir / "acc.txt").string(), "--columns", "t=0,ax=1", "--units",
                             "raw", "-o", (dir / "x.imulog").string()});
  EXPECT_EQ(cols.exit_code, cli::kExitUsage);
  EXPECT_THAT(cols.err, HasSubstr("--columns"));
}

// Hostile inputs end in a message and the documented exit code, never "unexpected error".
TEST(CliImport, HostileInputsAreRefusedWithAMessage) {
  const fs::path dir = test::scratch_dir();
  write_ascii(dir, false);
  const std::string acc = (dir / "acc.txt").string(), gyr = (dir / "gyr.txt").string();
  const std::string out = (dir / "x.imulog").string();
  // An empty option value is a mistake, not "the default".
  auto empty = test::run_cli(
      {"import", "ascii", "--accel", acc, "--gyro", gyr, "--units", "raw", "--accel-scale", "", "-o", out});
  EXPECT_EQ(empty.exit_code, cli::kExitUsage) << empty.err;
  EXPECT_THAT(empty.err, HasSubstr("empty value"));
  // Numbers that are not finite, with a short message.
  auto nan = test::run_cli({"import", "csv", acc, "--columns", "t=0,ax=1,ay=2,az=3,gx=1,gy=2,gz=3,temp=1",
                            "--delimiter", "space", "--units", "raw", "--temp-scale", "nan", "-o", out});
  EXPECT_EQ(nan.exit_code, cli::kExitUsage) << nan.err;
  EXPECT_THAT(nan.err, HasSubstr("'nan' is not a finite number"));
  auto huge_rate = test::run_cli(
      {"import", "ascii", "--accel", acc, "--gyro", gyr, "--units", "raw", "--rate", "1e309", "-o", out});
  EXPECT_EQ(huge_rate.exit_code, cli::kExitUsage);
  EXPECT_LT(huge_rate.err.size(), 200u) << huge_rate.err;
  // A 1 MB token in a row: named, not echoed whole.
  write(dir / "long.txt", "0 " + std::string(1 << 20, 'x') + " 0 9.8\n");
  auto token = test::run_cli({"import", "ascii", "--accel", (dir / "long.txt").string(), "--gyro", gyr,
                              "--units", "raw", "-o", out});
  EXPECT_EQ(token.exit_code, cli::kExitInput);
  EXPECT_THAT(token.err, HasSubstr("long.txt:1"));
  EXPECT_LT(token.err.size(), 400u);
  // EuRoC: a sensor folder number no index holds, and an image that is a folder.
  const std::string imu_csv = "#t\n1000,0,0,0,0,0,9.8\n2000,0,0,0,0,0,9.8\n";
  write(dir / "big/mav0/imu0/data.csv", imu_csv);
  write(dir / "big/mav0/cam99999999999999999999/data.csv", "#t,f\n");
  auto big = test::run_cli({"import", "euroc", (dir / "big").string(), "-o", out});
  EXPECT_EQ(big.exit_code, cli::kExitInput) << big.err;
  EXPECT_THAT(big.err, HasSubstr("too large for a EuRoC sensor folder"));
  write(dir / "dirimg/mav0/imu0/data.csv", imu_csv);
  write(dir / "dirimg/mav0/cam0/data.csv", "#t,f\n1000,x.png\n");
  fs::create_directories(dir / "dirimg/mav0/cam0/data/x.png");
  auto dirimg = test::run_cli({"import", "euroc", (dir / "dirimg").string(), "-o", out});
  EXPECT_EQ(dirimg.exit_code, cli::kExitInput) << dirimg.err;
  EXPECT_THAT(dirimg.err, HasSubstr("is a folder, expected a file"));
  // Text that is not UTF-8 (a Latin-1 sensor.yaml) is kept as it is in the log; JSON output
  // shows it with U+FFFD instead of failing.
  write(dir / "latin1/mav0/imu0/data.csv", imu_csv);
  write(dir / "latin1/mav0/imu0/sensor.yaml", "sensor_type: imu\ncomment: \"caf\xe9\"\nrate_hz: 200\n");
  const std::string latin1_log = (dir / "latin1.imulog").string();
  auto latin1 = test::run_cli({"import", "euroc", (dir / "latin1").string(), "-o", latin1_log});
  ASSERT_EQ(latin1.exit_code, 0) << latin1.err;
  auto json_info = test::run_cli({"info", "--json", latin1_log});
  EXPECT_EQ(json_info.exit_code, 0) << json_info.err;
  EXPECT_THAT(json_info.out, HasSubstr("caf\xef\xbf\xbd"));
  // Timestamps beyond 2^62 ns (where differences of two could overflow) are refused.
  write(dir / "far.txt", "9223372036.8 0 0 9.8\n9223372036.9 0 0 9.8\n");
  auto far = test::run_cli({"import", "ascii", "--accel", (dir / "far.txt").string(), "--gyro",
                            (dir / "far.txt").string(), "--units", "si", "-o", out});
  EXPECT_EQ(far.exit_code, cli::kExitInput);
  EXPECT_THAT(far.err, HasSubstr("beyond 146 years"));
  EXPECT_FALSE(fs::exists(out));
}

// What a EuRoC folder says is checked before it enters a log: a PNG cut short (its header
// intact) would be stored with a checksum of its damaged bytes and pass every later check; a
// rate of 1e308 Hz is no sensor's; a data.csv without rows is an empty input (exit 3, as
// docs/cli.md's table says).
TEST(CliImport, EurocDamageIsRefusedBeforeItEntersTheLog) {
  const fs::path dir = test::scratch_dir();
  const std::string imu_csv = "#t\n1000,0,0,0,0,0,9.8\n2000,0,0,0,0,0,9.8\n3000,0,0,0,0,0,9.8\n";
  log::Image image{64, 48, 1, 8, std::vector<std::uint8_t>(64 * 48)};
  std::uint32_t state = 12345;  // noise, so that the PNG is far longer than its header
  for (auto& v : image.data) v = static_cast<std::uint8_t>((state = state * 1664525u + 1013904223u) >> 24);
  auto png = log::encode_png(image);
  ASSERT_TRUE(png.ok());
  const std::string whole(png->begin(), png->end());
  ASSERT_GT(whole.size(), 200u);
  auto make = [&](const std::string& name, const std::string& image_bytes, const std::string& sensor_yaml,
                  const std::string& csv) {
    write(dir / name / "mav0/imu0/data.csv", csv);
    if (!sensor_yaml.empty()) write(dir / name / "mav0/imu0/sensor.yaml", sensor_yaml);
    write(dir / name / "mav0/cam0/data.csv", "#t,f\n1000,a.png\n2000,b.png\n");
    write(dir / name / "mav0/cam0/data/a.png", whole);
    write(dir / name / "mav0/cam0/data/b.png", image_bytes);
    return (dir / name).string();
  };
  const std::string out = (dir / "x.imulog").string();
  const std::string sound = make("sound", whole, "rate_hz: 200\n", imu_csv);
  auto ok = test::run_cli({"import", "euroc", sound, "-o", out});
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  fs::remove(out);
  struct Case {
    std::string folder, message;
  };
  for (const Case& c : {Case{make("cut", whole.substr(0, 100), "", imu_csv), "b.png is a damaged PNG"},
                        Case{make("fast", whole, "rate_hz: 1e308\n", imu_csv), "is above 100 kHz"},
                        Case{make("empty", whole, "", "#t,wx,wy,wz,ax,ay,az\n"), "no data rows"}}) {
    auto r = test::run_cli({"import", "euroc", c.folder, "-o", out});
    EXPECT_EQ(r.exit_code, cli::kExitInput) << c.folder << ": " << r.err;
    EXPECT_THAT(r.err, HasSubstr(c.message)) << c.folder;
    EXPECT_FALSE(fs::exists(out)) << c.folder;
  }
}

// A read error in the middle of an input (a failing disk, here an LD_PRELOAD shim returning EIO
// after 3000 bytes) fails the import instead of ending it early as if the file ended there.
TEST(CliImport, AReadErrorInTheMiddleOfAnInputFailsTheImport) {
  const fs::path dir = test::scratch_dir();
  write_ascii(dir, true);
  ASSERT_GT(fs::file_size(dir / "acc.txt"), 6000u);
  const std::string out = (dir / "x.imulog").string();
  const std::string cmd = std::string("IMUCAL_EIO_PATH=/acc.txt IMUCAL_EIO_AFTER=3000 ") +
                          "ASAN_OPTIONS=verify_asan_link_order=0 LD_PRELOAD=" + IMUCAL_EIO_SHIM + " " +
                          IMUCAL_CLI_PATH + " import ascii --units si --accel " + (dir / "acc.txt").string() +
                          " --gyro " + (dir / "gyr.txt").string() + " -o " + out + " 2> " +
                          (dir / "err.txt").string();
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  const std::string err = test::read_file((dir / "err.txt").string());
  EXPECT_EQ(WEXITSTATUS(status), cli::kExitInput) << err;
  EXPECT_THAT(err, HasSubstr("Input/output error"));
  EXPECT_THAT(err, HasSubstr("after 3000 bytes"));
  EXPECT_FALSE(fs::exists(out));
  // The same command without the fault imports every row.
  auto ok = test::run_cli({"import", "ascii", "--units", "si", "--accel", (dir / "acc.txt").string(),
                           "--gyro", (dir / "gyr.txt").string(), "-o", out});
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
}

}  // namespace
}  // namespace imucal
