// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The nearest of a few words to a mistyped one, for "did you mean ...?" hints (the programs'
// subcommands), and the answer to a mistyped command in one wording. Header-only.

#include <algorithm>
#include <string>
#include <string_view>
#include <vector>

namespace imucal {

/// Levenshtein distance: the insertions, deletions and substitutions that turn `a` into `b`.
inline std::size_t word_edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

/// The candidate nearest `word` when at most `max_distance` edits away (the first of equals), else
/// empty.
inline std::string closest_word(std::string_view word, const std::vector<std::string>& candidates,
                                std::size_t max_distance) {
  std::string best;
  std::size_t best_distance = max_distance + 1;
  for (const std::string& c : candidates) {
    const std::size_t d = word_edit_distance(word, c);
    if (d < best_distance) {
      best_distance = d;
      best = c;
    }
  }
  return best;
}

/// The answer to a command word that names none of `commands` (the subcommands at `path`, such
/// as "imucal calibrate"): "unknown command 'statc'; did you mean 'static'? The commands of
/// 'imucal calibrate': ... (imucal calibrate --help)". The programs find the word; this words it.
inline std::string unknown_command_text(const std::string& word, const std::vector<std::string>& commands,
                                        const std::string& path) {
  std::string all;
  for (const auto& c : commands) all += (all.empty() ? "" : ", ") + c;
  const std::string near = closest_word(word, commands, word.size() <= 3 ? 1 : 2);
  return "unknown command '" + word + "'" + (near.empty() ? "" : "; did you mean '" + near + "'?") +
         " The commands of '" + path + "': " + all + " (" + path + " --help)";
}

}  // namespace imucal
