// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The calibration as it is stored on the rig (docs/storage.md): the typed record of
// core/calibration_record.hpp, encoded as CBOR of its JSON form into the A/B record store of
// drivers/storage/, read and written through the rig configuration's `storage:`. Records are built
// from the solves' typed results (the service, replay), or from the result files the calibration
// commands write (the CLI's `store write` and `store verify`, the one place file paths come in).
//
// Merging a static result with a camimu result: the IMU comes from the static result (the
// method made for the intrinsics), the cameras from the camimu result; both must be of the same
// IMU stream and input units. A note records when the camimu solve estimated its own IMU
// intrinsics instead of fixing the static ones.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "app/camimu_calibration.hpp"
#include "core/calibration_record.hpp"
#include "core/imu.hpp"
#include "core/imu_calibration.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/storage/calibration_store.hpp"

namespace imucal::app {

struct StoredCalibration {
  std::optional<CalibrationRecord> record;  // empty: nothing valid is stored (not an error)
  std::uint32_t sequence = 0;
  int slot = -1;  // 0 = A, 1 = B
  std::string device;
  std::vector<drivers::SlotReport> slots;  // both slots; empty when the storage file does not exist
  std::size_t payload_bytes = 0;           // CBOR bytes of the payload
  std::string note;                        // why there are no slots to report, when there are none
};

/// A slot that holds a record in a newer imucal's framing ("slot B: format version 7, written by a
/// newer imucal ..."), empty when none does: not damage, and never written over unasked, so that a
/// session's write would be refused.
std::string newer_slot_on(const StoredCalibration& stored);

/// What an operator or a user can do about a record a newer imucal wrote (the payload
/// Errc::kNewerVersion, or a slot newer_slot_on names).
inline constexpr const char* kNewerRecordAdvice =
    "a newer imucal wrote the rig's calibration and this one never writes over it: update imucal on "
    "the rig and restart imucald, or abort to keep the rig as it is";

/// The record of a static calibration of `info`'s stream: the canonical model and Tedaldi's
/// sigmas (G's only when the g-sensitivity was estimated; else not determined). `path` names
/// the result file in the record's sources.
CalibrationRecord calibration_record_from_static(const StaticCalibrationResult& result,
                                                 const ImuStreamInfo& info, const std::string& path);

/// The record of a camera-IMU calibration: the IMU in canonical form on the stream's input
/// units with Krebs's sigmas, and the cameras (cam0, cam1, ... in the report's order).
CalibrationRecord calibration_record_from_camimu(const CamImuReport& report, const std::string& path);

/// The static record's IMU with the camimu record's cameras (the rules above). kInvalidArgument
/// when they are of different IMU data.
[[nodiscard]] Result<CalibrationRecord> merge_calibration_records(CalibrationRecord static_record,
                                                                  const CalibrationRecord& camimu_record);

/// A record from one result file: `calibrate static -o` YAML, camimu's calibration.yaml (or its
/// output folder), or a stored record exported as YAML or JSON (`store read [--json]`).
[[nodiscard]] Result<CalibrationRecord> calibration_record_from_file(const std::string& result_path);

/// One record from several result files: at most one static and one camimu result (merged), or a
/// single exported record.
[[nodiscard]] Result<CalibrationRecord> calibration_record_from_files(
    const std::vector<std::string>& result_paths);

/// A session that calibrated only the IMU must not drop the cameras the rig's record holds:
/// when `record` has no cameras and `stored` has some, they are carried over, with a note in its
/// notes. A stored thermal model is not carried over to a record without one (it belongs to the
/// IMU calibration it corrected), but a note says it was dropped. Returns what was done in words
/// (empty when nothing was carried or dropped).
std::string keep_stored_cameras(CalibrationRecord& record, const StoredCalibration& stored);

/// The newest valid record of the configured storage, decoded. A missing storage file or empty
/// slots give a StoredCalibration without record; a valid record whose payload is no imucal
/// calibration is kCorrupt; device errors are errors.
[[nodiscard]] Result<StoredCalibration> read_stored_calibration(const RigConfig& config);

/// What a rollback did: the record restored and the one it replaced as the newest.
struct Rollback {
  StoredCalibration written;            // the restored calibration as now stored (sequence advanced)
  std::uint32_t restored_sequence = 0;  // the sequence it had before
  std::uint32_t replaced_sequence = 0;  // the newest record before the rollback, kept in its slot
};

/// Writes the previous record (the valid one in the slot the newest is not in) again as the
/// next record, so that it becomes the newest with its sequence advanced; the record it replaces
/// stays in its slot until the next write. kNotFound when no valid record is stored, or no
/// previous one (the other slot erased or damaged: its reason in the message).
[[nodiscard]] Result<Rollback> rollback_stored_calibration(const RigConfig& config);

/// Writes `record` (its rig set from the configuration when empty) as the next record: to the
/// older slot, synced, read back byte for byte by the store and decoded again here. The refusals
/// of CalibrationStore::write (a record of a newer imucal without options.replace_newer, a region
/// holding something else); a record too large for a slot is refused before the storage file is
/// created.
[[nodiscard]] Result<StoredCalibration> write_stored_calibration(
    const RigConfig& config, const CalibrationRecord& record, const drivers::StoreWriteOptions& options = {});

/// The record as YAML, for people (numbers in full precision, short lists on one line).
std::string stored_calibration_yaml(const CalibrationRecord& record);

}  // namespace imucal::app
