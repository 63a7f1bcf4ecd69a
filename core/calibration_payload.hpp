// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The calibration record's payload as the storage holds it (CBOR of the record's JSON form,
// core/calibration_record.hpp), decoded with bounds: nlohmann's CBOR parser recurses once per
// level of nesting, so a payload of a million nested arrays would overflow the stack.

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <span>

#include "core/result.hpp"

namespace imucal {

/// What a stored payload may be: the record is a few KiB nested 4 deep.
inline constexpr int kMaxCalibrationPayloadDepth = 32;
inline constexpr std::size_t kMaxCalibrationPayloadBytes = 256 * 1024;

/// The JSON form of a stored payload. The bytes are walked first without recursion and refused
/// when they are longer than kMaxCalibrationPayloadBytes, nest arrays, maps or tags deeper than
/// kMaxCalibrationPayloadDepth, declare a length beyond the bytes present, or are not one whole
/// CBOR item; only then are they parsed. kCorrupt with a message that completes "the payload ...".
[[nodiscard]] Result<nlohmann::json> calibration_payload_json(std::span<const std::uint8_t> cbor);

}  // namespace imucal
