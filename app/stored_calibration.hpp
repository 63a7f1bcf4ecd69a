#pragma once
// The calibration as it is stored on the rig (docs/storage.md): a self-describing JSON document,
// encoded as CBOR into the A/B record store of drivers/storage/. Built from the result files the
// calibration commands write, read and written through the rig configuration's `storage:`.
//
// Payload (version 1):
//   {"format": "imucal.calibration", "version": 1, "created_utc": "...", "software_version": "...",
//    "rig": NAME,                                   (set from the configuration when written)
//    "imu": {"stream", "input_units", "form", "A_a", "b_a", "A_g", "b_g", "G",   (canonical form)
//            "source": "static"|"camimu", "sigma": {the source model's sigmas, "model": ...}},
//    "cameras": [{"name", "stream", "T_cam_imu" (4 rows), "rotation_sigma_rad", "translation_sigma_m",
//                 "timeshift_cam_imu_s", "timeshift_sigma_s"}],
//    "gravity_mps2": ..., "source": {"files": [{"path", "kind", "method"}], "notes": [...]}}
//
// Merging a static result with a camimu result: the IMU comes from the static result (the
// method made for the intrinsics), the cameras from the camimu result; both must be of the same
// IMU stream and input units. A note records when the camimu solve estimated its own IMU
// intrinsics instead of fixing the static ones.

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/storage/calibration_store.hpp"

namespace imucal::app {

inline constexpr const char* kCalibrationFormat = "imucal.calibration";
inline constexpr int kCalibrationPayloadVersion = 1;

struct StoredCalibration {
  std::optional<nlohmann::json> payload;  // empty: nothing valid is stored (not an error)
  std::uint32_t sequence = 0;
  int slot = -1;  // 0 = A, 1 = B
  std::string device;
  std::vector<drivers::SlotReport> slots;  // both slots; empty when the storage file does not exist
  std::size_t payload_bytes = 0;           // CBOR bytes of the payload
  std::string note;                        // why there are no slots to report, when there are none
};

/// A payload from one result file: `calibrate static -o` YAML, camimu's calibration.yaml (or
/// its output folder), or a stored payload exported as YAML or JSON (`store read [--json]`).
[[nodiscard]] Result<nlohmann::json> calibration_payload_from_file(const std::string& result_path);

/// One payload from several results: at most one static and one camimu result (merged as the
/// header comment says), or a single exported payload.
[[nodiscard]] Result<nlohmann::json> calibration_payload_from_files(
    const std::vector<std::string>& result_paths);

/// A session that calibrated only the IMU must not drop the cameras the rig's record holds:
/// when `payload` has no cameras and `stored` has some, they are carried over, with a note in
/// `source.notes`; returns what was done in words (empty when nothing was carried).
std::string keep_stored_cameras(nlohmann::json& payload, const StoredCalibration& stored);

/// Checks that `payload` is a version-1 calibration: format, version, the IMU's matrices and
/// vectors finite and of their sizes, every camera's T_cam_imu 4 rows of 4. kCorrupt otherwise.
[[nodiscard]] Status validate_calibration_payload(const nlohmann::json& payload);

/// True when both hold the same calibration: their "imu" and "cameras" (the creation time,
/// software version, rig name and sources may differ).
bool same_calibration(const nlohmann::json& a, const nlohmann::json& b);

/// The newest valid record of the configured storage, decoded. A missing storage file or empty
/// slots give a StoredCalibration without payload; a valid record whose payload is no imucal
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

/// Writes `payload` (validated; "rig" set from the configuration when absent) as the next record:
/// to the older slot, synced, read back byte for byte by the store and decoded again here.
[[nodiscard]] Result<StoredCalibration> write_stored_calibration(const RigConfig& config,
                                                                 const nlohmann::json& payload);

/// The payload as YAML, for people (numbers in full precision, short lists on one line).
std::string stored_calibration_yaml(const nlohmann::json& payload);

}  // namespace imucal::app
