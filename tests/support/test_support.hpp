// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Helpers shared by the test executables.

#include <filesystem>
#include <string>
#include <vector>

namespace imucal::test {

/// A fresh, empty scratch directory unique to the calling test (under the build tree).
std::string scratch_dir();

/// Path of a file in the source tree, e.g. source_path("fixtures/static.imulog").
std::string source_path(const std::string& relative);

struct CommandResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

/// Runs the imucal CLI with `args` (no shell), capturing stdout and stderr. With `limit_s`, a run
/// that has not ended after that many seconds is ended by SIGALRM (exit code 128 + 14).
CommandResult run_cli(const std::vector<std::string>& args, unsigned limit_s = 0);

/// Whether `program` is an executable in a folder of PATH (tests that need a tool skip without it).
bool on_path(const std::string& program);

/// Reads a whole file; empty when missing.
std::string read_file(const std::string& path);

/// Writes `text` to `path`, creating its folder.
void write_file(const std::filesystem::path& path, const std::string& text);

/// Copies fixtures/`name` into `dir` and returns the copy's path (for tests that write to a log).
std::string copy_fixture(const std::string& name, const std::string& dir);

/// Runs `sql` on the SQLite file `path` (a session log changed behind the reader's back, as
/// damage or a newer writer would); false when it fails.
bool run_sql(const std::string& path, const std::string& sql);

/// Points the CLI's detection cache at `dir` (IMUCAL_CACHE_DIR) while it lives. Without it each
/// run_cli call gets a cache of its own, removed after the call, so that no test reuses what
/// another one found and nothing is written into the user's home.
class ScopedCacheDir {
 public:
  explicit ScopedCacheDir(const std::string& dir);
  ~ScopedCacheDir();
  ScopedCacheDir(const ScopedCacheDir&) = delete;
  ScopedCacheDir& operator=(const ScopedCacheDir&) = delete;
};

/// Points the module loader at `dir` (IMUCAL_MODULE_DIR) while it lives.
class ScopedModuleDir {
 public:
  explicit ScopedModuleDir(const std::string& dir);
  ~ScopedModuleDir();
  ScopedModuleDir(const ScopedModuleDir&) = delete;
  ScopedModuleDir& operator=(const ScopedModuleDir&) = delete;
};

/// A child process that holds the writer's lock (flock LOCK_EX) on `path`, as `record` does on
/// its live log, from construction (held() once it has it) until destruction (the child killed).
class WriterLockHolder {
 public:
  explicit WriterLockHolder(const std::string& path);
  ~WriterLockHolder();
  WriterLockHolder(const WriterLockHolder&) = delete;
  WriterLockHolder& operator=(const WriterLockHolder&) = delete;
  bool held() const { return held_; }

 private:
  int child_ = -1;
  bool held_ = false;
};

}  // namespace imucal::test
