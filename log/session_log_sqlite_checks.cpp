// SPDX-License-Identifier: BSD-3-Clause
// The session log on SQLite: the checks of a log file made outside SQLite, before and while the
// reader opens it (size and header, truncation, the write-ahead log, a live writer).
// Schema and guarantees: docs/session-log.md.

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <system_error>

#include "log/session_log_sqlite.hpp"

namespace imucal::log::sqlite {

// Checks the file before SQLite sees it, so that the common mistakes get a precise message.
Status precheck_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT)
      return make_error(Errc::kNotFound, "no such session log: " + path + " (check the path)");
    return make_error(Errc::kNotFound, "cannot access session log " + path + ": " + std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) {
    return make_error(Errc::kNotFound, path + " is a directory, not a session log (.imulog file)");
  }
  if (!S_ISREG(st.st_mode)) {
    // A FIFO or a device would block the open below or read without end.
    return make_error(Errc::kNotFound, path + " is not a regular file, not a session log (.imulog file)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return make_error(Errc::kNotFound, "cannot read session log " + path + ": " + std::strerror(errno));
  char header[16] = {};
  in.read(header, sizeof header);
  const auto got = static_cast<std::size_t>(in.gcount());
  static constexpr char kMagic[16] = {'S', 'Q', 'L', 'i', 't', 'e', ' ', 'f',
                                      'o', 'r', 'm', 'a', 't', ' ', '3', '\0'};
  if (st.st_size == 0) {
    return make_error(Errc::kCorrupt, path +
                                          " is empty (0 bytes): the recording was lost before its first "
                                          "commit; record the session again");
  }
  if (got < sizeof header || std::memcmp(header, kMagic, sizeof kMagic) != 0) {
    if (std::memcmp(header, kMagic, got) == 0 && got < sizeof header) {
      return make_error(Errc::kCorrupt, path + " is truncated to " + std::to_string(st.st_size) +
                                            " bytes; nothing is readable");
    }
    return make_error(Errc::kCorrupt, path +
                                          " is not a session log (not an SQLite database); pass an .imulog "
                                          "file written by 'imucal record' or the imucal daemon");
  }
  if (st.st_size < 512) {
    return make_error(Errc::kCorrupt, path + " is truncated to " + std::to_string(st.st_size) +
                                          " bytes; nothing is readable");
  }
  return {};
}

// The page count in the file header against the file size: a copy that stopped early, or a
// file cut by a full disk, is shorter than its header says.
std::string truncation_of(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char h[100] = {};
  in.read(reinterpret_cast<char*>(h), sizeof h);
  if (in.gcount() != sizeof h) return {};
  const auto be32 = [&](int at) {
    return (std::uint32_t{h[at]} << 24) | (std::uint32_t{h[at + 1]} << 16) | (std::uint32_t{h[at + 2]} << 8) |
           h[at + 3];
  };
  std::uint64_t page_size = (std::uint64_t{h[16]} << 8) | h[17];
  if (page_size == 1) page_size = 65536;
  // The header page count is valid only when it was written by the same change as the counter.
  if (be32(24) != be32(92)) return {};
  const std::uint64_t expected = page_size * be32(28);
  std::error_code ec;
  const std::uint64_t actual = std::filesystem::file_size(path, ec);
  if (ec || actual >= expected) return {};
  return "the file is truncated: " + std::to_string(actual) + " of " + std::to_string(expected) +
         " bytes present, the rest is lost";
}

WalCheck check_wal(const std::string& path) {
  WalCheck out;
  std::ifstream in(path + "-wal", std::ios::binary);
  if (!in) return out;
  out.present = true;
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  out.size = bytes.size();
  if (bytes.empty()) return out;
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  // SQLite ignores a -wal whose header is bad, with every commit in it.
  const auto damaged_header = [&] {
    if (bytes.size() > 32)
      out.damage = "its write-ahead log " + path + "-wal has a damaged header: SQLite ignores all " +
                   std::to_string(bytes.size()) + " bytes of it, with every commit since the last checkpoint";
    return out;
  };
  const auto be32 = [&](std::size_t at) {
    return (std::uint32_t{b[at]} << 24) | (std::uint32_t{b[at + 1]} << 16) | (std::uint32_t{b[at + 2]} << 8) |
           b[at + 3];
  };
  if (bytes.size() < 32) {
    out.torn_tail = true;
    return out;
  }
  const std::uint32_t magic = be32(0);
  const std::uint32_t page_size = be32(8);
  if ((magic != 0x377f0682 && magic != 0x377f0683) || page_size < 512 || page_size > 65536 ||
      (page_size & (page_size - 1)) != 0) {
    return damaged_header();
  }
  const bool big_endian = (magic & 1) != 0;
  const auto word = [&](std::size_t at) {
    return big_endian ? be32(at)
                      : (std::uint32_t{b[at + 3]} << 24) | (std::uint32_t{b[at + 2]} << 16) |
                            (std::uint32_t{b[at + 1]} << 8) | b[at];
  };
  std::uint32_t s0 = 0, s1 = 0;
  const auto sum = [&](std::size_t at, std::size_t n) {
    for (std::size_t i = at; i + 8 <= at + n; i += 8) {
      s0 += word(i) + s1;
      s1 += word(i + 4) + s0;
    }
  };
  sum(0, 24);
  if (s0 != be32(24) || s1 != be32(28)) {
    return damaged_header();
  }
  const std::uint32_t salt1 = be32(16), salt2 = be32(20);
  const std::size_t frame = 24 + page_size;
  const std::size_t frames = (bytes.size() - 32) / frame;
  std::size_t valid = 0, last_commit = 0;  // frames in the intact chain; 1 + the last commit among them
  bool chain = true;
  std::size_t lost_commits = 0, lost_pages = 0;
  for (std::size_t k = 0; k < frames; ++k) {
    const std::size_t at = 32 + k * frame;
    const bool same_generation = be32(at + 8) == salt1 && be32(at + 12) == salt2;
    const bool commit = be32(at + 4) != 0;
    if (chain) {
      sum(at, 8);
      sum(at + 24, page_size);
      if (same_generation && s0 == be32(at + 16) && s1 == be32(at + 20)) {
        valid = k + 1;
        if (commit) last_commit = k + 1;
        continue;
      }
      chain = false;
    }
    if (same_generation) {
      ++lost_pages;
      if (commit) ++lost_commits;
    }
  }
  if (lost_commits > 0) {
    out.damage = "its write-ahead log " + path + "-wal is damaged at frame " + std::to_string(valid + 1) +
                 " of " + std::to_string(frames) + ": " + std::to_string(lost_commits) +
                 " later commit(s) of up to " + std::to_string(lost_pages) +
                 " pages are lost (the log reads as it was at the last intact commit)";
  }
  // A file that ends inside a frame, or in frames no commit completes, is what a writer leaves
  // when it stops while committing (killed, a full disk, a power loss): the log reads as it was
  // at its last commit and is incomplete. Only a closed log with such a tail is damaged.
  const std::size_t partial = (bytes.size() - 32) % frame;
  out.commits_replayed = last_commit > 0;
  out.torn_tail = partial != 0 || valid > last_commit || !chain;
  return out;
}

/// A log in WAL mode (header bytes 18 and 19 are 2) keeps what its writer committed since the
/// last checkpoint in LOG-wal: without it, an unclosed log may hold no tables at all.
bool in_wal_mode(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char h[20] = {};
  in.read(reinterpret_cast<char*>(h), sizeof h);
  return in.gcount() == sizeof h && h[18] == 2;
}

std::string no_tables_in_wal_mode(const std::string& path, const WalCheck& wal) {
  static const std::string kCopy =
      "a log that was not closed keeps its data there; copy that file next to the log";
  static const std::string kAgain = "nothing was recorded; record the session again";
  // As found before SQLite opened the log (its read-only open creates an empty -wal).
  if (!wal.present) {
    return path + " holds no session tables, and its write-ahead log " + path + "-wal is missing: " + kCopy +
           " (it was lost or not copied with it)";
  }
  if (wal.size > 0 && !wal.commits_replayed && wal.damage.empty()) {
    return path + " was stopped while it was being created, before its first commit (its write-ahead log " +
           path + "-wal holds no commit): " + kAgain;
  }
  if (wal.size == 0) {
    // Reading a log whose -wal was lost leaves an empty one behind, as does a writer stopped
    // before its first commit: the two look the same.
    return path + " holds no session tables, and its write-ahead log " + path +
           "-wal is empty: either the log was copied without its -wal (" + kCopy +
           "), or its writer stopped before its first commit (then " + kAgain + ")";
  }
  return path + " holds no session tables: its write-ahead log " + path + "-wal is damaged (" + wal.damage +
         ")";
}

/// True when a writer holds the log `st` describes (its flock, see lock_for_writing). A file
/// that this process does not have open is tested with a shared flock, held for an instant
/// (writers retry theirs); one open here is looked up in /proc/locks, whose first read costs a
/// process 5-30 ms on some kernels.
bool being_written(const std::string& path, const struct stat& st) {
  if (OpenHere::contains(st)) return flock_holder(st.st_dev, st.st_ino) != 0;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
  if (fd < 0) return flock_holder(st.st_dev, st.st_ino) != 0;
  struct stat opened {};
  bool held = false;
  if (::fstat(fd, &opened) != 0 || opened.st_dev != st.st_dev || opened.st_ino != st.st_ino) {
    held = flock_holder(st.st_dev, st.st_ino) != 0;  // replaced meanwhile
  } else if (::flock(fd, LOCK_SH | LOCK_NB) != 0) {
    held = errno == EWOULDBLOCK;
  }
  ::close(fd);  // drops the shared lock
  return held;
}

}  // namespace imucal::log::sqlite
