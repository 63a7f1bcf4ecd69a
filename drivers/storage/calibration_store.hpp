// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Two slots (A/B) for the calibration record inside a region of a StorageDevice, so that a
// write cut at any byte (power loss, a pulled cable) leaves the previous calibration readable.
//
//   region [offset, offset + size):  slot A = first half, slot B = second half (size / 2 each)
//
// A reader takes the valid record (record.hpp: magic, header CRC, payload CRC) with the highest
// sequence. A write goes to the slot that does not hold that record (the older or the invalid
// one) with sequence + 1, is synced, read back and compared, and only then reported done. The
// slot holding the newest valid record is never written, so whatever a cut leaves in the other
// slot, the newest record before the write is still there (docs/storage.md).

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "drivers/storage/record.hpp"
#include "drivers/storage/storage_device.hpp"

namespace imucal::drivers {

struct SlotReport {
  int slot = 0;              // 0 = A, 1 = B
  std::uint64_t offset = 0;  // on the device
  bool valid = false;
  std::uint32_t sequence = 0;     // when valid
  std::size_t payload_bytes = 0;  // when valid
  RecordDefect defect = RecordDefect::kNone;
  std::string reason;  // why not valid
};

/// "A" or "B".
const char* slot_name(int slot);

struct LatestRecord {
  std::optional<Record> record;  // empty: no slot holds a valid record (not an error)
  int slot = -1;
  std::array<SlotReport, 2> slots;
};

/// What a write may replace besides an older or damaged record of this imucal's.
struct StoreWriteOptions {
  /// A record of a newer format version (a newer imucal's): kept unless this is set.
  bool replace_newer = false;
};

struct WriteReport {
  int slot = 0;
  std::uint32_t sequence = 0;
  std::size_t bytes = 0;  // header + payload
};

class CalibrationStore {
 public:
  /// Checks that the region lies inside the device and that a slot can hold a header and
  /// some payload. `device` must outlive the store.
  [[nodiscard]] static Result<CalibrationStore> open(StorageDevice& device, std::uint64_t offset,
                                                     std::uint64_t size);

  /// Per slot: valid with its sequence, or invalid with the reason. Device errors are errors.
  [[nodiscard]] Result<std::array<SlotReport, 2>> inspect();
  /// The newest valid record, or none; device errors are errors.
  [[nodiscard]] Result<LatestRecord> read_latest();
  /// Writes `payload` as the next record (see the header comment). Refused before anything is
  /// written (kInvalidArgument): a payload that does not fit a slot; a slot holding a record of a
  /// newer format version (without options.replace_newer; remedy "replace_newer"); a region
  /// that holds no record of imucal's and bytes that are neither erased nor an imucal record
  /// header (storage.path names another file, or the region overlaps other data). A read-back
  /// that differs from what was written is a failed write (kDevice).
  [[nodiscard]] Result<WriteReport> write(std::span<const std::uint8_t> payload,
                                          const StoreWriteOptions& options = {});

  /// Whether a payload of `payload_bytes` fits a slot of a region of `region_bytes`
  /// (kInvalidArgument naming `device` and what to change): checked by write(), and by callers
  /// before they open a device for writing, so that a refused write creates no storage file.
  [[nodiscard]] static Status check_fits(const std::string& device, std::uint64_t region_bytes,
                                         std::size_t payload_bytes);

  /// The record one slot holds (0 = A, 1 = B), decoded, or why it holds none; device errors
  /// are errors.
  [[nodiscard]] Result<DecodedRecord> read_record(int slot) { return read_slot(slot); }

  /// Bytes one slot holds, and the longest payload that fits.
  std::uint64_t slot_bytes() const { return slot_bytes_; }
  std::uint64_t max_payload_bytes() const { return slot_bytes_ - kRecordHeaderBytes; }
  std::uint64_t slot_offset(int slot) const {
    return offset_ + static_cast<std::uint64_t>(slot) * slot_bytes_;
  }
  const StorageDevice& device() const { return *device_; }

 private:
  CalibrationStore(StorageDevice& device, std::uint64_t offset, std::uint64_t slot_bytes)
      : device_(&device), offset_(offset), slot_bytes_(slot_bytes) {}
  // Reads one slot: the record it holds (decoded), reading no more than the record spans.
  [[nodiscard]] Result<DecodedRecord> read_slot(int slot);

  StorageDevice* device_;
  std::uint64_t offset_;
  std::uint64_t slot_bytes_;
};

}  // namespace imucal::drivers
