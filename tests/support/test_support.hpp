#pragma once
// Helpers shared by the test executables.

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

/// Reads a whole file; empty when missing.
std::string read_file(const std::string& path);

}  // namespace imucal::test
