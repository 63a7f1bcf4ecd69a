// SPDX-License-Identifier: BSD-3-Clause
#include "tests/support/test_support.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace imucal::test {

std::string scratch_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "global";
  for (auto& c : name) {
    if (c == '/') c = '_';
  }
  const std::filesystem::path dir = std::filesystem::path(IMUCAL_TEST_TMP) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

std::string source_path(const std::string& relative) {
  return (std::filesystem::path(IMUCAL_SOURCE_DIR) / relative).string();
}

bool on_path(const std::string& program) {
  const char* path = std::getenv("PATH");
  std::stringstream ss(path ? path : "");
  for (std::string dir; std::getline(ss, dir, ':');)
    if (!dir.empty() && ::access((std::filesystem::path(dir) / program).c_str(), X_OK) == 0) return true;
  return false;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_file(const std::filesystem::path& path, const std::string& text) {
  const std::filesystem::path parent = path.parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  std::ofstream(path, std::ios::binary) << text;
}

std::string copy_fixture(const std::string& name, const std::string& dir) {
  const std::string path = (std::filesystem::path(dir) / std::filesystem::path(name).filename()).string();
  std::filesystem::copy_file(source_path("fixtures/" + name), path);
  return path;
}

bool run_sql(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  const bool ok = sqlite3_open(path.c_str(), &db) == SQLITE_OK &&
                  sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr) == SQLITE_OK;
  sqlite3_close(db);
  return ok;
}

ScopedCacheDir::ScopedCacheDir(const std::string& dir) { setenv("IMUCAL_CACHE_DIR", dir.c_str(), 1); }
ScopedCacheDir::~ScopedCacheDir() { unsetenv("IMUCAL_CACHE_DIR"); }

ScopedModuleDir::ScopedModuleDir(const std::string& dir) { setenv("IMUCAL_MODULE_DIR", dir.c_str(), 1); }
ScopedModuleDir::~ScopedModuleDir() { unsetenv("IMUCAL_MODULE_DIR"); }

WriterLockHolder::WriterLockHolder(const std::string& path) {
  int ready[2];
  if (::pipe(ready) != 0) return;
  child_ = ::fork();
  if (child_ == 0) {
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0 || ::flock(fd, LOCK_EX) != 0) _exit(1);
    (void)!::write(ready[1], "x", 1);
    ::sleep(30);
    _exit(0);
  }
  ::close(ready[1]);
  char c = 0;
  held_ = child_ > 0 && ::read(ready[0], &c, 1) == 1;
  ::close(ready[0]);
}

WriterLockHolder::~WriterLockHolder() {
  if (child_ <= 0) return;
  ::kill(child_, SIGKILL);
  ::waitpid(child_, nullptr, 0);
}

CommandResult run_cli(const std::vector<std::string>& args, unsigned limit_s) {
  CommandResult result;
  const std::string dir = std::filesystem::temp_directory_path() / ("imucal-cli-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string out_path = dir + "/out";
  const std::string err_path = dir + "/err";
  const pid_t pid = fork();
  if (pid == 0) {
    if (!freopen(out_path.c_str(), "w", stdout) || !freopen(err_path.c_str(), "w", stderr)) _exit(127);
    if (std::getenv("IMUCAL_CACHE_DIR") == nullptr) setenv("IMUCAL_CACHE_DIR", (dir + "/cache").c_str(), 1);
    std::vector<char*> argv;
    std::string bin = IMUCAL_CLI_PATH;
    argv.push_back(bin.data());
    std::vector<std::string> copy = args;
    for (auto& a : copy) argv.push_back(a.data());
    argv.push_back(nullptr);
    if (limit_s > 0) alarm(limit_s);  // a pending alarm survives execv
    execv(bin.c_str(), argv.data());
    _exit(127);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  result.out = read_file(out_path);
  result.err = read_file(err_path);
  std::filesystem::remove_all(dir);
  return result;
}

}  // namespace imucal::test
