#pragma once
// printf-style formatting into a std::string of whatever length the text needs, for messages
// that carry paths or numbers of any size (a fixed buffer would cut them short).

#include <string>

namespace imucal {

/// The text printf would print for `format` and its arguments, whole.
[[nodiscard]] std::string format_printf(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace imucal
