// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/storage/calibration_store.hpp"

#include <algorithm>
#include <limits>

namespace imucal::drivers {

const char* slot_name(int slot) { return slot == 0 ? "A" : "B"; }

Result<CalibrationStore> CalibrationStore::open(StorageDevice& device, std::uint64_t offset,
                                                std::uint64_t size) {
  IMUCAL_TRY(check_range(device.name(), device.size(), offset, size));
  const std::uint64_t slot = size / 2;
  if (slot < kRecordHeaderBytes + 1) {
    return make_error(Errc::kInvalidArgument,
                      device.name() + ": a region of " + std::to_string(size) +
                          " bytes leaves no room for two records; raise storage.size_bytes");
  }
  return CalibrationStore(device, offset, slot);
}

Result<DecodedRecord> CalibrationStore::read_slot(int slot) {
  const std::uint64_t at = slot_offset(slot);
  // The header first, then only the bytes the header says the record spans: an EEPROM on a
  // 100 kHz bus reads about 10 kB/s, so a small record in a large slot is read quickly.
  std::vector<std::uint8_t> bytes(
      static_cast<std::size_t>(std::min<std::uint64_t>(slot_bytes_, kRecordMaxHeaderBytes)));
  if (auto st = device_->read(at, bytes); !st.ok())
    return st.error().context(std::string("slot ") + slot_name(slot));
  if (const auto extent = record_extent(bytes); extent && *extent > bytes.size()) {
    bytes.resize(static_cast<std::size_t>(std::min<std::uint64_t>(*extent, slot_bytes_)));
    if (auto st = device_->read(at, bytes); !st.ok())
      return st.error().context(std::string("slot ") + slot_name(slot));
  }
  return decode_record(bytes);
}

Result<std::array<SlotReport, 2>> CalibrationStore::inspect() {
  std::array<SlotReport, 2> out;
  for (int s = 0; s < 2; ++s) {
    auto decoded = read_slot(s);
    if (!decoded.ok()) return decoded.error();
    SlotReport& r = out[static_cast<std::size_t>(s)];
    r.slot = s;
    r.offset = slot_offset(s);
    r.defect = decoded->defect;
    r.reason = decoded->reason;
    r.valid = decoded->record.has_value();
    if (r.valid) {
      r.sequence = decoded->record->sequence;
      r.payload_bytes = decoded->record->payload.size();
    }
  }
  return out;
}

Result<LatestRecord> CalibrationStore::read_latest() {
  LatestRecord latest;
  std::array<std::optional<Record>, 2> records;
  for (int s = 0; s < 2; ++s) {
    auto decoded = read_slot(s);
    if (!decoded.ok()) return decoded.error();
    SlotReport& r = latest.slots[static_cast<std::size_t>(s)];
    r = {s, slot_offset(s), decoded->record.has_value(), 0, 0, decoded->defect, decoded->reason};
    if (decoded->record) {
      r.sequence = decoded->record->sequence;
      r.payload_bytes = decoded->record->payload.size();
      records[static_cast<std::size_t>(s)] = std::move(decoded->record);
    }
  }
  for (int s = 0; s < 2; ++s) {
    if (!records[static_cast<std::size_t>(s)]) continue;
    if (latest.slot < 0 || records[static_cast<std::size_t>(s)]->sequence > latest.record->sequence) {
      latest.slot = s;
      latest.record = records[static_cast<std::size_t>(s)];
    }
  }
  return latest;
}

Status CalibrationStore::check_fits(const std::string& device, std::uint64_t region_bytes,
                                    std::size_t payload_bytes) {
  const std::uint64_t slot = region_bytes / 2;
  if (slot < kRecordHeaderBytes || payload_bytes > slot - kRecordHeaderBytes) {
    return make_error(
        Errc::kInvalidArgument,
        "the calibration record needs " + std::to_string(payload_bytes + kRecordHeaderBytes) +
            " bytes, a slot of " + device + " holds " + std::to_string(slot) +
            " (half of storage.size_bytes); nothing was written. Raise storage.size_bytes or store "
            "fewer results");
  }
  return {};
}

Result<WriteReport> CalibrationStore::write(std::span<const std::uint8_t> payload,
                                            const StoreWriteOptions& options) {
  IMUCAL_TRY(check_fits(device_->name(), 2 * slot_bytes_, payload.size()));
  auto latest = read_latest();
  if (!latest.ok()) return latest.error();
  for (const SlotReport& r : latest->slots) {
    // A newer imucal's record is not damage: it is kept unless the caller says to replace it.
    if (r.defect == RecordDefect::kNewerVersion && !options.replace_newer) {
      return make_error(Errc::kInvalidArgument,
                        device_->name() + " slot " + slot_name(r.slot) + " holds a record of " + r.reason +
                            "; nothing was written. Write with that imucal, or replace its record "
                            "knowingly")
          .with_remedy("replace_newer");
    }
  }
  if (!latest->record) {
    // No record of imucal's anywhere, and bytes that are neither erased nor an imucal header:
    // the region is something else's (a session log named as storage.path by mistake).
    for (const SlotReport& r : latest->slots) {
      if (r.defect == RecordDefect::kBadMagic) {
        return make_error(Errc::kInvalidArgument,
                          device_->name() + " slot " + slot_name(r.slot) + " (byte " +
                              std::to_string(r.offset) + ") holds data that is not a calibration record (" +
                              r.reason +
                              ") and no slot holds one: storage.path, storage.offset_bytes or "
                              "storage.size_bytes name something else, which is never written over; "
                              "nothing was written. Fix those keys, or erase the region (all 0x00 "
                              "or 0xFF) if its content is not needed");
      }
    }
  }
  std::uint32_t sequence = 1;
  int target = 0;
  if (latest->record) {
    if (latest->record->sequence == std::numeric_limits<std::uint32_t>::max()) {
      return make_error(Errc::kUnsupported, device_->name() + ": the record sequence is at its maximum (" +
                                                std::to_string(latest->record->sequence) +
                                                "); erase the storage region to start again");
    }
    sequence = latest->record->sequence + 1;
    target = 1 - latest->slot;
  }
  const std::vector<std::uint8_t> bytes = encode_record(sequence, payload);
  const std::uint64_t at = slot_offset(target);
  const std::string where = device_->name() + " slot " + slot_name(target);
  if (auto st = device_->write(at, bytes); !st.ok()) return st.error().context("writing " + where);
  if (auto st = device_->sync(); !st.ok()) return st.error().context("syncing " + where);
  std::vector<std::uint8_t> back(bytes.size());
  if (auto st = device_->read(at, back); !st.ok()) return st.error().context("reading back " + where);
  if (back != bytes) {
    const auto diff = std::mismatch(bytes.begin(), bytes.end(), back.begin());
    const auto first = static_cast<std::size_t>(diff.first - bytes.begin());
    return make_error(
        Errc::kDevice,
        where + ": the read-back differs from what was written at byte " + std::to_string(first) + " of " +
            std::to_string(bytes.size()) +
            ", so the write failed; the previous record is untouched in the other slot. Check the "
            "device (write protection, wear, wiring) and write again");
  }
  return WriteReport{target, sequence, bytes.size()};
}

}  // namespace imucal::drivers
