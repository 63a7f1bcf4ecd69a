// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: the payload of a stored calibration record (CBOR of the record's JSON form,
// core/calibration_record.hpp) as `store read`, `store verify`, `store rollback` and imucald's
// session start decode it. Checks what they promise: no crash (a deep nesting overflowed the
// stack of nlohmann's recursive parser), a refusal always says why, and a record that is
// accepted encodes to JSON that reads back as the same calibration.

#include <cstdint>
#include <cstdlib>
#include <span>

#include "core/calibration_payload.hpp"
#include "core/calibration_record.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal;
  auto payload = calibration_payload_json(std::span<const std::uint8_t>(data, size));
  if (!payload.ok()) {
    if (payload.error().message.empty()) std::abort();
    return 0;
  }
  auto record = calibration_record_from_json(*payload);
  if (!record.ok()) {
    if (record.error().message.empty()) std::abort();
    return 0;
  }
  const auto cbor = nlohmann::json::to_cbor(calibration_record_json(*record));
  // Numbers given as half floats come back as doubles: a large accepted input may encode past
  // the bound, which a writer checks (store write) before it writes.
  if (cbor.size() > kMaxCalibrationPayloadBytes) return 0;
  auto again = calibration_payload_json(cbor);
  if (!again.ok()) std::abort();
  auto back = calibration_record_from_json(*again);
  if (!back.ok() || !same_calibration(*back, *record)) std::abort();
  return 0;
}
