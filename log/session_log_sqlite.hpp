#pragma once
// Internal to the session log implementation: small RAII wrappers around the SQLite C API and
// the schema text shared by the writer, the reader and the salvage scanner.

#include <sqlite3.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "core/result.hpp"

namespace imucal::log::sqlite {

struct DbCloser {
  void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
};
struct StmtFinalizer {
  void operator()(sqlite3_stmt* stmt) const { sqlite3_finalize(stmt); }
};
using Db = std::unique_ptr<sqlite3, DbCloser>;
using Stmt = std::unique_ptr<sqlite3_stmt, StmtFinalizer>;

/// `PRAGMA application_id` of a session log: "IMUC" in ASCII.
inline constexpr int kApplicationId = 0x494D5543;

/// Schema version 1. Sample value columns carry no declared type, so each value keeps the
/// storage class it was written with: INTEGER for the counts of raw streams, REAL for SI
/// streams, NULL for a missing temperature. SQLite keeps no checksums of its own; frames carry
/// a CRC-32 of their data, since damage inside a large blob leaves the page structure intact.
inline constexpr const char* kSchemaSql = R"sql(
CREATE TABLE metadata(
  key TEXT PRIMARY KEY NOT NULL,
  value TEXT NOT NULL);
CREATE TABLE imu_streams(
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL UNIQUE,
  units TEXT NOT NULL CHECK(units IN ('si', 'raw')),
  rate_hz REAL NOT NULL,
  accel_scale_x REAL NOT NULL, accel_scale_y REAL NOT NULL, accel_scale_z REAL NOT NULL,
  accel_offset_x REAL NOT NULL, accel_offset_y REAL NOT NULL, accel_offset_z REAL NOT NULL,
  gyro_scale_x REAL NOT NULL, gyro_scale_y REAL NOT NULL, gyro_scale_z REAL NOT NULL,
  gyro_offset_x REAL NOT NULL, gyro_offset_y REAL NOT NULL, gyro_offset_z REAL NOT NULL,
  temperature_scale REAL NOT NULL,
  temperature_offset REAL NOT NULL,
  accel_full_scale_g INTEGER NOT NULL,
  gyro_full_scale_dps INTEGER NOT NULL,
  dlpf_hz INTEGER NOT NULL,
  device TEXT NOT NULL);
CREATE TABLE camera_streams(
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL UNIQUE,
  width INTEGER NOT NULL,
  height INTEGER NOT NULL,
  rate_hz REAL NOT NULL,
  backend TEXT NOT NULL,
  device TEXT NOT NULL,
  timestamp_source TEXT NOT NULL);
CREATE TABLE imu_samples(
  stream_id INTEGER NOT NULL,
  t_ns INTEGER NOT NULL,
  ax, ay, az,
  gx, gy, gz,
  temperature,
  flags INTEGER NOT NULL);
CREATE INDEX imu_samples_by_time ON imu_samples(stream_id, t_ns);
CREATE TABLE frames(
  stream_id INTEGER NOT NULL,
  t_ns INTEGER NOT NULL,
  width INTEGER NOT NULL,
  height INTEGER NOT NULL,
  encoding TEXT NOT NULL,
  exposure_ns INTEGER NOT NULL,
  sequence INTEGER NOT NULL,
  flags INTEGER NOT NULL,
  data BLOB NOT NULL,
  data_crc32 INTEGER NOT NULL);
CREATE INDEX frames_by_time ON frames(stream_id, t_ns);
CREATE TABLE events(
  t_ns INTEGER NOT NULL,
  kind TEXT NOT NULL,
  message TEXT NOT NULL);
CREATE INDEX events_by_time ON events(t_ns);
)sql";

/// Name of a VFS that fails (instead of zero-filling) a short read of a database page, for
/// the reader of possibly truncated logs. Registered on first use.
const char* strict_vfs_name();

/// CRC-32 (IEEE 802.3, as zlib's crc32) of `size` bytes.
std::uint32_t crc32(const std::uint8_t* data, std::size_t size);

/// The message of the last error on `db`, e.g. "database disk image is malformed".
inline std::string errmsg(sqlite3* db) { return db ? sqlite3_errmsg(db) : "out of memory"; }

/// Runs SQL without results; returns the SQLite result code.
inline int exec(sqlite3* db, const char* sql) { return sqlite3_exec(db, sql, nullptr, nullptr, nullptr); }

/// Prepares one statement; `*rc` receives the result code.
inline Stmt prepare(sqlite3* db, const char* sql, int* rc) {
  sqlite3_stmt* raw = nullptr;
  *rc = sqlite3_prepare_v3(db, sql, -1, SQLITE_PREPARE_PERSISTENT, &raw, nullptr);
  return Stmt(raw);
}

/// True for result codes that mean the file content is damaged (as opposed to I/O or usage).
inline bool is_corruption(int rc) {
  const int primary = rc & 0xff;
  return primary == SQLITE_CORRUPT || primary == SQLITE_NOTADB || primary == SQLITE_IOERR ||
         primary == SQLITE_FORMAT || primary == SQLITE_RANGE;
}

/// Who holds the writer's flock on the file open as `fd`: "process 123 (imucal)", or "another
/// process" when /proc/locks does not say.
std::string lock_holder(int fd);

}  // namespace imucal::log::sqlite
