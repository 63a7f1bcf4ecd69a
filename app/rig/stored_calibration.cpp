// SPDX-License-Identifier: BSD-3-Clause
#include "app/rig/stored_calibration.hpp"

#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "app/camimu_inputs.hpp"
#include "app/results/camimu_results.hpp"
#include "app/results/static_results.hpp"
#include "core/calibration_payload.hpp"
#include "core/text_file.hpp"
#include "core/text_format.hpp"
#include "core/version.hpp"
#include "core/yaml_json.hpp"
#include "drivers/storage/storage_device.hpp"

namespace imucal::app {
namespace {

using nlohmann::json;

CalibrationRecord new_record() {
  CalibrationRecord r;
  r.created_utc = utc_now_iso8601();
  r.software_version = kVersion;
  return r;
}

Result<json> load_document(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error();
  const std::string& s = *text;
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && s[first] == '{') {
    json j = json::parse(s, nullptr, false);
    if (j.is_discarded()) return make_error(Errc::kCorrupt, path + ": not valid JSON");
    return j;
  }
  try {
    return yaml_to_json(YAML::Load(s));
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, path + ": not valid YAML (" + std::string(e.what()) + ")");
  }
}

StoredCalibration from_latest(const drivers::LatestRecord& latest, const std::string& device) {
  StoredCalibration out;
  out.device = device;
  out.slots.assign(latest.slots.begin(), latest.slots.end());
  if (latest.record) {
    out.sequence = latest.record->sequence;
    out.slot = latest.slot;
    out.payload_bytes = latest.record->payload.size();
  }
  return out;
}

/// The A/B store in the configured region of an opened device.
Result<drivers::CalibrationStore> open_store(drivers::StorageDevice& device, const RigConfig& config) {
  return drivers::CalibrationStore::open(device, static_cast<std::uint64_t>(config.storage.offset_bytes),
                                         static_cast<std::uint64_t>(config.storage.size_bytes));
}

Result<StoredCalibration> decode_latest(const drivers::LatestRecord& latest, const std::string& device) {
  StoredCalibration out = from_latest(latest, device);
  if (!latest.record) return out;
  const std::string where = device + " slot " + drivers::slot_name(latest.slot) + " (sequence " +
                            std::to_string(latest.record->sequence) + ")";
  const auto payload = calibration_payload_json(latest.record->payload);
  if (!payload.ok()) {
    return make_error(Errc::kCorrupt, where + " holds an intact record whose payload " +
                                          payload.error().message +
                                          ": it was not written by imucal; write a new calibration");
  }
  auto record = calibration_record_from_json(*payload);
  if (!record.ok()) return record.error().context(where);
  out.record = std::move(*record);
  return out;
}

}  // namespace

std::string newer_slot_on(const StoredCalibration& stored) {
  for (const drivers::SlotReport& s : stored.slots)
    if (s.defect == drivers::RecordDefect::kNewerVersion)
      return std::string("slot ") + drivers::slot_name(s.slot) + ": " + s.reason;
  return "";
}

CalibrationRecord calibration_record_from_static(const StaticCalibrationResult& r, const ImuStreamInfo& info,
                                                 const std::string& path) {
  CalibrationRecord rec = new_record();
  rec.imu.stream = info.name;
  rec.imu.input_units = imu_units_name(info.units);
  rec.imu.model = r.canonical;
  rec.imu.source = "static";
  rec.imu.sigma.model = std::string("tedaldi: ") + kTedaldiConvention;
  rec.imu.sigma.accel = r.accel_sigma;
  rec.imu.sigma.gyro = r.gyro_sigma;
  rec.imu.sigma.G = r.gsens_mode == GSensitivityMode::kEstimate
                        ? r.gsens_sigma
                        : Eigen::Matrix3d(Eigen::Matrix3d::Constant(kNotDetermined));
  rec.gravity_mps2 = r.gravity_mps2;
  rec.thermal = r.thermal;
  rec.files.push_back({path, "static", kStaticMethod, std::nullopt});
  return rec;
}

