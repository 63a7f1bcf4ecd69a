// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include "core/option_words.hpp"

namespace imucal {
namespace {

std::string flags(CalibOption option, std::string_view value) {
  return option == CalibOption::kShutter ? "--shutter " + std::string(value) : "--other";
}

// Restores the process's vocabulary when a test ends.
struct Restore {
  OptionVocabulary before = set_option_vocabulary(nullptr);
  ~Restore() { set_option_vocabulary(before); }
};

TEST(OptionWords, WithoutAHostTheQuantityIsNamedWithItsValue) {
  Restore restore;
  EXPECT_EQ(option_words(CalibOption::kShutter, "rolling"), "shutter: rolling");
  EXPECT_EQ(option_words(CalibOption::kLineDelay), "line delay: given");
  EXPECT_EQ(option_words(CalibOption::kHoldTimeOffsets), "time offsets: held");
  EXPECT_EQ(option_words(CalibOption::kAccelModel, "faces"), "accelerometer model: faces");
  // Every option has words of its own, and none is a flag.
  for (int o = 0; o <= static_cast<int>(CalibOption::kImportScales); ++o) {
    const std::string w = plain_option_words(static_cast<CalibOption>(o), "");
    EXPECT_NE(w.find(": "), std::string::npos) << o;
    EXPECT_EQ(w.find("--"), std::string::npos) << w;
  }
}

TEST(OptionWords, TheInstalledVocabularyIsUsedUntilAnotherIs) {
  Restore restore;
  EXPECT_EQ(set_option_vocabulary(&flags), nullptr);
  EXPECT_EQ(option_words(CalibOption::kShutter, "global"), "--shutter global");
  EXPECT_EQ(option_words(CalibOption::kFix), "--other");
  EXPECT_EQ(set_option_vocabulary(nullptr), &flags);
  EXPECT_EQ(option_words(CalibOption::kShutter, "global"), "shutter: global");
}

}  // namespace
}  // namespace imucal
