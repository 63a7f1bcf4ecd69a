// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Internal to the session log implementation: small RAII wrappers around the SQLite C API and
// the schema text and row helpers shared by the writer (session_log_sqlite_writer.cpp), the
// reader (session_log_sqlite.cpp) and the salvage scanner.

#include <sqlite3.h>
#include <sys/stat.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "core/imu.hpp"
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

// Reserved metadata keys, set by the writer only.
inline constexpr const char* kKeySchemaVersion = "schema_version";
inline constexpr const char* kKeySoftwareVersion = "software_version";
inline constexpr const char* kKeyCreatedUtc = "created_utc";
inline constexpr const char* kKeyComplete = "complete";

// Binds one sample value: NaN as NULL; in raw streams an integral value as INTEGER (exact up
// to 2^53); everything else as REAL (an exact double round trip).
inline void bind_value(sqlite3_stmt* stmt, int index, double value, bool raw) {
  constexpr double kExactIntLimit = 9007199254740992.0;  // 2^53
  if (std::isnan(value)) {
    sqlite3_bind_null(stmt, index);
  } else if (raw && std::trunc(value) == value && std::fabs(value) <= kExactIntLimit) {
    sqlite3_bind_int64(stmt, index, static_cast<sqlite3_int64>(value));
  } else {
    sqlite3_bind_double(stmt, index, value);
  }
}

inline double column_value(sqlite3_stmt* stmt, int index) {
  if (sqlite3_column_type(stmt, index) == SQLITE_NULL) return std::numeric_limits<double>::quiet_NaN();
  return sqlite3_column_double(stmt, index);
}

inline std::string column_text(sqlite3_stmt* stmt, int index) {
  const auto* text = sqlite3_column_text(stmt, index);
  return text ? std::string(reinterpret_cast<const char*>(text)) : std::string();
}

inline void bind_text(sqlite3_stmt* stmt, int index, const std::string& text) {
  sqlite3_bind_text(stmt, index, text.data(), static_cast<int>(text.size()), SQLITE_TRANSIENT);
}

inline ImuSample read_sample_columns(sqlite3_stmt* stmt, int first) {
  ImuSample s;
  s.t_ns = sqlite3_column_int64(stmt, first);
  s.accel = {column_value(stmt, first + 1), column_value(stmt, first + 2), column_value(stmt, first + 3)};
  s.gyro = {column_value(stmt, first + 4), column_value(stmt, first + 5), column_value(stmt, first + 6)};
  s.temperature = column_value(stmt, first + 7);
  s.flags = static_cast<std::uint32_t>(sqlite3_column_int64(stmt, first + 8));
  return s;
}

/// Registers a session log file (device, inode) as open in this process through SQLite while it
/// lives. Closing any descriptor of such a file drops the POSIX locks SQLite holds on it, so a
/// file open here must never be opened and closed by other code (being_written reads
/// /proc/locks for it instead).
class OpenHere {
 public:
  OpenHere() = default;
  explicit OpenHere(const struct stat& st) : key_(st.st_dev, st.st_ino), registered_(true) {
    const std::lock_guard guard(mutex());
    ++files()[key_];
  }
  OpenHere(OpenHere&& o) noexcept : key_(o.key_), registered_(std::exchange(o.registered_, false)) {}
  OpenHere& operator=(OpenHere&& o) noexcept {
    std::swap(key_, o.key_);
    std::swap(registered_, o.registered_);
    return *this;
  }
  ~OpenHere() {
    if (!registered_) return;
    const std::lock_guard guard(mutex());
    if (--files()[key_] == 0) files().erase(key_);
  }

  static bool contains(const struct stat& st) {
    const std::lock_guard guard(mutex());
    return files().contains({st.st_dev, st.st_ino});
  }

 private:
  using Key = std::pair<dev_t, ino_t>;
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  static std::map<Key, int>& files() {
    static std::map<Key, int> f;
    return f;
  }
  Key key_{};
  bool registered_ = false;
};

/// The process that holds a flock on the file with this device and inode (from /proc/locks),
/// or 0 when none is listed; read without opening the file.
long flock_holder(dev_t dev, ino_t ino);

// The checks of a log file made outside SQLite (session_log_sqlite_checks.cpp).

/// Checks the file before SQLite sees it, so that the common mistakes get a precise message.
Status precheck_file(const std::string& path);

/// The page count in the file header against the file size: a copy that stopped early, or a
/// file cut by a full disk, is shorter than its header says ("" when it is whole).
std::string truncation_of(const std::string& path);

/// What the write-ahead log beside a log says about commits SQLite will not replay. SQLite
/// replays the -wal up to its first frame that fails the checksum chain and silently ignores
/// the rest; frames of the same generation (same salts) after that point that end a transaction
/// were committed and are lost. Only called when no writer holds the log (a live -wal grows).
struct WalCheck {
  bool present = false;
  std::size_t size = 0;           // bytes, when present
  std::string damage;             // committed frames that will not be replayed; empty when none
  bool torn_tail = false;         // the file ends inside a frame, or in frames no commit ends
  bool commits_replayed = false;  // SQLite reads pages of at least one commit from it
};

WalCheck check_wal(const std::string& path);

/// True when the file's header says WAL mode (bytes 18 and 19 are 2).
bool in_wal_mode(const std::string& path);

/// Why a log in WAL mode holds no tables, from its LOG-wal as `wal` describes it: the -wal is
/// missing (not copied with the log), holds only frames no commit ends (the writer stopped
/// while creating the log), or is empty (either).
std::string no_tables_in_wal_mode(const std::string& path, const WalCheck& wal);

/// True when a writer holds the log `st` describes (its flock, see lock_for_writing).
bool being_written(const std::string& path, const struct stat& st);

}  // namespace imucal::log::sqlite
