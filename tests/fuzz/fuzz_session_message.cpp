// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: one session message as the console reads it from the socket and replay from a
// session log (core/session_messages.hpp). Any bytes must give a message or an error with a
// message, never a crash or an exception; a decoded message must encode, and decode again to
// the same JSON.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "core/session_messages.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal::session_msg;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const auto message = parse(text);
  if (!message.ok()) {
    if (message.error().message.empty()) std::abort();
  } else {
    const std::string once = dump(*message);
    const auto again = parse(once);
    if (!again.ok() || dump(*again) != once) std::abort();
  }
  (void)type_of(text);
  const auto frame = parse_frame_event(text);
  if (!frame.ok() && frame.error().message.empty()) std::abort();
  return 0;
}
