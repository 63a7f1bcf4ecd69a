// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: one line from a control socket client (daemon/service/protocol.hpp). Any bytes
// must give a request or an error with a message, never a crash or an exception; a parsed
// request must be well formed, and the reply to it must serialise.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "daemon/service/protocol.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal::service;
  const std::string_view line(reinterpret_cast<const char*>(data), size);
  const auto request = parse_request(line);
  if (request.ok()) {
    const bool needs_key = request->command == Command::kKey || request->command == Command::kAbort ||
                           request->command == Command::kAccept;
    if (needs_key) {
      // The key, typed, goes back on the line as the same key.
      const std::string again = to_line(to_json(*request));
      const auto back = parse_request(std::string_view(again).substr(0, again.size() - 1));
      if (!back.ok() || back->key != request->key) {
        std::abort();
      }
    }
    for (const auto& step : request->steps) {
      if (step.empty()) {
        std::abort();
      }
    }
    (void)to_line(make_reply(command_name(request->command), {}));
  } else {
    if (request.error().message.empty()) {
      std::abort();
    }
    (void)to_line(make_reply(command_of(line), request.error()));
  }
  return 0;
}
