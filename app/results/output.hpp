// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Writing a result file: the output checks every command makes before its work (an input is never
// written over, an existing file only when asked) and the atomic write (a temporary file beside
// it, flushed, renamed).

#include <string>
#include <vector>

#include "core/result.hpp"

namespace imucal::app {

/// How a result file may be written.
struct OutputPolicy {
  bool overwrite = false;           // replace an existing file
  std::vector<std::string> inputs;  // files the command reads: never written over
};

/// Whether `path` may be written under `policy`, checked before the work that produces it:
/// kInvalidArgument when it could replace one of the inputs (check_not_input, whatever the policy),
/// kAlreadyExists when it exists and may not be replaced.
[[nodiscard]] Status check_output(const std::string& path, const OutputPolicy& policy);

/// Writes `text` as the whole content of `path` after check_output: into a temporary file beside
/// it, flushed to disk, then renamed over `path`, so that a reader never sees a partial file and
/// a failure (a full disk) leaves any earlier file as it was. Errc::kIo on failure.
[[nodiscard]] Status write_text_file(const std::string& path, const std::string& text,
                                     const OutputPolicy& policy = {});

}  // namespace imucal::app
