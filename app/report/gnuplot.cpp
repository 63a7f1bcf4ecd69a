// SPDX-License-Identifier: BSD-3-Clause
#include "app/report/gnuplot.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

extern char** environ;

namespace imucal::app::report {
namespace {

constexpr const char* kInstallHint =
    "gnuplot is not installed: the report's figures are drawn by gnuplot. Install the Debian package "
    "gnuplot-nox (apt-get install --no-install-recommends gnuplot-nox, or scripts/install-deps.sh)";

std::string read_whole(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The outcome of one gnuplot run: its exit status and what it wrote on stderr.
struct RunOutcome {
  int status = 0;  // as from waitpid
  std::string err;
};

/// Runs gnuplot with `args` (stdin and stdout on /dev/null, stderr into `err_path`).
Result<RunOutcome> run_gnuplot(const std::vector<std::string>& args, const std::string& err_path) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  std::vector<std::string> copy = args;
  std::vector<char*> argv;
  std::string program = "gnuplot";
  argv.push_back(program.data());
  for (auto& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc == ENOENT) return make_error(Errc::kUnsupported, kInstallHint);
  if (rc != 0)
    return make_error(Errc::kUnsupported, std::string("gnuplot could not be started: ") + std::strerror(rc));
  RunOutcome out;
  while (waitpid(pid, &out.status, 0) < 0) {
    if (errno != EINTR)
      return make_error(Errc::kInternal, std::string("waiting for gnuplot: ") + std::strerror(errno));
  }
  out.err = read_whole(err_path);
  return out;
}

std::string terminal_line(const Figure& f, FigureFormat format) {
  const std::string size = std::to_string(f.width_px) + "," + std::to_string(f.height_px);
  if (format == FigureFormat::kSvg)
    return "set terminal svg size " + size + " dynamic enhanced font 'Sans,12' background rgb 'white'\n";
  return "set terminal pngcairo size " + size + " enhanced font 'Sans,10' background rgb 'white'\n";
}

}  // namespace

std::string datablock(const std::string& name, const std::vector<std::vector<double>>& rows) {
  std::string out = "$" + name + " << EOD\n";
  char buf[32];
  for (const auto& row : rows) {
    for (std::size_t i = 0; i < row.size(); ++i) {
      // NaN breaks a line in gnuplot; it reads "NaN" as a missing value.
      std::snprintf(buf, sizeof buf, "%.10g", row[i]);
      if (i) out += ' ';
      out += std::isfinite(row[i]) ? buf : "NaN";
    }
    out += '\n';
  }
  out += "EOD\n";
  return out;
}

std::string gp_quote(const std::string& text) {
  std::string out = "'";
  for (char c : text) {
    if (c == '\'')
      out += "''";  // gnuplot's escape inside single quotes
    else
      out += c;
  }
  return out + "'";
}

Result<std::string> render_figure(const Figure& figure, FigureFormat format, const std::string& work_dir) {
  const std::string ext = format == FigureFormat::kSvg ? ".svg" : ".png";
  const std::string script_path = work_dir + "/" + figure.id + ext + ".gp";
  const std::string output_path = work_dir + "/" + figure.id + ext;
  {
    std::ofstream script(script_path, std::ios::binary);
    script << terminal_line(figure, format) << "set output " << gp_quote(output_path) << "\n"
           << figure.script << "\nunset output\n";
    if (!script) return make_error(Errc::kIo, "could not write the gnuplot script " + script_path);
  }
  auto run = run_gnuplot({script_path}, work_dir + "/" + figure.id + ext + ".err");
  if (!run.ok()) return run.error();
  std::string image = read_whole(output_path);
  if (!WIFEXITED(run->status) || WEXITSTATUS(run->status) != 0 || image.empty()) {
    const std::string err = run->err.empty() ? "(nothing on stderr)" : run->err;
    return make_error(Errc::kInternal, "gnuplot failed to draw the figure '" + figure.id + "' (exit status " +
                                           std::to_string(WEXITSTATUS(run->status)) + "); gnuplot said:\n" +
                                           err);
  }
  std::error_code ec;
  std::filesystem::remove(script_path, ec);
  std::filesystem::remove(output_path, ec);
  return image;
}

Status check_gnuplot(const std::string& work_dir) {
  auto run = run_gnuplot({"--version"}, work_dir + "/version.err");
  if (!run.ok()) return run.error();
  if (!WIFEXITED(run->status) || WEXITSTATUS(run->status) != 0)
    return make_error(Errc::kUnsupported, "gnuplot --version failed: " + run->err);
  return {};
}

}  // namespace imucal::app::report
