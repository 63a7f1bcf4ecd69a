// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The checks that keep a command's outputs off its inputs and off each other (app/results/output.hpp
// applies them to every result file; commands that write other kinds of output call them too).

#include <string>
#include <vector>

#include "app/results/output.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// kInvalidArgument when writing `path` could replace one of `inputs`: the same file (by inode,
/// or by resolved path when one does not exist yet), or a folder that holds an input; or one of
/// `input_folders` (folders read as a whole, a EuRoC dataset): the folder itself, an existing
/// file inside it, or a folder around it. Every command checks each output against each of its
/// inputs with this before any work, whatever --force says.
[[nodiscard]] Status check_not_input(const std::string& path, const std::vector<std::string>& inputs,
                                     const std::vector<std::string>& input_folders = {});

/// A command's output, by the option that names it (for the messages).
struct NamedOutput {
  std::string option;  // "-o", "--json"
  std::string path;    // empty: not asked for
};

/// check_output for each output asked for, and no two of them the same file (kInvalidArgument
/// naming both options): with `-o X --json X` the second would replace the first.
[[nodiscard]] Status check_outputs(const std::vector<NamedOutput>& outputs, const OutputPolicy& policy);

}  // namespace imucal::app
