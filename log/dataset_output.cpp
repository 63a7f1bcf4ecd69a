// SPDX-License-Identifier: BSD-3-Clause
// Outputs that appear only when complete: write under a temporary name, rename on success.

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>
#include <vector>

#include "log/dataset_io.hpp"
#include "log/session_log_sqlite.hpp"

namespace imucal::log {
namespace fs = std::filesystem;

namespace {

void remove_file_family(const std::string& path) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) fs::remove(path + suffix, ec);
}

/// The writer's process id in a temporary's name after `final_name` (".tmp-<pid>",
/// ".partial-<pid>-<n>", either with a SQLite companion's suffix), or 0 when it is not one.
pid_t temporary_owner(const std::string& entry, const std::string& final_name) {
  if (entry.size() <= final_name.size() || entry.compare(0, final_name.size(), final_name) != 0) return 0;
  std::string rest = entry.substr(final_name.size());
  for (const std::string suffix : {"-wal", "-shm", "-journal"}) {
    if (rest.size() > suffix.size() && rest.ends_with(suffix)) {
      rest.resize(rest.size() - suffix.size());
      break;
    }
  }
  const auto digits = [](const std::string& t) {
    return !t.empty() && t.size() <= 9 && t.find_first_not_of("0123456789") == std::string::npos;
  };
  std::string pid;
  if (rest.starts_with(".tmp-")) {
    pid = rest.substr(5);
  } else if (rest.starts_with(".partial-")) {
    const std::string tail = rest.substr(9);
    const auto dash = tail.find('-');
    if (dash == std::string::npos || !digits(tail.substr(dash + 1))) return 0;
    pid = tail.substr(0, dash);
  }
  if (!digits(pid)) return 0;
  return static_cast<pid_t>(std::stol(pid));
}

}  // namespace

void remove_stale_temporaries(const std::string& final_path) {
  std::string base = final_path;
  while (base.size() > 1 && base.back() == '/') base.pop_back();
  const fs::path path(base);
  const std::string name = path.filename().string();
  if (name.empty()) return;
  const fs::path parent = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  std::vector<fs::path> stale;
  std::error_code ec;
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const pid_t pid = temporary_owner(it->path().filename().string(), name);
    if (pid <= 0 || pid == ::getpid()) continue;          // not a temporary, or this process's own
    if (::kill(pid, 0) == 0 || errno != ESRCH) continue;  // its writer may still run
    stale.push_back(it->path());
  }
  for (const fs::path& p : stale) fs::remove_all(p, ec);
}

PendingOutput::PendingOutput(std::string final_path, std::string temp_path, Kind kind, bool force)
    : final_path_(std::move(final_path)), temp_path_(std::move(temp_path)), kind_(kind), force_(force) {}

PendingOutput::PendingOutput(PendingOutput&& other) noexcept
    : final_path_(std::move(other.final_path_)),
      temp_path_(std::move(other.temp_path_)),
      kind_(other.kind_),
      force_(other.force_),
      done_(other.done_) {
  other.done_ = true;
}

PendingOutput::~PendingOutput() { discard(); }

void PendingOutput::discard() {
  if (done_) return;
  done_ = true;
  std::error_code ec;
  if (kind_ == Kind::kDirectory) {
    fs::remove_all(temp_path_, ec);
  } else {
    remove_file_family(temp_path_);
  }
}

