#pragma once
// Reading a whole text file that a user names (datasets, configurations, targets): one read of
// the known size, refusing what is not a regular file (a FIFO would block, /dev/zero never ends)
// and, with a limit, files far larger than such a file can be.

#include <cstddef>
#include <limits>
#include <string>
#include <string_view>

#include "core/result.hpp"

namespace imucal {

/// Reads the file at `path`. Errors name the path: kNotFound (missing, a folder, not a regular
/// file), kInvalidArgument (larger than `max_bytes`), kCorrupt (a read error, with how far it got:
/// an unreadable input, exit 3 in the CLI).
[[nodiscard]] Result<std::string> read_text_file(
    const std::string& path, std::size_t max_bytes = std::numeric_limits<std::size_t>::max());

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