namespace {

/// The record of a camera-IMU calibration whose canonical model on the stream's input values is
/// `canonical_input`: from a report (converted) or from its calibration.yaml (as written).
CalibrationRecord camimu_record(const CamImuReport& report, const CanonicalImuModel& canonical_input,
                                const std::string& path) {
  const CamImuCalibrationResult& res = report.result;
  CalibrationRecord rec = new_record();
  rec.imu.stream = report.imu_stream.name;
  rec.imu.input_units = imu_units_name(report.imu_stream.units);
  rec.imu.model = canonical_input;
  rec.imu.source = "camimu";
  rec.imu.sigma.model = std::string("krebs: ") + kKrebsForm;
  rec.imu.sigma.krebs = res.imu_sigma;
  for (std::size_t i = 0; i < res.cameras.size(); ++i) {
    const CamImuCameraResult& c = res.cameras[i];
    CameraRecord cam;
    cam.name = "cam" + std::to_string(i);
    cam.stream = c.stream;
    cam.T_cam_imu = c.T_cam_imu.matrix();
    cam.rotation_sigma_rad = c.rotation_sigma_rad;
    cam.translation_sigma_m = c.translation_sigma_m;
    cam.timeshift_cam_imu_s = c.timeshift_cam_imu_s;
    cam.timeshift_sigma_s = c.timeshift_sigma_s;
    if (c.camera.shutter.rolling()) {
      cam.line_delay_s = c.camera.shutter.line_delay_s;
      cam.line_delay_sigma_s = c.line_delay_sigma_s;
    }
    cam.intrinsics = held_intrinsics(report, i);
    rec.cameras.push_back(cam);
  }
  rec.gravity_mps2 = report.options.gravity_mps2;
  rec.thermal = report.thermal;
  rec.files.push_back({path, "camimu", kCamImuMethod, res.fixed});
  return rec;
}

}  // namespace

CalibrationRecord calibration_record_from_camimu(const CamImuReport& report, const std::string& path) {
  return camimu_record(report, canonical_on_input_units(report.result.canonical, report.imu_stream), path);
}

Result<CalibrationRecord> merge_calibration_records(CalibrationRecord stat, const CalibrationRecord& cam) {
  const std::pair<const char*, std::pair<std::string, std::string>> keys[] = {
      {"stream", {stat.imu.stream, cam.imu.stream}},
      {"input_units", {stat.imu.input_units, cam.imu.input_units}}};
  for (const auto& [key, values] : keys) {
    if (values.first != values.second) {
      return make_error(Errc::kInvalidArgument,
                        std::string("the static and camimu results are of different IMU data (") + key +
                            " \"" + values.first + "\" and \"" + values.second +
                            "\"): give results of one stream");
    }
  }
  stat.cameras = cam.cameras;
  if (cam.thermal && (!stat.thermal || stat.thermal->reference_c != cam.thermal->reference_c)) {
    stat.notes.push_back(
        "the camimu result's samples were corrected with a thermal model the static result's were not (or "
        "with "
        "another): the stored IMU keeps the static result's; run both with the same --thermal");
  }
  if (!cam.files.empty()) stat.files.push_back(cam.files.front());
  std::string note = "imu from the static result; cameras from the camimu result";
  const std::vector<std::string> fixed = cam.files.empty()
                                             ? std::vector<std::string>()
                                             : cam.files.front().fixed.value_or(std::vector<std::string>());
  if (std::find(fixed.begin(), fixed.end(), "S_a") == fixed.end()) {
    note +=
        "; the camimu solve estimated its own IMU intrinsics (run calibrate camimu --imu-intrinsics with the "
        "static result for extrinsics consistent with the stored IMU)";
  }
  stat.notes.push_back(note);
  return stat;
}

// A record from one file; `exported` tells a stored record from a result converted here.
static Result<CalibrationRecord> load_record(const std::string& result_path, bool& exported);

Result<CalibrationRecord> calibration_record_from_file(const std::string& result_path) {
  bool exported = false;
  return load_record(result_path, exported);
}

static Result<CalibrationRecord> load_record(const std::string& result_path, bool& exported) {
  std::string path = result_path;
  if (std::filesystem::is_directory(path)) path = (std::filesystem::path(path) / "calibration.yaml").string();
  auto doc = load_document(path);
  if (!doc.ok()) return doc.error();
  // `store read --json` wraps the calibration with the state of the slots.
  const json& r = doc->is_object() && doc->contains("calibration") ? (*doc)["calibration"] : *doc;
  if (!r.is_object()) return make_error(Errc::kCorrupt, path + ": not a calibration result (not a mapping)");
  if (r.value("format", json()) == kCalibrationFormat) {
    exported = true;
    auto record = calibration_record_from_json(r);
    if (!record.ok()) return record.error().context(path);
    return record;
  }
  // A result: read typed, and made a record by the builders the service uses.
  const json method = r.value("method", json());
  if (method == json(kStaticMethod)) {
    auto file = parse_static_result(r, path);
    if (!file.ok()) return file.error();
    return calibration_record_from_static(file->result, file->info, path);
  }
  if (method == json(kCamImuMethod)) {
    auto file = parse_camimu_calibration(r, path);
    if (!file.ok()) return file.error();
    return camimu_record(file->report, file->canonical_input, path);
  }
  return make_error(Errc::kCorrupt, path +
                                        ": neither a static result (calibrate static -o), a camimu "
                                        "calibration.yaml nor an exported stored calibration");
}

