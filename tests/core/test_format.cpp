#include <gtest/gtest.h>

#include <string>

#include "core/format.hpp"

namespace imucal {
namespace {

TEST(FormatPrintf, KeepsTheWholeTextHoweverLong) {
  const std::string path(5000, 'p');
  const std::string text = format_printf("kept %zu samples in %s, readable", std::size_t{6000}, path.c_str());
  EXPECT_EQ(text, "kept 6000 samples in " + path + ", readable");
  EXPECT_EQ(format_printf("%.1f", 1e300).size(), 303u);  // 301 digits, the point, one decimal
  EXPECT_EQ(format_printf("%s", ""), "");
}

}  // namespace
}  // namespace imucal
