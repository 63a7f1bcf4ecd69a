// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Reading a whole text file that a user names (datasets, configurations, targets): one read of
// the known size, refusing what is not a regular file (a FIFO would block, /dev/zero never ends)
// and, with a limit, files far larger than such a file can be.

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/result.hpp"

namespace imucal {

/// Reads the file at `path`. Errors name the path: kNotFound (missing, a folder, not a regular
/// file), kInvalidArgument (larger than `max_bytes`), kCorrupt (a read error, with how far it got:
/// an unreadable input, exit 3 in the CLI).
[[nodiscard]] Result<std::string> read_text_file(
    const std::string& path, std::size_t max_bytes = std::numeric_limits<std::size_t>::max());

/// Reads a text file line by line in chunks, so that the file is never held whole: memory is one
/// chunk plus the longest line. It refuses what read_text_file refuses (a folder, a FIFO or
/// device), and a read error ends the reading with an error, never as an early end of the file.
class TextLineReader {
 public:
  static constexpr std::size_t kChunkBytes = 1 << 20;
  static constexpr std::size_t kMaxLineBytes = 1 << 20;

  /// Opens `path`; errors as read_text_file's. `chunk_bytes` is for tests of chunk boundaries.
  [[nodiscard]] static Result<std::unique_ptr<TextLineReader>> open(const std::string& path,
                                                                    std::size_t chunk_bytes = kChunkBytes);
  ~TextLineReader();
  TextLineReader(const TextLineReader&) = delete;
  TextLineReader& operator=(const TextLineReader&) = delete;

  /// The next line, without its '\n'; valid until the next call. False at the end of the file and
  /// on an error (a read error, a line longer than kMaxLineBytes): then error() says which.
  bool next(std::string_view& line);
  [[nodiscard]] const std::optional<Error>& error() const { return error_; }
  /// Bytes of the file consumed so far, and the file's size when opened (for progress).
  [[nodiscard]] std::uint64_t offset() const { return consumed_; }
  [[nodiscard]] std::uint64_t size() const { return size_; }

 private:
  TextLineReader(int fd, std::string path, std::uint64_t size, std::size_t chunk_bytes);
  bool fill();  // reads one more chunk behind the unread part; false at the end or on an error

  int fd_;
  std::string path_;
  std::uint64_t size_;
  std::size_t chunk_bytes_;
  std::string buffer_;
  std::size_t pos_ = 0;  // start of the unread part of buffer_
  std::uint64_t consumed_ = 0;
  bool eof_ = false;
  std::optional<Error> error_;
};

/// True when `text` is well-formed UTF-8 (no overlong forms, surrogates or code points above
/// U+10FFFF): what JSON output and the control socket can carry.
bool valid_utf8(std::string_view text);

/// `text` for an error message: control characters, a byte-order mark and bytes that are not
/// UTF-8 shown as \xNN, and at most `max_chars` characters (then "...").
std::string printable(std::string_view text, std::size_t max_chars = 80);

/// The limit for configuration and target files (they are a few kilobytes).
inline constexpr std::size_t kMaxConfigFileBytes = 1 << 20;

/// The limit for result files that commands read back (calibrations, camchains, imu.yaml):
/// far above the largest imucal writes, far below what would exhaust memory.
inline constexpr std::size_t kMaxResultFileBytes = 64 << 20;

}  // namespace imucal
