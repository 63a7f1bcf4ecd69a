// SPDX-License-Identifier: BSD-3-Clause
// Real recordings from other people's IMUs (../shared/data, beside the repository; absent in a
// user's clone, where these tests skip and say why). The static calibration is judged against
// the peer it follows, imu_tk, by `calibrate check` on one fixed set of poses and motions.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using test::run_cli;

std::string xsens_dir() { return test::source_path("../shared/data/xsens_mti"); }

/// imu_tk's result on the same recording (its example app's settings: gravity 9.81744, 50 s
/// still start, accel bias guess 32768, gyro scale guess 1/6258; imu_tk 7780270 built from
/// source), as its own calib files: T, K, B with calibrated = T K (raw - B).
void write_imu_tk_result(const std::string& dir) {
  std::ofstream(dir + "/acc.calib") << "1 -0.0033593 -0.00890639\n0 1 -0.0213341\n-0 0 1\n\n"
                                       "0.00241278 0 0\n0 0.00242712 0\n0 0 0.00241168\n\n"
                                       "33124.2\n33275.2\n32364.4\n";
  std::ofstream(dir + "/gyro.calib")
      << "1 0.00593634 0.00111101\n0.00808812 1 -0.0535569\n0.0253067 -0.0025513 1\n\n"
         "0.000209295 0 0\n0 0.000209899 0\n0 0 0.000209483\n\n"
         "32777.1\n32459.8\n32511.8\n";
}

// imu_tk's own Xsens recording imported as a newcomer would, raw counts without their offsets
// (the sensor's zero is mid-range: values near 32768). Before: refused with "found at most 1
// distinct static attitudes ... Record again" although it holds 14. Now the offset is found
// (said in a warning that names --accel-offset), and the calibration fits the poses as well as
// the one imported with the sensor's offsets and scales (as in the test below).
TEST(RealRecordings, XsensImportedWithoutItsOffsetsCalibratesAsWellAsWithThem) {
  const std::string data = xsens_dir();
  if (!std::filesystem::exists(data + "/xsens_acc.txt")) {
    GTEST_SKIP() << data << " is absent (the real recordings sit beside the repository, not in it)";
  }
  const std::string dir = test::scratch_dir();
  double rms[2][2] = {};
  for (const bool offsets : {false, true}) {
    const std::string name = dir + (offsets ? "/with" : "/without");
    std::vector<std::string> import = {
        "import",  "ascii", "--accel", data + "/xsens_acc.txt", "--gyro", data + "/xsens_gyro.txt",
        "--units", "raw",   "-o",      name + ".imulog"};
    if (offsets) {
      for (const char* a : {"--accel-offset", "32768", "--accel-scale", "0.00241", "--gyro-offset", "32768",
                            "--gyro-scale", "0.0001598"})
        import.push_back(a);
    }
    auto r = run_cli(import);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = run_cli({"calibrate", "static", name + ".imulog", "--gravity", "9.81744", "-o", name + ".yaml",
                 "--json", name + ".json"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err.find("carry an offset") != std::string::npos, !offsets) << r.err;
    if (!offsets) {
      EXPECT_NE(r.err.find("--accel-offset"), std::string::npos) << r.err;
    }
    EXPECT_EQ(nlohmann::json::parse(test::read_file(name + ".json"))["static_intervals"].size(), 38u);
    r = run_cli({"calibrate", "check", name + ".imulog", "--calibration", name + ".yaml", "--gravity",
                 "9.81744", "--json", name + "-check.json"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto check = nlohmann::json::parse(test::read_file(name + "-check.json"))["calibrations"][0];
    rms[offsets][0] = check["gravity_magnitude_mps2"]["rms"];
    rms[offsets][1] = check["gravity_direction_rad"]["rms"];
  }
  // Measured 2026-12-03: the same to six digits.
  EXPECT_NEAR(rms[0][0], rms[1][0], 0.02 * rms[1][0]);
  EXPECT_NEAR(rms[0][1], rms[1][1], 0.02 * rms[1][1]);
}

TEST(RealRecordings, XsensStaticCalibrationIsAtLeastAsGoodAsImuTk) {
  const std::string data = xsens_dir();
  if (!std::filesystem::exists(data + "/xsens_acc.txt")) {
    GTEST_SKIP() << data << " is absent (the real recordings sit beside the repository, not in it)";
  }
  const std::string dir = test::scratch_dir();
  const std::string log = dir + "/xsens.imulog";
  auto r = run_cli({"import", "ascii", "--accel", data + "/xsens_acc.txt", "--gyro", data + "/xsens_gyro.txt",
                    "--units", "raw", "--accel-offset", "32768", "--accel-scale", "0.00241", "--gyro-offset",
                    "32768", "--gyro-scale", "0.0001598", "-o", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run_cli({"calibrate", "static", log, "--gravity", "9.81744", "-o", dir + "/imucal.yaml", "--json",
               dir + "/imucal.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // All 38 poses are kept (imu_tk keeps 38; the thesis' k varsigma_init^2 rule kept 30).
  const auto result = nlohmann::json::parse(test::read_file(dir + "/imucal.json"));
  EXPECT_EQ(result["static_intervals"].size(), 38u);
  EXPECT_EQ(result["gsens"]["mode"], "estimate");
  write_imu_tk_result(dir);
  r = run_cli({"calibrate", "check", log, "--calibration", dir + "/imucal.yaml", "--imu-tk",
               dir + "/acc.calib," + dir + "/gyro.calib", "--gravity", "9.81744", "--json",
               dir + "/check.json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto check = nlohmann::json::parse(test::read_file(dir + "/check.json"));
  const auto& ours = check["calibrations"][0];
  const auto& peer = check["calibrations"][1];
  const double ours_mag = ours["gravity_magnitude_mps2"]["rms"],
               peer_mag = peer["gravity_magnitude_mps2"]["rms"];
  const double ours_dir = ours["gravity_direction_rad"]["rms"],
               peer_dir = peer["gravity_direction_rad"]["rms"];
  // Measured 2026-11-23: ours 0.00098 m/s^2 and 3.6 mrad, imu_tk 0.00112 m/s^2 and 22.5 mrad.
  EXPECT_LE(ours_mag, peer_mag) << r.out;
  EXPECT_LE(ours_dir, 0.5 * peer_dir) << r.out;
  // Paired over the same transfers, imu_tk's larger direction error is far beyond chance
  // (2026-11-27: +18.9 +- 3.0 mrad); its magnitude residual is not (+0.00014 +- 0.00009 m/s^2).
  const auto& paired = peer["against_first"]["gravity_direction_rad"];
  EXPECT_GT(paired["rms_difference"].get<double>(), 4.0 * paired["sigma"].get<double>()) << r.out;
}

}  // namespace
}  // namespace imucal
