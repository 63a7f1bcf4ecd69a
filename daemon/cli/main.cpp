// SPDX-License-Identifier: BSD-3-Clause
// imucal: the offline command-line tool. Subcommands live in cmd_*.cpp.

#include <malloc.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "core/text_format.hpp"
#include "core/threads.hpp"
#include "core/version.hpp"
#include "daemon/cli/command.hpp"
#include "daemon/cli/option_flags.hpp"
#include "daemon/common/unknown_command.hpp"
#include "log/dataset_io.hpp"

namespace imucal::cli {
namespace {

std::vector<std::pair<int, CommandRegistrar::Setup>>& registry() {
  static std::vector<std::pair<int, CommandRegistrar::Setup>> commands;
  return commands;
}

}  // namespace

CommandRegistrar::CommandRegistrar(int order, Setup setup) {
  registry().emplace_back(order, std::move(setup));
}

int exit_code_for(Errc code) {
  switch (code) {
    case Errc::kInvalidArgument:
    case Errc::kAlreadyExists:  // replacing needs --force: a command-line matter
      return kExitUsage;
    case Errc::kNotFound:
    case Errc::kCorrupt:
    case Errc::kNewerVersion:
      return kExitInput;
    case Errc::kIo:
      return kExitIo;
    case Errc::kInsufficientData:
      return kExitData;
    case Errc::kSolverFailed:
      return kExitSolver;
    case Errc::kDevice:
    case Errc::kTimeout:
      return kExitDevice;
    case Errc::kUnsupported:
    case Errc::kInternal:
      return kExitFailure;
  }
  return kExitFailure;
}

std::string remedy_flag(const Remedy& remedy) {
  // Library option names (the fields of the options structs) and the flags that set them.
  static const std::map<std::string, std::string> kFlags = {
      {"accel_scale", "--accel-scale"}, {"allow_damaged", "--allow-damaged"},
      {"camera", "--camera"},           {"columns", "--columns"},
      {"delimiter", "--delimiter"},     {"gyro_scale", "--gyro-scale"},
      {"init_still_s", "--init-still"}, {"min_interval_s", "--min-interval"},
      {"multiplier", "--multiplier"},   {"rate_hz", "--rate"},
      {"receive_time", "--bag-time"},   {"replace_newer", "--replace-newer"},
      {"skip_header", "--skip-header"}, {"target", "--target"},
      {"time_unit", "--time-unit"},     {"units", "--units"},
  };
  if (remedy.option == "unit_check" && remedy.value == "off") return "--no-unit-check";
  const auto it = kFlags.find(remedy.option);
  const std::string flag = it != kFlags.end() ? it->second : remedy.option;
  return remedy.value.empty() ? flag : flag + " " + remedy.value;
}

std::string with_flag_hints(const Error& error, const std::string& what) {
  std::string message = what.empty() ? error.message : what + ": " + error.message;
  // Libraries say what exists; replacing it is the CLI's --force.
  if (error.code == Errc::kAlreadyExists) message += "; pass --force to replace it";
  for (std::size_t i = 0; i < error.remedies.size(); ++i) {
    message += (i == 0 ? "; options: " : ", ") + remedy_flag(error.remedies[i]);
  }
  return message;
}

Eigen::Vector3d parse_triple(const std::string& text, const std::string& option) {
  std::vector<double> values;
  std::stringstream items(text);
  std::string item;
  while (std::getline(items, item, ',')) {
    auto v = log::parse_double(item);
    if (!v.ok()) throw CliExit{kExitUsage, option + ": " + v.error().message + " (give V or Vx,Vy,Vz)"};
    values.push_back(*v);
  }
  if (values.size() == 1) return Eigen::Vector3d::Constant(values[0]);
  if (values.size() == 3) return {values[0], values[1], values[2]};
  throw CliExit{
      kExitUsage,
      option + ": expected one value for all three axes or three comma-separated values, got '" + text + "'"};
}

void fail(const Error& error, const std::string& what) {
  throw CliExit{exit_code_for(error.code), with_flag_hints(error, what)};
}

const CLI::Validator kPositive = finite_number(NumberSign::kPositive);
const CLI::Validator kNonNegative = finite_number(NumberSign::kNonNegative);
const CLI::Validator kFinite = finite_number(NumberSign::kAny);
const CLI::Validator kNonEmpty = non_empty();

bool stderr_is_tty() { return isatty(STDERR_FILENO) == 1; }

namespace {

double progress_interval_from_env() {
  const char* text = std::getenv("IMUCAL_PROGRESS_INTERVAL");
  if (text == nullptr || *text == '\0') return Progress::kLogIntervalS;
  const std::optional<double> v = parse_finite_number(text);
  return v && *v >= 0.0 ? *v : Progress::kLogIntervalS;
}

std::string seconds_text(double s) {
  char text[32];
  if (s < 10.0) {
    std::snprintf(text, sizeof text, "%.1f s", s);
  } else if (s < 600.0) {
    std::snprintf(text, sizeof text, "%.0f s", s);
  } else {
    std::snprintf(text, sizeof text, "%.0f min", s / 60.0);
  }
  return text;
}

}  // namespace

Progress::Progress(std::string label, double total)
    : Progress(std::move(label), total, stderr, stderr_is_tty(), progress_interval_from_env()) {}

Progress::Progress(std::string label, double total, std::FILE* out, bool terminal, double interval_s)
    : label_(std::move(label)),
      total_(total),
      out_(out),
      terminal_(terminal),
      interval_s_(interval_s),
      start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() { finish(); }

double Progress::elapsed_s() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::update(double done) {
  if (finished_ || total_ <= 0) return;
  const double fraction = std::clamp(done / total_, 0.0, 1.0);
  updated_ = true;
  last_fraction_ = fraction;
  if (terminal_) {
    const int permille = static_cast<int>(fraction * 1000.0);
    if (permille == last_permille_) return;
    last_permille_ = permille;
    std::fprintf(out_, "\r%s %5.1f%%", label_.c_str(), permille / 10.0);
    std::fflush(out_);
    return;
  }
  const double now = elapsed_s();
  if (now - last_line_s_ < interval_s_) return;
  last_line_s_ = now;
  char head[64];
  std::snprintf(head, sizeof head, ": %.1f %% after ", 100.0 * fraction);
  std::string line = label_ + head + seconds_text(now);
  if (fraction > 0.0 && now > 0.0) {
    char rate[48];
    std::snprintf(rate, sizeof rate, " (%.1f %%/s, about ", 100.0 * fraction / now);
    line += rate + seconds_text(now * (1.0 - fraction) / fraction) + " left)";
  }
  std::fprintf(out_, "%s\n", line.c_str());
  std::fflush(out_);
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  if (!updated_) return;
  if (terminal_) {
    if (last_permille_ >= 0) std::fprintf(out_, "\r%s done  \n", label_.c_str());
    return;
  }
  // The last line says how far the work got: 100 % when it ran to the end, less when it stopped.
  char how_far[48];
  if (last_fraction_ >= 1.0) {
    std::snprintf(how_far, sizeof how_far, "done");
  } else {
    std::snprintf(how_far, sizeof how_far, "stopped at %.1f %%", 100.0 * last_fraction_);
  }
  std::fprintf(out_, "%s: %s after %s\n", label_.c_str(), how_far, seconds_text(elapsed_s()).c_str());
  std::fflush(out_);
}

}  // namespace imucal::cli