std::string keep_stored_cameras(CalibrationRecord& record, const StoredCalibration& stored) {
  if (!stored.record) return {};
  std::string said;
  if (record.cameras.empty() && !stored.record->cameras.empty()) {
    record.cameras = stored.record->cameras;
    const std::string note = "cameras kept from the stored record (sequence " +
                             std::to_string(stored.sequence) + "): this session did not calibrate them";
    record.notes.push_back(note);
    said = note;
  }
  // A thermal model belongs to the IMU calibration whose biases it refers to its reference
  // temperature: it cannot be carried over to a new one, but its loss is said, not silent.
  if (!record.thermal && stored.record->thermal) {
    const std::string note = "the stored thermal model (sequence " + std::to_string(stored.sequence) +
                             ", reference " + fixed(stored.record->thermal->reference_c, 1) +
                             " deg C) is not kept: this session's IMU calibration was not corrected to its "
                             "reference temperature; run the thermal step (or calibrate thermal) again to "
                             "store one";
    record.notes.push_back(note);
    said += (said.empty() ? "" : "; ") + note;
  }
  return said;
}

Result<CalibrationRecord> calibration_record_from_files(const std::vector<std::string>& paths) {
  if (paths.empty()) return make_error(Errc::kInvalidArgument, "no result file given");
  std::optional<CalibrationRecord> stat, cam;
  for (const auto& path : paths) {
    bool exported = false;
    auto p = load_record(path, exported);
    if (!p.ok()) return p.error();
    if (paths.size() == 1) return p;
    const std::string kind = p->imu.source;
    std::optional<CalibrationRecord>& slot = kind == "static" ? stat : cam;
    if (exported) {
      return make_error(
          Errc::kInvalidArgument,
          path + ": an exported stored calibration cannot be merged with other results; give it alone");
    }
    if (slot) {
      return make_error(Errc::kInvalidArgument, path + ": a second " + kind +
                                                    " result; give at most one static and one camimu result");
    }
    slot = std::move(*p);
  }
  if (stat && cam) return merge_calibration_records(std::move(*stat), *cam);
  return stat ? *stat : *cam;
}

Result<StoredCalibration> read_stored_calibration(const RigConfig& config) {
  auto device = drivers::open_storage_device(config.storage, drivers::StorageAccess::kRead);
  if (!device.ok()) {
    if (device.error().code == Errc::kNotFound && config.storage.backend == StorageBackend::kFile) {
      StoredCalibration none;
      none.device = "file " + config.storage.path;
      none.note = device.error().message;
      return none;
    }
    return device.error();
  }
  auto store = open_store(**device, config);
  if (!store.ok()) return store.error();
  auto latest = store->read_latest();
  if (!latest.ok()) return latest.error();
  return decode_latest(*latest, (*device)->name());
}

