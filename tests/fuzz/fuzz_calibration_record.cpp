// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: the calibration record (drivers/storage/record.hpp) and the A/B store reading a
// device image of arbitrary bytes (drivers/storage/calibration_store.hpp). Checks what they
// promise: no crash or out-of-range read on any input, a record that decodes encodes back to
// the same bytes, and read_latest() returns a record only when one of its slots decodes to it.

#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/fake/memory_storage.hpp"
#include "drivers/storage/record.hpp"

namespace {

using imucal::drivers::CalibrationStore;
using imucal::drivers::decode_record;
using imucal::drivers::encode_record;
using imucal::drivers::MemoryStorage;

void check_decode(std::span<const std::uint8_t> bytes) {
  const auto decoded = decode_record(bytes);
  if (!decoded.record) {
    if (decoded.reason.empty()) std::abort();  // a refusal always says why
    return;
  }
  const auto again = encode_record(decoded.record->sequence, decoded.record->payload);
  if (again.size() > bytes.size() || !std::equal(again.begin(), again.end(), bytes.begin())) std::abort();
}

void check_store(const std::uint8_t* data, std::size_t size) {
  if (size < 2 * (imucal::drivers::kRecordHeaderBytes + 1)) return;
  MemoryStorage device(std::vector<std::uint8_t>(data, data + size));
  auto store = CalibrationStore::open(device, 0, size);
  if (!store.ok()) std::abort();
  auto latest = store->read_latest();
  if (!latest.ok()) std::abort();  // a memory device never fails to read
  if (!latest->record) return;
  const std::size_t slot_bytes = size / 2;
  const auto slot = std::span<const std::uint8_t>(data, size)
                        .subspan(static_cast<std::size_t>(latest->slot) * slot_bytes, slot_bytes);
  const auto decoded = decode_record(slot);
  if (!decoded.record || decoded.record->payload != latest->record->payload) std::abort();
  const auto& other = latest->slots[static_cast<std::size_t>(1 - latest->slot)];
  if (other.valid && other.sequence > latest->record->sequence) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  check_decode({data, size});
  check_store(data, size);
  return 0;
}
