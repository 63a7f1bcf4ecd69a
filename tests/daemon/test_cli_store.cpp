// SPDX-License-Identifier: BSD-3-Clause
// imucal store read|write|verify against a file-backed storage region in the test's scratch
// folder, with a static result computed from the fixture log by the CLI itself.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/calibration_record.hpp"
#include "core/rig_config.hpp"
#include "daemon/cli/command.hpp"
#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/storage_device.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

struct Rig {
  std::string dir, config, storage, result;
};

Rig make_rig(int size_bytes = 4096) {
  Rig r;
  r.dir = test::scratch_dir();
  r.config = r.dir + "/rig.yaml";
  r.storage = r.dir + "/calibration.bin";
  std::ofstream(r.config) << "name: cli-rig\nimu:\n  bus: sim\nstorage:\n  backend: file\n  path: "
                          << r.storage << "\n  size_bytes: " << size_bytes << "\n  offset_bytes: 128\n";
  r.result = r.dir + "/static.yaml";
  auto c =
      test::run_cli({"calibrate", "static", test::source_path("fixtures/static.imulog"), "-o", r.result});
  EXPECT_EQ(c.exit_code, 0) << c.err;
  return r;
}

TEST(CliStore, WriteReadVerifyRoundTrip) {
  const Rig rig = make_rig();
  auto empty = test::run_cli({"store", "read", "--config", rig.config});
  EXPECT_EQ(empty.exit_code, cli::kExitInput) << empty.err;
  EXPECT_THAT(empty.err, HasSubstr("no calibration is stored"));
  EXPECT_FALSE(std::filesystem::exists(rig.storage));  // reading creates nothing

  auto w1 = test::run_cli({"store", "write", "--config", rig.config, rig.result});
  ASSERT_EQ(w1.exit_code, 0) << w1.err;
  EXPECT_THAT(w1.out, HasSubstr("slot A, sequence 1"));
  auto w2 = test::run_cli({"store", "write", "--config", rig.config, rig.result});
  ASSERT_EQ(w2.exit_code, 0) << w2.err;
  EXPECT_THAT(w2.out, HasSubstr("slot B, sequence 2"));

  auto read = test::run_cli({"store", "read", "--config", rig.config});
  ASSERT_EQ(read.exit_code, 0) << read.err;
  EXPECT_THAT(read.out, HasSubstr("# file " + rig.storage + ": slot B, sequence 2"));
  EXPECT_THAT(read.out, HasSubstr("format: imucal.calibration"));
  EXPECT_THAT(read.out, HasSubstr("rig: cli-rig"));

  auto json_read = test::run_cli({"store", "read", "--json", "--config", rig.config});
  ASSERT_EQ(json_read.exit_code, 0) << json_read.err;
  const auto j = nlohmann::json::parse(json_read.out);
  EXPECT_EQ(j["slot"], "B");
  EXPECT_EQ(j["sequence"], 2);
  EXPECT_EQ(j["slots"][0]["sequence"], 1);
  EXPECT_EQ(j["calibration"]["imu"]["source"], "static");

  auto verify = test::run_cli({"store", "verify", "--config", rig.config, rig.result});
  ASSERT_EQ(verify.exit_code, 0) << verify.err;
  EXPECT_THAT(verify.out, HasSubstr("equals the given result"));
  // Exports (YAML and JSON) verify against what is stored.
  for (const auto& [name, text] :
       {std::pair{"export.yaml", read.out}, std::pair{"export.json", json_read.out}}) {
    std::ofstream(rig.dir + "/" + name) << text;
    auto v = test::run_cli({"store", "verify", "--config", rig.config, rig.dir + "/" + name});
    EXPECT_EQ(v.exit_code, 0) << name << ": " << v.err;
  }
}

