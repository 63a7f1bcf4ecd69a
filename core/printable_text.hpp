// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Text from outside the program (a socket client, a file) made safe to show on a terminal.

#include <string>
#include <string_view>

namespace imucal {

/// `text` safe to put on a terminal: every control character (C0 but the newline when
/// `keep_newlines`, DEL, and the C1 range U+0080..U+009F, which holds CSI) and every byte that is
/// not well-formed UTF-8 becomes U+FFFD, so that text from a socket client or a file cannot move
/// the cursor, clear the screen, retitle the window or draw a fake message.
std::string printable_text(std::string_view text, bool keep_newlines = false);

/// Whether `text` is printable_text(text) already (no control character, well-formed UTF-8).
bool is_printable_text(std::string_view text);

}  // namespace imucal