Result<StoredCalibration> write_stored_calibration(const RigConfig& config, const CalibrationRecord& record,
                                                   const drivers::StoreWriteOptions& options) {
  CalibrationRecord rec = record;
  if (rec.rig.empty()) rec.rig = config.name;
  const json p = calibration_record_json(rec);
  // What is stored must read back as what was meant: the JSON form is checked as a reader sees it.
  IMUCAL_TRY(calibration_record_from_json(p));
  const std::vector<std::uint8_t> cbor = json::to_cbor(p);
  // Before the device is opened for writing: a file backend creates its file there.
  const std::string device_name =
      config.storage.backend == StorageBackend::kFile    ? "file " + config.storage.path
      : config.storage.backend == StorageBackend::kNvmem ? "nvmem " + config.storage.path
                                                         : "the EEPROM on " + config.storage.i2c_device;
  IMUCAL_TRY(drivers::CalibrationStore::check_fits(
      device_name, static_cast<std::uint64_t>(config.storage.size_bytes), cbor.size()));
  auto device = drivers::open_storage_device(config.storage, drivers::StorageAccess::kWrite);
  if (!device.ok()) return device.error();
  auto store = open_store(**device, config);
  if (!store.ok()) return store.error();
  // The newest record's payload from a newer imucal (a newer record version in this framing) is
  // kept as the newest unless the caller says to replace it, as a newer framing is by the store.
  if (!options.replace_newer) {
    auto latest = store->read_latest();
    if (!latest.ok()) return latest.error();
    if (latest->record) {
      const auto payload = calibration_payload_json(latest->record->payload);
      const json version = payload.ok() && payload->is_object() ? payload->value("version", json()) : json();
      if (version.is_number_integer() && version.get<std::int64_t>() > kCalibrationRecordVersion) {
        return make_error(
                   Errc::kInvalidArgument,
                   (*device)->name() + " slot " + drivers::slot_name(latest->slot) +
                       " holds the newest record, of calibration record version " + version.dump() +
                       ", written by a newer imucal (this one writes version " +
                       std::to_string(kCalibrationRecordVersion) +
                       "); nothing was written. Write with that imucal, or replace its record knowingly")
            .with_remedy("replace_newer");
      }
    }
  }
  auto written = store->write(cbor, options);
  if (!written.ok()) return written.error();
  auto latest = store->read_latest();
  if (!latest.ok()) return latest.error();
  auto out = decode_latest(*latest, (*device)->name());
  if (!out.ok()) return out.error();
  if (out->slot != written->slot || out->sequence != written->sequence || !out->record ||
      calibration_record_json(*out->record) != p) {
    return make_error(Errc::kDevice, (*device)->name() + ": after writing sequence " +
                                         std::to_string(written->sequence) + " to slot " +
                                         drivers::slot_name(written->slot) +
                                         ", the newest readable record is another one; check the device");
  }
  return out;
}

namespace {

bool is_number_list(const json& j) {
  return j.is_array() && std::all_of(j.begin(), j.end(), [](const json& x) { return x.is_number(); });
}

void emit(YAML::Emitter& y, const json& j) {
  if (j.is_object()) {
    y << YAML::BeginMap;
    for (const auto& [k, v] : j.items()) {
      y << YAML::Key << k << YAML::Value;
      emit(y, v);
    }
    y << YAML::EndMap;
  } else if (j.is_array()) {
    y << (is_number_list(j) ? YAML::Flow : YAML::Block) << YAML::BeginSeq;
    for (const auto& v : j) emit(y, v);
    y << YAML::EndSeq;
  } else if (j.is_number_integer()) {
    y << j.get<std::int64_t>();
  } else if (j.is_number()) {
    // JSON's shortest text that reads back to the same double, so that an exported calibration
    // compares equal to the stored one (store verify).
    y << j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  } else if (j.is_boolean()) {
    y << j.get<bool>();
  } else if (j.is_string()) {
    y << j.get<std::string>();
  } else {
    y << YAML::Null;
  }
}

}  // namespace

std::string stored_calibration_yaml(const CalibrationRecord& record) {
  YAML::Emitter y;
  emit(y, calibration_record_json(record));
  return std::string(y.c_str()) + "\n";
}

Result<Rollback> rollback_stored_calibration(const RigConfig& config) {
  CalibrationRecord previous;
  Rollback out;
  {
    auto device = drivers::open_storage_device(config.storage, drivers::StorageAccess::kRead);
    if (!device.ok()) return device.error();
    auto store = open_store(**device, config);
    if (!store.ok()) return store.error();
    auto latest = store->read_latest();
    if (!latest.ok()) return latest.error();
    if (!latest->record) {
      return make_error(Errc::kNotFound,
                        "no calibration is stored on " + (*device)->name() + ": nothing to roll back");
    }
    const int other = 1 - latest->slot;
    auto older = store->read_record(other);
    if (!older.ok()) return older.error();
    if (!older->record) {
      return make_error(Errc::kNotFound, std::string("no previous record to roll back to: slot ") +
                                             drivers::slot_name(other) + " holds none (" + older->reason +
                                             ")");
    }
    const auto payload = calibration_payload_json(older->record->payload);
    if (!payload.ok()) {
      return make_error(Errc::kCorrupt, std::string("slot ") + drivers::slot_name(other) +
                                            " holds a record whose payload " + payload.error().message +
                                            ": it cannot be restored");
    }
    auto record = calibration_record_from_json(*payload);
    if (!record.ok()) {
      return record.error().context(std::string("slot ") + drivers::slot_name(other) +
                                    " holds a record that cannot be restored");
    }
    previous = std::move(*record);
    out.restored_sequence = older->record->sequence;
    out.replaced_sequence = latest->record->sequence;
  }
  auto written = write_stored_calibration(config, previous);
  if (!written.ok()) return written.error();
  out.written = std::move(*written);
  return out;
}

}  // namespace imucal::app
