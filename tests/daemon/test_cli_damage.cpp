// SPDX-License-Identifier: BSD-3-Clause
// The damage matrix through the commands a user runs: variants of the static fixture log with a
// page overwritten or a byte flipped, each through `imucal info`, `calibrate static` and
// `export euroc`. A command may exit 0 only with every sample the log holds, or with the loss
// said; the per-variant reads are checked against the reader in this process.

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;

std::int64_t lines_of(const std::string& path) {
  std::ifstream in(path);
  std::int64_t n = 0;
  std::string line;
  while (std::getline(in, line))
    if (!line.empty() && line[0] != '#') ++n;
  return n;
}

TEST(CliDamage, NoCommandLosesSamplesWithoutSayingSo) {
  const std::string fixture = test::source_path("fixtures/static.imulog");
  const std::string dir = test::scratch_dir();
  std::int64_t total = 0;
  {
    auto reader = log::SessionLogReader::open(fixture);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    total = *(*reader)->imu_count(*(*reader)->find_imu_stream());
  }
  const auto size = fs::file_size(fixture);
  constexpr std::size_t kPage = 4096;
  std::mt19937 rng(5);
  int variants = 0, refused_everywhere = 0, salvaged = 0;
  for (int k = 0; k < 16; ++k) {
    const std::string bad = dir + "/bad.imulog";
    fs::copy_file(fixture, bad, fs::copy_options::overwrite_existing);
    std::string what;
    {
      std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
      if (k < 8) {  // a page of garbage, spread over the file (page 0 is the header)
        const std::size_t page = 1 + k * (size / kPage - 2) / 8;
        f.seekp(static_cast<std::streamoff>(page * kPage));
        std::string garbage(kPage, '\0');
        for (auto& c : garbage) c = static_cast<char>(rng());
        f.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
        what = "page " + std::to_string(page) + " overwritten";
      } else {
        const auto at = static_cast<std::streamoff>(100 + rng() % (size - 100));
        f.seekg(at);
        char c = 0;
        f.get(c);
        f.seekp(at);
        f.put(static_cast<char>(c ^ 0x04));
        what = "byte " + std::to_string(at) + " flipped";
      }
    }
    SCOPED_TRACE(what);
    ++variants;
    // What the reader here finds: the truth each command is held to.
    bool damaged = true;
    std::int64_t readable = 0;
    if (auto r = log::SessionLogReader::open(bad); r.ok()) {
      auto samples = (*r)->read_imu(*(*r)->find_imu_stream());
      readable = samples.ok() ? static_cast<std::int64_t>(samples->size()) : 0;
      damaged = (*r)->health().damaged;
    }
    bool any_ok = false;
    const auto info = test::run_cli({"info", "--json", bad});
    if (info.exit_code == 0) {
      any_ok = true;
      const auto j = nlohmann::json::parse(info.out);
      EXPECT_FALSE(j.at("damaged").get<bool>());
      EXPECT_EQ(j.at("imu_streams").at(0).at("count").get<std::int64_t>(), total);
    } else {
      EXPECT_EQ(info.exit_code, 3) << info.err;
    }
    fs::remove(dir + "/r.yaml");
    const auto cal = test::run_cli({"calibrate", "static", bad, "-o", dir + "/r.yaml"});
    if (cal.exit_code == 0) {
      any_ok = true;
      EXPECT_FALSE(damaged) << "calibrated a damaged log without saying so";
      EXPECT_EQ(readable, total);
    }
    const std::string out = dir + "/euroc";
    fs::remove_all(out);
    const auto exp = test::run_cli({"export", "euroc", bad, out});
    if (exp.exit_code == 0) {
      any_ok = true;
      EXPECT_EQ(lines_of(out + "/mav0/imu0/data.csv"), total) << "exported fewer samples, exit 0";
    }
    if (!any_ok) ++refused_everywhere;
    // With --allow-damaged a damaged log is calibrated from what is readable, and said to be.
    if (damaged && readable > 0) {
      fs::remove(dir + "/r.yaml");
      const auto salvage =
          test::run_cli({"calibrate", "static", bad, "--allow-damaged", "-o", dir + "/r.yaml"});
      if (salvage.exit_code == 0) {
        ++salvaged;
        EXPECT_NE(salvage.err.find("damaged"), std::string::npos) << salvage.err;
      }
    }
  }
  std::printf(
      "damage matrix (CLI): %d variants, %d refused by every command, %d salvaged by --allow-damaged\n",
      variants, refused_everywhere, salvaged);
}

}  // namespace
}  // namespace imucal