Result<PendingOutput> PendingOutput::begin(const std::string& final_path, Kind kind, bool force) {
  if (final_path.empty()) return make_error(Errc::kInvalidArgument, "the output path is empty");
  std::error_code ec;
  const fs::path path(final_path);
  fs::path parent = path.parent_path();
  if (parent.empty()) parent = ".";
  if (!fs::is_directory(parent, ec)) {
    return make_error(Errc::kIo, "cannot write " + final_path + ": folder " + parent.string() +
                                     " does not exist (create it first)");
  }
  const auto status = fs::symlink_status(path, ec);
  if (fs::exists(status)) {
    const bool is_dir = fs::is_directory(status);
    if (kind == Kind::kFile && is_dir) {
      return make_error(Errc::kInvalidArgument, "output " + final_path + " is a folder; give a file name");
    }
    if (kind == Kind::kDirectory && !is_dir) {
      return make_error(Errc::kInvalidArgument, "output " + final_path + " exists and is not a folder");
    }
    const bool empty_dir = is_dir && fs::is_empty(path, ec);
    if (!force && !empty_dir) {
      return make_error(Errc::kAlreadyExists, "output " + final_path + " already exists");
    }
    if (kind == Kind::kFile) IMUCAL_TRY(check_replaceable(final_path));
  }
  remove_stale_temporaries(final_path);
  std::string temp = final_path;
  while (!temp.empty() && temp.back() == '/') temp.pop_back();
  // Unique per process and output, so two outputs to one path never share a temporary.
  static std::atomic<unsigned> serial{0};
  temp += ".partial-" + std::to_string(::getpid()) + "-" + std::to_string(serial++);
  PendingOutput out(final_path, temp, kind, force);
  // A leftover from an earlier crash of a process with the same id.
  if (kind == Kind::kDirectory) {
    fs::remove_all(temp, ec);
    if (!fs::create_directory(temp, ec)) {
      out.done_ = true;
      return make_error(Errc::kIo, "cannot create " + temp + ": " + ec.message());
    }
  } else {
    remove_file_family(temp);
  }
  return out;
}

Status PendingOutput::commit() {
  if (done_)
    return make_error(Errc::kInternal, "output " + final_path_ + " was already committed or discarded");
  std::error_code ec;
  std::string final_path = final_path_;
  while (final_path.size() > 1 && final_path.back() == '/') final_path.pop_back();
  if (kind_ == Kind::kFile) {
    if (force_) {
      // A stale -wal next to the replaced log would be replayed into the new one.
      for (const char* suffix : {"-wal", "-shm", "-journal"}) fs::remove(final_path + suffix, ec);
    }
    IMUCAL_TRY(rename_into_place(temp_path_, final_path, force_));
    done_ = true;
    return {};
  }
  const bool exists = fs::exists(final_path, ec);
  if (exists && !fs::is_empty(final_path, ec)) {
    if (!force_)
      return make_error(Errc::kInvalidArgument, "output " + final_path + " appeared while writing");
    const std::string old = final_path + ".replaced-" + std::to_string(::getpid());
    fs::rename(final_path, old, ec);
    if (ec) return make_error(Errc::kIo, "cannot move the old " + final_path + " aside: " + ec.message());
    fs::rename(temp_path_, final_path, ec);
    if (ec) {
      std::error_code ignored;
      fs::rename(old, final_path, ignored);
      return make_error(Errc::kIo, "cannot move " + temp_path_ + " to " + final_path + ": " + ec.message());
    }
    fs::remove_all(old, ec);
  } else {
    if (exists) fs::remove(final_path, ec);  // an empty folder
    fs::rename(temp_path_, final_path, ec);
    if (ec)
      return make_error(Errc::kIo, "cannot move " + temp_path_ + " to " + final_path + ": " + ec.message());
  }
  done_ = true;
  return {};
}

Status check_replaceable(const std::string& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) return {};
  if (!fs::is_regular_file(status)) {
    return make_error(Errc::kInvalidArgument,
                      path +
                          " exists and is not a regular file (a device, FIFO, socket or folder); it is never "
                          "replaced, --force or not: write the output to a file");
  }
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return {};
  Status result;
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK) {
    result = make_error(Errc::kIo, path + " is being written by " + sqlite::lock_holder(fd) +
                                       " (a recording in progress); stop it first, or write to another file");
  } else {
    ::flock(fd, LOCK_UN);
  }
  ::close(fd);
  return result;
}

Status rename_into_place(const std::string& from, const std::string& to, bool replace) {
  if (replace) IMUCAL_TRY(check_replaceable(to));
  int rc = replace ? ::rename(from.c_str(), to.c_str())
                   : ::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE);
  if (rc != 0 && !replace && errno == EINVAL) {  // a filesystem without RENAME_NOREPLACE
    rc = ::link(from.c_str(), to.c_str());
    if (rc == 0) ::unlink(from.c_str());
  }
  if (rc == 0) return {};
  if (errno == EEXIST)
    return make_error(Errc::kAlreadyExists, "output " + to +
                                                " appeared while it was being written (another "
                                                "process wrote it); " +
                                                from + " was not moved there");
  return make_error(Errc::kIo, "cannot move " + from + " to " + to + ": " + std::strerror(errno));
}

}  // namespace imucal::log
