// SPDX-License-Identifier: BSD-3-Clause
// imucal store read|write|verify --config RIG.yaml [RESULT...]: the calibration record on the
// rig's storage (A/B slots, docs/storage.md): print it, write results into it, check it.

#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "app/rig/stored_calibration.hpp"
#include "core/rig_config.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

using nlohmann::json;

struct StoreOptions {
  std::string config_path;
  std::vector<std::string> results;
  bool json = false;
  bool replace_newer = false;
};

RigConfig load_config(const std::string& path) {
  auto cfg = load_rig_config(path);
  if (!cfg.ok()) throw CliExit{kExitInput, "reading the rig configuration: " + cfg.error().message};
  return std::move(cfg).value();
}

std::string slot_line(const drivers::SlotReport& s) {
  std::string line =
      std::string("slot ") + drivers::slot_name(s.slot) + " (byte " + std::to_string(s.offset) + "): ";
  if (s.valid) {
    return line + "valid, sequence " + std::to_string(s.sequence) + ", " + std::to_string(s.payload_bytes) +
           " payload bytes";
  }
  return line + record_defect_name(s.defect) + " - " + s.reason;
}

json slots_json(const app::StoredCalibration& s) {
  json out = json::array();
  for (const auto& r : s.slots) {
    json j = {{"slot", drivers::slot_name(r.slot)}, {"offset", r.offset}, {"valid", r.valid}};
    if (r.valid) {
      j["sequence"] = r.sequence;
      j["payload_bytes"] = r.payload_bytes;
    } else {
      j["defect"] = record_defect_name(r.defect);
      j["reason"] = r.reason;
    }
    out.push_back(j);
  }
  return out;
}

// Prints where the record is and the state of both slots (stdout for read's YAML as comments).
void print_state(std::ostream& out, const app::StoredCalibration& s, const char* prefix) {
  out << prefix << s.device;
  if (s.record) {
    out << ": slot " << drivers::slot_name(s.slot) << ", sequence " << s.sequence << ", " << s.payload_bytes
        << " payload bytes";
  }
  out << "\n";
  for (const auto& r : s.slots) out << prefix << "  " << slot_line(r) << "\n";
  if (!s.note.empty()) out << prefix << "  " << s.note << "\n";
}

app::StoredCalibration read_or_fail(const RigConfig& config) {
  auto stored = app::read_stored_calibration(config);
  if (!stored.ok()) fail(stored.error(), "reading the stored calibration");
  if (!stored->record) {
    print_state(std::cerr, *stored, "");
    throw CliExit{kExitInput,
                  "no calibration is stored on " + stored->device + " (write one with imucal store write)"};
  }
  return std::move(stored).value();
}

/// The slots that hold a damaged record (not merely erased): a write that was interrupted, or a
/// record corrupted since. The record served may then be older than the last one written.
std::vector<const drivers::SlotReport*> damaged_slots(const app::StoredCalibration& s) {
  std::vector<const drivers::SlotReport*> out;
  for (const auto& r : s.slots)
    if (!r.valid && r.defect != drivers::RecordDefect::kErased) out.push_back(&r);
  return out;
}

/// Says on stderr that the record served may be older than the last one written.
void warn_damaged(const app::StoredCalibration& s) {
  for (const drivers::SlotReport* r : damaged_slots(s)) {
    std::cerr << "warning: slot " << drivers::slot_name(r->slot) << " is damaged ("
              << record_defect_name(r->defect) << " - " << r->reason << "): the record served (slot "
              << drivers::slot_name(s.slot) << ", sequence " << s.sequence
              << ") may be older than the last one written; check it, and write the calibration again "
                 "(imucal store write) to hold two good copies\n";
  }
}

void run_read(const StoreOptions& o) {
  const app::StoredCalibration s = read_or_fail(load_config(o.config_path));
  warn_damaged(s);
  if (o.json) {
    json damaged = json::array();
    for (const drivers::SlotReport* r : damaged_slots(s)) damaged.push_back(drivers::slot_name(r->slot));
    json j = {{"device", s.device},
              {"slot", drivers::slot_name(s.slot)},
              {"sequence", s.sequence},
              {"payload_bytes", s.payload_bytes},
              {"slots", slots_json(s)},
              {"damaged_slots", damaged},
              {"may_be_older_than_last_write", !damaged.empty()},
              {"calibration", calibration_record_json(*s.record)}};
    std::cout << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
    return;
  }
  print_state(std::cout, s, "# ");
  std::cout << app::stored_calibration_yaml(*s.record);
}

