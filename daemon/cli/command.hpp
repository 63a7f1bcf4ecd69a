// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Subcommands of the offline CLI register themselves: each cmd_*.cpp defines one static
// CommandRegistrar whose setup function adds a CLI11 subcommand to the root app. The
// subcommand's callback throws CliExit to end with a given exit code and message.

#include <CLI/CLI.hpp>
#include <Eigen/Core>
#include <chrono>
#include <cstdio>
#include <functional>
#include <string>

#include "core/result.hpp"
#include "daemon/common/number_check.hpp"

namespace imucal::cli {

/// Exit codes of `imucal` (documented in docs/cli.md).
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,  // unexpected failure (a bug)
  kExitUsage = 2,    // bad command line (CLI11 parse errors also end here)
  kExitInput = 3,    // unreadable, malformed or damaged input file
  kExitData = 4,     // input readable but not enough / not suitable for the method
  kExitSolver = 5,   // estimation failed or failed its quality checks
  kExitDevice = 6,   // hardware or device file problem
  kExitIo = 7,       // could not write the output
};

/// Thrown from a subcommand callback to end the program with `code` after printing `message`
/// to stderr (when not empty).
struct CliExit {
  int code;
  std::string message;
};

/// Maps an error code to the CLI exit code.
int exit_code_for(Errc code);

/// Throws CliExit for a failed Result, with the error's message prefixed by `what`.
[[noreturn]] void fail(const Error& error, const std::string& what = "");

/// Puts every command's examples at the end of its --help (cli/examples.cpp); called once all
/// commands are set up.
void add_examples(CLI::App& root);

class CommandRegistrar {
 public:
  using Setup = std::function<void(CLI::App& root)>;
  /// `order` sorts the subcommands in --help.
  CommandRegistrar(int order, Setup setup);
};

/// Option checks with short messages (daemon/common/number_check.hpp): a finite number above zero,
/// at zero or above, or any finite number; a value that is not empty.
extern const CLI::Validator kPositive;
extern const CLI::Validator kNonNegative;
extern const CLI::Validator kFinite;
extern const CLI::Validator kNonEmpty;

/// An option's value for the three axes: "V" -> (V, V, V), "Vx,Vy,Vz" -> the three, each a
/// finite number (log::parse_double's rules); anything else ends the program with a usage error
/// that names `option`.
Eigen::Vector3d parse_triple(const std::string& text, const std::string& option);

/// True when stderr is a terminal.
bool stderr_is_tty();

/// Progress of long work on stderr. On a terminal, one line redrawn in place (the percentage).
/// Otherwise (a file, a pipe, a journal) a line every few seconds with the fraction done, the
/// elapsed time, the rate and the time left, and a last line when the work ends, as build tools
/// do: "detecting the target: 42.0 % after 12 s (3.5 %/s, about 17 s left)". The interval is
/// kLogIntervalS, or IMUCAL_PROGRESS_INTERVAL seconds from the environment.
class Progress {
 public:
  static constexpr double kLogIntervalS = 5.0;

  /// `total` is the value update() reaches at the end.
  Progress(std::string label, double total);
  /// For tests: the stream to write, whether it is a terminal, the interval between lines.
  Progress(std::string label, double total, std::FILE* out, bool terminal, double interval_s);
  ~Progress();
  void update(double done);
  void finish();

 private:
  double elapsed_s() const;

  std::string label_;
  double total_;
  std::FILE* out_;
  bool terminal_;
  double interval_s_;
  std::chrono::steady_clock::time_point start_;
  double last_line_s_ = 0.0;
  double last_fraction_ = 0.0;
  bool finished_ = false;
  bool updated_ = false;
  int last_permille_ = -1;
};

}  // namespace imucal::cli
