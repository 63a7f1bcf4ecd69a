// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/output.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "app/results/output_checks.hpp"
#include "log/dataset_io.hpp"

namespace imucal::app {

namespace {

/// `path` resolved as far as it exists (symbolic links, `..`), absolute.
std::filesystem::path resolved(const std::string& path) {
  std::error_code ec;
  return std::filesystem::weakly_canonical(std::filesystem::absolute(path, ec), ec);
}

/// Whether two paths name one file: the same inode when both exist, else the same resolved path.
bool same_file(const std::string& a, const std::string& b) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) return fs::equivalent(a, b, ec);
  const fs::path ra = resolved(a);
  return !ra.empty() && ra == resolved(b);
}

/// Whether `inner` lies inside the folder `outer` (both resolved).
bool inside(const std::filesystem::path& inner, const std::filesystem::path& outer) {
  if (inner.empty() || outer.empty()) return false;
  const std::filesystem::path rel = inner.lexically_relative(outer);
  return !rel.empty() && rel != "." && *rel.begin() != "..";
}

}  // namespace

Status check_not_input(const std::string& path, const std::vector<std::string>& inputs,
                       const std::vector<std::string>& input_folders) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const std::string rule = "; write the result to another file (--force never replaces an input)";
  for (const auto& input : inputs) {
    if (input.empty()) continue;
    if (same_file(path, input)) {
      return make_error(Errc::kInvalidArgument, path + " is an input of this command" + rule);
    }
    if (fs::is_directory(path, ec) && fs::exists(input, ec) && inside(resolved(input), resolved(path))) {
      return make_error(Errc::kInvalidArgument,
                        path + " holds " + input + ", an input of this command" + rule);
    }
  }
  for (const auto& folder : input_folders) {
    if (folder.empty()) continue;
    const fs::path r = resolved(path);
    if (same_file(path, folder) || (fs::exists(path, ec) && inside(r, resolved(folder))) ||
        (fs::is_directory(path, ec) && inside(resolved(folder), r))) {
      return make_error(Errc::kInvalidArgument, path + " is, holds or lies in " + folder +
                                                    ", an input folder of this command" + rule);
    }
  }
  return {};
}

Status check_output(const std::string& path, const OutputPolicy& policy) {
  namespace fs = std::filesystem;
  std::error_code ec;
  IMUCAL_TRY(check_not_input(path, policy.inputs));
  if (fs::is_directory(path, ec))
    return make_error(Errc::kInvalidArgument, path + " is a folder, not a file");
  IMUCAL_TRY(log::check_replaceable(path));
  if (!policy.overwrite && fs::exists(path, ec)) return make_error(Errc::kAlreadyExists, path + " exists");
  return {};
}

Status check_outputs(const std::vector<NamedOutput>& outputs, const OutputPolicy& policy) {
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    if (outputs[i].path.empty()) continue;
    for (std::size_t k = 0; k < i; ++k) {
      if (!outputs[k].path.empty() && same_file(outputs[k].path, outputs[i].path)) {
        return make_error(Errc::kInvalidArgument, outputs[k].option + " and " + outputs[i].option +
                                                      " name the same file (" + outputs[i].path +
                                                      "): give each output a file of its own");
      }
    }
    IMUCAL_TRY(check_output(outputs[i].path, policy));
  }
  return {};
}

Status write_text_file(const std::string& path, const std::string& text, const OutputPolicy& policy) {
  IMUCAL_TRY(check_output(path, policy));
  log::remove_stale_temporaries(path);  // a killed writer's "<path>.tmp-<pid>"
  const std::string temp = path + ".tmp-" + std::to_string(::getpid());
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    return make_error(Errc::kIo, "could not write " + path + ": " + std::strerror(errno) +
                                     " (check the folder exists and is writable)");
  }
  std::size_t done = 0;
  int err = 0;
  while (done < text.size()) {
    const ssize_t w = ::write(fd, text.data() + done, text.size() - done);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0) {
      err = errno;
      break;
    }
    done += static_cast<std::size_t>(w);
  }
  if (err == 0 && ::fsync(fd) != 0) err = errno;
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0) {
    if (Status moved = log::rename_into_place(temp, path, policy.overwrite); !moved.ok()) {
      ::unlink(temp.c_str());
      return moved.error();
    }
  }
  if (err != 0) {
    ::unlink(temp.c_str());
    return make_error(Errc::kIo, "could not write " + path + ": " + std::strerror(err) +
                                     (err == ENOSPC ? " (the disk is full)" : "") + "; nothing was replaced");
  }
  return {};
}

}  // namespace imucal::app