TEST(CliStore, VerifyReportsADifferentCalibrationAndADamagedSlot) {
  const Rig rig = make_rig();
  ASSERT_EQ(test::run_cli({"store", "write", "--config", rig.config, rig.result}).exit_code, 0);
  ASSERT_EQ(test::run_cli({"store", "write", "--config", rig.config, rig.result}).exit_code, 0);
  // A different result: one bias changed.
  std::ifstream in(rig.result);
  std::stringstream text;
  text << in.rdbuf();
  std::string changed = text.str();
  const auto at = changed.find("b_a: [");
  ASSERT_NE(at, std::string::npos);
  changed.insert(changed.find_first_of("0123456789", at + 6), "1");  // a digit more in front
  std::ofstream(rig.dir + "/other.yaml") << changed;
  auto v = test::run_cli({"store", "verify", "--config", rig.config, rig.dir + "/other.yaml"});
  EXPECT_EQ(v.exit_code, cli::kExitData) << v.err;
  EXPECT_THAT(v.err, HasSubstr("differs"));

  // Damage slot B's payload (region at 128, slot of 2048 bytes, payload after a 24-byte header).
  {
    std::fstream f(rig.storage, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(128 + 2048 + 24 + 10);
    f.put('\x5a');
  }
  auto after = test::run_cli({"store", "verify", "--config", rig.config, rig.result});
  EXPECT_EQ(after.exit_code, 0) << after.err;  // slot A still holds the calibration
  EXPECT_THAT(after.out, HasSubstr("slot A, sequence 1"));
  EXPECT_THAT(after.out, HasSubstr("bad payload CRC"));
  EXPECT_THAT(after.out, HasSubstr("the next write goes there"));
  EXPECT_THAT(after.err, HasSubstr("warning: slot B is damaged"));
  // read serves the older record and says so where a script sees it: stderr and the JSON.
  auto read = test::run_cli({"store", "read", "--config", rig.config});
  EXPECT_EQ(read.exit_code, 0) << read.err;
  EXPECT_THAT(read.err, HasSubstr("warning: slot B is damaged (bad payload CRC"));
  EXPECT_THAT(read.err, HasSubstr("may be older than the last one written"));
  auto json_read = test::run_cli({"store", "read", "--json", "--config", rig.config});
  ASSERT_EQ(json_read.exit_code, 0) << json_read.err;
  const auto j = nlohmann::json::parse(json_read.out);
  EXPECT_EQ(j["slot"], "A");
  EXPECT_EQ(j["damaged_slots"], nlohmann::json::array({"B"}));
  EXPECT_EQ(j["may_be_older_than_last_write"], true);
  auto w = test::run_cli({"store", "write", "--config", rig.config, rig.result});
  EXPECT_EQ(w.exit_code, 0) << w.err;
  EXPECT_THAT(w.out, HasSubstr("slot B, sequence 2"));
  // Two good copies again: no warning, nothing damaged.
  auto healed = test::run_cli({"store", "read", "--json", "--config", rig.config});
  ASSERT_EQ(healed.exit_code, 0) << healed.err;
  EXPECT_THAT(healed.err, ::testing::Not(HasSubstr("warning")));
  EXPECT_EQ(nlohmann::json::parse(healed.out)["may_be_older_than_last_write"], false);
}

// store rollback makes the previous record the newest again, its sequence advanced; the one
// it replaced stays, so a second rollback restores it.
TEST(CliStore, RollbackRestoresThePreviousRecordAndKeepsTheReplacedOne) {
  const Rig rig = make_rig();
  auto none = test::run_cli({"store", "rollback", "--config", rig.config});
  EXPECT_EQ(none.exit_code, cli::kExitInput) << none.err;
  EXPECT_THAT(none.err, HasSubstr("nothing was stored yet"));
  ASSERT_EQ(test::run_cli({"store", "write", "--config", rig.config, rig.result}).exit_code, 0);
  auto single = test::run_cli({"store", "rollback", "--config", rig.config});
  EXPECT_EQ(single.exit_code, cli::kExitInput) << single.err;
  EXPECT_THAT(single.err, HasSubstr("no previous record to roll back to: slot B"));
  // A second, different calibration (one bias changed) as sequence 2.
  std::string changed = test::read_file(rig.result);
  const auto at = changed.find("b_a: [");
  ASSERT_NE(at, std::string::npos);
  changed.insert(changed.find_first_of("0123456789", at + 6), "1");
  const std::string other = rig.dir + "/other.yaml";
  test::write_file(other, changed);
  ASSERT_EQ(test::run_cli({"store", "write", "--config", rig.config, other}).exit_code, 0);
  ASSERT_EQ(test::run_cli({"store", "verify", "--config", rig.config, other}).exit_code, 0);

  auto back = test::run_cli({"store", "rollback", "--config", rig.config});
  ASSERT_EQ(back.exit_code, 0) << back.err;
  EXPECT_THAT(back.out, HasSubstr("the record of sequence 1 is now sequence 3 in slot A"));
  EXPECT_EQ(test::run_cli({"store", "verify", "--config", rig.config, rig.result}).exit_code, 0);
  // And forth again: the replaced record was kept.
  auto forth = test::run_cli({"store", "rollback", "--config", rig.config});
  ASSERT_EQ(forth.exit_code, 0) << forth.err;
  EXPECT_THAT(forth.out, HasSubstr("the record of sequence 2 is now sequence 4 in slot B"));
  EXPECT_EQ(test::run_cli({"store", "verify", "--config", rig.config, other}).exit_code, 0);
}

TEST(CliStore, ErrorsHaveTheirExitCodes) {
  const Rig rig = make_rig(256);
  auto too_big = test::run_cli({"store", "write", "--config", rig.config, rig.result});
  EXPECT_EQ(too_big.exit_code, cli::kExitUsage) << too_big.err;
  EXPECT_THAT(too_big.err, HasSubstr("storage.size_bytes"));
  // A refused write leaves no storage file behind (it was created before the refusal).
  EXPECT_FALSE(std::filesystem::exists(rig.storage));
  auto missing = test::run_cli({"store", "write", "--config", rig.config, rig.dir + "/none.yaml"});
  EXPECT_EQ(missing.exit_code, cli::kExitInput) << missing.err;
  auto no_config = test::run_cli({"store", "read", "--config", rig.dir + "/none-rig.yaml"});
  EXPECT_EQ(no_config.exit_code, cli::kExitInput) << no_config.err;
  auto no_result = test::run_cli({"store", "write", "--config", rig.config});
  EXPECT_EQ(no_result.exit_code, cli::kExitUsage) << no_result.err;
  // A file of the wrong size is a device configuration problem, named with its keys.
  std::ofstream(rig.storage) << "short";
  auto short_file = test::run_cli({"store", "read", "--config", rig.config});
  EXPECT_EQ(short_file.exit_code, cli::kExitUsage) << short_file.err;
  EXPECT_THAT(short_file.err, HasSubstr("storage.offset_bytes"));
}

// Before: `store write` wrote its record into whatever regular file storage.path named (a session
// log given by mistake was destroyed, exit 0), and `store read` waited for good on a FIFO there.
TEST(CliStore, NeverWritesOverAnotherFileNorWaitsOnAFifo) {
  const Rig rig = make_rig();
  std::filesystem::copy_file(test::source_path("fixtures/static.imulog"), rig.storage);
  const std::string before = test::read_file(rig.storage);
  auto w = test::run_cli({"store", "write", "--config", rig.config, rig.result});
  EXPECT_EQ(w.exit_code, cli::kExitUsage) << w.err;
  EXPECT_THAT(w.err, HasSubstr("holds data that is not a calibration record"));
  EXPECT_THAT(w.err, HasSubstr("nothing was written"));
  EXPECT_TRUE(test::read_file(rig.storage) == before) << "the file at storage.path was changed";

  std::filesystem::remove(rig.storage);
  ASSERT_EQ(::mkfifo(rig.storage.c_str(), 0600), 0);
  for (const char* sub : {"read", "verify"}) {
    auto r = test::run_cli({"store", sub, "--config", rig.config});
    EXPECT_EQ(r.exit_code, cli::kExitUsage) << sub << ": " << r.err;
    EXPECT_THAT(r.err, HasSubstr(rig.storage + " is not a regular file"));
  }
  auto fifo_write = test::run_cli({"store", "write", "--config", rig.config, rig.result});
  EXPECT_EQ(fifo_write.exit_code, cli::kExitUsage) << fifo_write.err;
  EXPECT_TRUE(std::filesystem::is_fifo(rig.storage));
}

// The storage holds a record this imucal must not read, or must not replace, or its path loops.
// Before: a payload nested 200,000 deep crashed `store read` and `store verify` (a stack
// overflow); a record of a newer imucal was taken for damage, and `store write` wrote over it
// (exit 0); a loop of symbolic links exited 7, as a failed write does.
TEST(CliStore, ANestedANewerOrALoopedStorageIsNamedWithItsExitCodeAndKept) {
  {
    SCOPED_TRACE("a payload nested 200,000 deep in a 1 MiB region");
    const Rig rig = make_rig(1 << 20);
    ASSERT_EQ(test::run_cli({"store", "write", "--config", rig.config, rig.result}).exit_code, 0);
    auto rig_config = load_rig_config(rig.config);
    ASSERT_TRUE(rig_config.ok()) << rig_config.error().message;
    {
      auto dev = drivers::open_storage_device(rig_config->storage, drivers::StorageAccess::kWrite);
      ASSERT_TRUE(dev.ok()) << dev.error().message;
      auto store = drivers::CalibrationStore::open(**dev, 128, 1 << 20);
      ASSERT_TRUE(store.ok()) << store.error().message;
      std::vector<std::uint8_t> nested(200'000, 0x81);  // an array of one item, 200,000 deep
      nested.push_back(0x00);
      ASSERT_TRUE(store->write(nested).ok());  // slot B, the newest
    }
    for (const char* sub : {"read", "verify"}) {
      auto r = test::run_cli({"store", sub, "--config", rig.config});
      EXPECT_EQ(r.exit_code, cli::kExitInput) << sub << ": " << r.err;
      EXPECT_THAT(r.err, HasSubstr("deeper than 32 levels"));
      EXPECT_THAT(r.err, Not(HasSubstr("unexpected")));
    }
  }
  {
    SCOPED_TRACE("a record of a newer imucal");
    const Rig rig = make_rig();
    ASSERT_EQ(test::run_cli({"store", "write", "--config", rig.config, rig.result}).exit_code, 0);
    auto read = test::run_cli({"store", "read", "--json", "--config", rig.config});
    ASSERT_EQ(read.exit_code, 0) << read.err;
    nlohmann::json newer = nlohmann::json::parse(read.out)["calibration"];
    newer["version"] = kCalibrationRecordVersion + 1;
    auto rig_config = load_rig_config(rig.config);
    ASSERT_TRUE(rig_config.ok()) << rig_config.error().message;
    {
      auto dev = drivers::open_storage_device(rig_config->storage, drivers::StorageAccess::kWrite);
      ASSERT_TRUE(dev.ok()) << dev.error().message;
      auto store = drivers::CalibrationStore::open(**dev, 128, 4096);
      ASSERT_TRUE(store.ok()) << store.error().message;
      ASSERT_TRUE(store->write(nlohmann::json::to_cbor(newer)).ok());  // slot B, sequence 2
    }
    const std::string before = test::read_file(rig.storage);
    auto r = test::run_cli({"store", "read", "--config", rig.config});
    EXPECT_EQ(r.exit_code, cli::kExitInput) << r.err;
    EXPECT_THAT(r.err, HasSubstr("newer imucal"));
    auto w = test::run_cli({"store", "write", "--config", rig.config, rig.result});
    EXPECT_EQ(w.exit_code, cli::kExitUsage) << w.err;
    EXPECT_THAT(w.err, HasSubstr("written by a newer imucal"));
    EXPECT_THAT(w.err, HasSubstr("--replace-newer"));
    EXPECT_TRUE(test::read_file(rig.storage) == before) << "the newer record was written over";
    auto replaced = test::run_cli({"store", "write", "--replace-newer", "--config", rig.config, rig.result});
    ASSERT_EQ(replaced.exit_code, 0) << replaced.err;
    EXPECT_THAT(replaced.out, HasSubstr("sequence 3"));
    EXPECT_EQ(test::run_cli({"store", "read", "--config", rig.config}).exit_code, 0);
  }
  {
    SCOPED_TRACE("a loop of symbolic links at storage.path");
    const Rig rig = make_rig();
    std::filesystem::create_symlink(rig.storage, rig.storage);
    for (const char* sub : {"read", "verify", "write"}) {
      std::vector<std::string> args = {"store", sub, "--config", rig.config};
      if (std::string(sub) == "write") args.push_back(rig.result);
      auto r = test::run_cli(args);
      EXPECT_EQ(r.exit_code, cli::kExitUsage) << sub << ": " << r.err;
      EXPECT_THAT(r.err, HasSubstr("fix storage.path"));
    }
    EXPECT_TRUE(std::filesystem::is_symlink(rig.storage));
  }
}

}  // namespace
}  // namespace imucal
