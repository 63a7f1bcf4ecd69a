// SPDX-License-Identifier: BSD-3-Clause
#include "core/calibration_payload.hpp"

#include <string>
#include <vector>

namespace imucal {

using nlohmann::json;

namespace {

/// Walks one CBOR item (RFC 8949) without recursion: the nesting depth and that every length
/// stays within the bytes. Empty when it is one whole item, else why not.
std::string check_cbor_shape(std::span<const std::uint8_t> b) {
  struct Open {
    std::uint64_t items;  // still to come (definite length)
    bool indefinite;      // ends with a break byte instead
  };
  std::vector<Open> open;
  std::size_t at = 0;
  bool first = true;
  while (first || !open.empty()) {
    first = false;
    if (at >= b.size()) return "ends inside an item (truncated)";
    const std::uint8_t initial = b[at++];
    const int major = initial >> 5;
    const int info = initial & 0x1F;
    if (initial == 0xFF) {  // break: ends the innermost indefinite-length item
      if (open.empty() || !open.back().indefinite)
        return "holds a break byte outside an indefinite-length item";
      open.pop_back();
    } else {
      std::uint64_t value = static_cast<std::uint64_t>(info);
      bool indefinite = false;
      if (info >= 24 && info <= 27) {
        const std::size_t n = std::size_t{1} << (info - 24);
        if (b.size() - at < n) return "ends inside an item (truncated)";
        value = 0;
        for (std::size_t i = 0; i < n; ++i) value = value << 8 | b[at++];
      } else if (info >= 28 && info <= 30) {
        return "holds a reserved CBOR length code";
      } else if (info == 31) {
        if (major == 0 || major == 1 || major == 6) return "holds an indefinite length on a number or tag";
        indefinite = major != 7;
      }
      std::uint64_t children = 0;
      switch (major) {
        case 2:
        case 3:  // byte and text strings: their bytes follow (an indefinite one: chunks)
          if (!indefinite) {
            if (value > b.size() - at) return "declares a string longer than the bytes present";
            at += static_cast<std::size_t>(value);
          }
          break;
        case 4:  // array
          children = value;
          break;
        case 5:  // map: a key and a value per entry
          if (value > (b.size() - at) / 2) return "declares a map longer than the bytes present";
          children = 2 * value;
          break;
        case 6:  // tag: one item follows
          children = 1;
          break;
        default:
          break;
      }
      // Every item takes at least a byte: a count beyond the bytes left cannot be honest.
      if (children > b.size() - at) return "declares more items than the bytes present";
      if (indefinite || children > 0) {
        if (static_cast<int>(open.size()) >= kMaxCalibrationPayloadDepth) {
          return "nests arrays, maps or tags deeper than " + std::to_string(kMaxCalibrationPayloadDepth) +
                 " levels (a calibration record has 4)";
        }
        open.push_back({children, indefinite});
        continue;
      }
    }
    // One item done: it counts against the items of the one that holds it.
    while (!open.empty() && !open.back().indefinite && --open.back().items == 0) open.pop_back();
  }
  if (at != b.size()) return "holds " + std::to_string(b.size() - at) + " bytes after its CBOR item";
  return {};
}

}  // namespace

Result<json> calibration_payload_json(std::span<const std::uint8_t> cbor) {
  if (cbor.size() > kMaxCalibrationPayloadBytes) {
    return make_error(Errc::kCorrupt, "is " + std::to_string(cbor.size()) +
                                          " bytes long, more than a record (at most " +
                                          std::to_string(kMaxCalibrationPayloadBytes) + ")");
  }
  if (const std::string why = check_cbor_shape(cbor); !why.empty()) {
    return make_error(Errc::kCorrupt, "is not a CBOR document this imucal reads: it " + why);
  }
  json j = json::from_cbor(cbor.begin(), cbor.end(), true, false);
  if (j.is_discarded()) return make_error(Errc::kCorrupt, "is not CBOR");
  return j;
}

}  // namespace imucal
