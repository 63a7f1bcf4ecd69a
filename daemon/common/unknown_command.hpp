// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// "unknown command 'calibrat'; did you mean 'calibrate'?" for a program with CLI11 subcommands,
// nested ones too (imucal calibrate static): CLI11 itself only says "A subcommand is required".
// Header-only (daemon/common/: what the programs share).

#include <CLI/CLI.hpp>
#include <algorithm>
#include <string>
#include <vector>

#include "core/closest_word.hpp"

namespace imucal::cli {

/// The first word of the command line that should name a subcommand and names none, with the
/// nearest subcommand when few edits away and the list of them; empty when every command word
/// is known (the parse error is then another one). Options are skipped; the walk stops at a
/// command without subcommands. `program`: the program's name in the message.
inline std::string unknown_command_message(const CLI::App& app, const std::string& program, int argc,
                                           char** argv) {
  const CLI::App* level = &app;
  std::string path = program;
  for (int i = 1; i < argc; ++i) {
    const std::string word = argv[i];
    if (word.empty() || word[0] == '-') continue;
    const auto subs = level->get_subcommands([](const CLI::App*) { return true; });
    if (subs.empty()) return {};
    std::vector<std::string> names;
    const CLI::App* next = nullptr;
    for (const CLI::App* sub : subs) {
      names.push_back(sub->get_name());
      if (sub->get_name() == word) next = sub;
    }
    if (next) {
      level = next;
      path += " " + word;
      continue;
    }
    return unknown_command_text(word, names, path);
  }
  return {};
}

}  // namespace imucal::cli