namespace {

/// What was printed on stdout must have arrived: a full disk or a closed pipe behind it turns a
/// success into exit 7 (an output could not be written).
int checked_stdout(int code) {
  std::cout.flush();
  errno = 0;
  const bool failed = !std::cout.good() || std::fflush(stdout) != 0 || std::ferror(stdout) != 0;
  if (!failed) return code;
  const int err = errno;
  std::cerr << "imucal: could not write the output to standard output"
            << (err != 0 ? std::string(": ") + std::strerror(err) : std::string()) << "\n";
  return code == imucal::cli::kExitOk ? imucal::cli::kExitIo : code;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace imucal::cli;
  // The solvers allocate and free the same large blocks (Jacobians, normal equations) every
  // iteration; by default glibc hands each back to the kernel and faults it in again, a fifth of
  // the camera-IMU solve's time. A command that ends after its solve keeps them (glibc's largest
  // mmap threshold; docs/benchmarks.md, "End to end").
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
  imucal::limit_openmp_teams();
  // Results go to stdout, diagnostics (warnings, progress, logs) to stderr.
  spdlog::set_default_logger(spdlog::stderr_color_mt("imucal"));
  spdlog::set_pattern("%^%l%$: %v");
  spdlog::set_level(spdlog::level::warn);
  // The calibrations' messages name this program's flags (core/option_words.hpp).
  imucal::set_option_vocabulary(&cli_option_words);

  CLI::App app{
      "imucal: calibrate MPU-6000 IMUs and camera-IMU rigs, offline tools.\n"
      "Run 'imucal COMMAND --help' for the options of a command."};
  app.set_version_flag("--version", std::string("imucal ") + imucal::kVersion);
  app.footer(
      "Examples:\n"
      "  imucal sim static -o static.imulog                  # a recording of the virtual rig, with its "
      "truth\n"
      "  imucal calibrate static static.imulog -o imu.yaml   # the IMU's intrinsics from its still poses\n"
      "  imucal sim camimu -o camimu.imulog                  # IMU and rendered camera frames\n"
      "  imucal calibrate camera camimu.imulog -o camchain.yaml\n"
      "  imucal calibrate camimu camimu.imulog --camera camchain.yaml -o camimu\n"
      "  imucal record --config /etc/imucal/rig.yaml --duration 60 -o rig.imulog   # the rig's own devices\n"
      "  imucal store read --config /etc/imucal/rig.yaml     # the calibration on the rig's storage\n"
      "The service's guided session: imucalctl (docs/service.md).");
  app.require_subcommand(1);
  app.fallthrough();
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "Log more (info level)")->each([](const std::string&) {
    spdlog::set_level(spdlog::level::info);
  });

  auto commands = registry();
  std::stable_sort(commands.begin(), commands.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (auto& [order, setup] : commands) setup(app);
  add_examples(app);

  int code = kExitOk;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // A mistyped command would be "A subcommand is required": name the nearest one.
    const std::string unknown =
        e.get_exit_code() != 0 ? imucal::cli::unknown_command_message(app, "imucal", argc, argv) : "";
    if (!unknown.empty()) {
      std::cerr << "imucal: " << unknown << "\n";
      return checked_stdout(kExitUsage);
    }
    const int rc = app.exit(e);
    code = rc == 0 ? kExitOk : kExitUsage;
  } catch (const CliExit& e) {
    if (!e.message.empty()) std::cerr << "imucal: " << e.message << "\n";
    code = e.code;
  } catch (const std::exception& e) {
    std::cerr << "imucal: unexpected error: " << e.what() << "\n";
    code = kExitFailure;
  }
  return checked_stdout(code);
}
