// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: a rig configuration file (core/rig_config.hpp) and a Kalibr target YAML
// (core/target.hpp), the first byte choosing which. Any bytes must give a configuration or an
// error with a message, never a crash, an uncaught exception (yaml-cpp's or nlohmann's) or a
// hang; an accepted configuration must validate and print as YAML and as JSON (what `imucal
// config check [--json]` and the recorder's log metadata do), and an accepted target must have
// points and print back.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "core/rig_config.hpp"
#include "core/target.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal;
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] % 2 == 0) {
    // base_dir is a folder that does not exist: a relative target path fails to load instead
    // of reading whatever lies around; absolute paths (/dev/zero, a FIFO) are the parser's to
    // refuse.
    auto config = parse_rig_config(text, "fuzz.yaml", "/nonexistent-fuzz-dir");
    if (!config.ok()) {
      if (config.error().message.empty()) std::abort();
      return 0;
    }
    if (!validate_rig_config(*config).ok()) std::abort();
    (void)rig_config_to_yaml(*config);
    (void)rig_config_to_json(*config);
  } else {
    auto target = parse_target_yaml(text, "fuzz-target.yaml");
    if (!target.ok()) {
      if (target.error().message.empty()) std::abort();
      return 0;
    }
    if (target->points().empty()) std::abort();
    (void)target_to_yaml(*target);
  }
  return 0;
}