CalibrationRecord record_of(const std::vector<std::string>& results) {
  auto record = app::calibration_record_from_files(results);
  if (!record.ok()) {
    const int code = record.error().code == Errc::kInvalidArgument ? kExitUsage : kExitInput;
    throw CliExit{code, record.error().message};
  }
  return std::move(record).value();
}

void run_write(const StoreOptions& o) {
  const RigConfig config = load_config(o.config_path);
  const CalibrationRecord record = record_of(o.results);
  auto written = app::write_stored_calibration(config, record, drivers::StoreWriteOptions{o.replace_newer});
  if (!written.ok()) fail(written.error(), "writing the calibration");
  std::cout << "written and verified: " << written->device << " slot " << drivers::slot_name(written->slot)
            << ", sequence " << written->sequence << ", " << written->payload_bytes << " payload bytes\n";
  for (const auto& r : written->slots) std::cout << "  " << slot_line(r) << "\n";
}

void run_rollback(const StoreOptions& o) {
  const RigConfig config = load_config(o.config_path);
  auto done = app::rollback_stored_calibration(config);
  if (!done.ok()) fail(done.error(), "rolling back the stored calibration");
  const app::StoredCalibration& w = done->written;
  std::cout << "rolled back: the record of sequence " << done->restored_sequence << " is now sequence "
            << w.sequence << " in slot " << drivers::slot_name(w.slot) << " (" << w.device
            << "), written and verified; the replaced record (sequence " << done->replaced_sequence
            << ") stays in the other slot until the next write\n";
  for (const auto& r : w.slots) std::cout << "  " << slot_line(r) << "\n";
}

void run_verify(const StoreOptions& o) {
  const RigConfig config = load_config(o.config_path);
  std::optional<CalibrationRecord> expected;
  if (!o.results.empty()) expected = record_of(o.results);
  const app::StoredCalibration s = read_or_fail(config);
  warn_damaged(s);
  print_state(std::cout, s, "");
  for (const auto& r : s.slots) {
    if (!r.valid && r.defect != drivers::RecordDefect::kErased) {
      std::cout << "  note: slot " << drivers::slot_name(r.slot)
                << " is not valid (an interrupted or failed write); the next write goes there\n";
    }
  }
  if (expected && !same_calibration(*s.record, *expected)) {
    throw CliExit{kExitData, "the stored calibration (sequence " + std::to_string(s.sequence) +
                                 ") differs from the given result's imu or cameras"};
  }
  std::cout << (expected ? "ok: the stored calibration equals the given result\n" : "ok\n");
}

void setup(CLI::App& root) {
  CLI::App* store = root.add_subcommand(
      "store",
      "The calibration record on the rig's storage (A/B slots; file, nvmem or I2C EEPROM; docs/storage.md)");
  store->require_subcommand(1);
  auto o = std::make_shared<StoreOptions>();
  auto add_config = [&](CLI::App* c) {
    c->add_option("--config", o->config_path, "Rig configuration YAML (its storage: section)")->required();
  };
  CLI::App* read =
      store->add_subcommand("read", "Print the stored calibration and which slot and sequence hold it");
  add_config(read);
  read->add_flag("--json", o->json, "Print JSON (the state of both slots and the calibration)");
  read->callback([o] { run_read(*o); });

  CLI::App* write = store->add_subcommand(
      "write",
      "Write results (calibrate static -o YAML, calibrate camimu's folder or calibration.yaml, or an "
      "exported calibration) as the next record; synced, read back and verified");
  add_config(write);
  write->add_option("RESULT", o->results, "Result files: at most one static and one camimu")->required();
  write->add_flag("--replace-newer", o->replace_newer,
                  "Write even over a record a newer imucal wrote (of a newer format version), which is "
                  "otherwise kept");
  write->callback([o] { run_write(*o); });

  CLI::App* rollback = store->add_subcommand(
      "rollback",
      "Make the previous record (the other slot's) the newest again: it is written as the next record, its "
      "sequence advanced; the record it replaces stays in its slot until the next write");
  add_config(rollback);
  rollback->callback([o] { run_rollback(*o); });

  CLI::App* verify = store->add_subcommand(
      "verify", "Check both slots; with RESULT, also that the stored calibration equals it");
  add_config(verify);
  verify->add_option("RESULT", o->results, "Result files to compare with (as for write)");
  verify->callback([o] { run_verify(*o); });
}

const CommandRegistrar registrar(85, setup);

}  // namespace
}  // namespace imucal::cli
