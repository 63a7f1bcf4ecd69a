// SPDX-License-Identifier: BSD-3-Clause
// Stored target detections in a session log (log/target_detections.hpp, docs/session-log.md).

#include "log/target_detections.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "core/text_format.hpp"
#include "log/session_log_sqlite.hpp"

namespace imucal::log {
namespace {

using sqlite::Stmt;

// Created when a set is first stored; IF NOT EXISTS so that a second writer changes nothing.
constexpr const char* kDetectionSchemaSql = R"sql(
CREATE TABLE IF NOT EXISTS target_detection_sets(
  stream_id INTEGER NOT NULL,
  target_key TEXT NOT NULL,
  description TEXT NOT NULL,
  frames INTEGER NOT NULL,
  created_utc TEXT NOT NULL,
  PRIMARY KEY(stream_id, target_key));
CREATE TABLE IF NOT EXISTS target_detections(
  stream_id INTEGER NOT NULL,
  target_key TEXT NOT NULL,
  t_ns INTEGER NOT NULL,
  data TEXT NOT NULL,
  PRIMARY KEY(stream_id, target_key, t_ns));
)sql";

std::string column_text(sqlite3_stmt* stmt, int index) {
  const auto* text = sqlite3_column_text(stmt, index);
  return text ? std::string(reinterpret_cast<const char*>(text),
                            static_cast<std::size_t>(sqlite3_column_bytes(stmt, index)))
              : std::string();
}

void bind_text(sqlite3_stmt* stmt, int index, const std::string& text) {
  sqlite3_bind_text(stmt, index, text.data(), static_cast<int>(text.size()), SQLITE_TRANSIENT);
}

/// What a file holds: a session log, or a detection cache.
enum class FileKind { kLog, kCache };

const char* kind_name(FileKind kind) { return kind == FileKind::kLog ? "session log" : "detection cache"; }

/// Opens a log or a cache; a file of another kind (application id) is refused. A cache opened
/// for writing is created when missing.
Result<sqlite::Db> open_file(const std::string& path, bool write, FileKind kind) {
  sqlite3* raw = nullptr;
  int flags = write ? SQLITE_OPEN_READWRITE : SQLITE_OPEN_READONLY;
  if (write && kind == FileKind::kCache) flags |= SQLITE_OPEN_CREATE;
  const int rc = sqlite3_open_v2(path.c_str(), &raw, flags, nullptr);
  sqlite::Db db(raw);
  if (rc != SQLITE_OK) {
    return make_error(
        rc == SQLITE_CANTOPEN ? Errc::kNotFound : Errc::kIo,
        std::string("cannot open ") + kind_name(kind) + " " + path + ": " + sqlite::errmsg(raw));
  }
  // A writer that holds the file (a recording in progress) gets a moment, then we give up.
  sqlite3_busy_timeout(db.get(), 2000);
  int prc = 0;
  Stmt stmt = sqlite::prepare(db.get(), "PRAGMA application_id", &prc);
  if (prc != SQLITE_OK || sqlite3_step(stmt.get()) != SQLITE_ROW) {
    return make_error(Errc::kCorrupt, std::string("cannot read ") + kind_name(kind) + " " + path + ": " +
                                          sqlite::errmsg(db.get()));
  }
  const int id = sqlite3_column_int(stmt.get(), 0);
  const int expected = kind == FileKind::kLog ? sqlite::kApplicationId : kDetectionCacheApplicationId;
  if (id == 0 && kind == FileKind::kCache && write) {
    // A new (empty) cache file: mark it as one.
    stmt.reset();
    Stmt count = sqlite::prepare(db.get(), "SELECT count(*) FROM sqlite_schema", &prc);
    if (prc == SQLITE_OK && sqlite3_step(count.get()) == SQLITE_ROW &&
        sqlite3_column_int(count.get(), 0) == 0) {
      count.reset();
      if (sqlite::exec(db.get(), ("PRAGMA application_id=" + std::to_string(expected)).c_str()) == SQLITE_OK)
        return db;
    }
  }
  if (id != expected) {
    return make_error(Errc::kCorrupt, path + " is not a " + kind_name(kind) + " (wrong application id)");
  }
  return db;
}

bool has_table(sqlite3* db, const char* name) {
  int rc = 0;
  Stmt stmt = sqlite::prepare(db, "SELECT 1 FROM sqlite_schema WHERE type='table' AND name=?1", &rc);
  if (rc != SQLITE_OK) return false;
  sqlite3_bind_text(stmt.get(), 1, name, -1, SQLITE_STATIC);
  return sqlite3_step(stmt.get()) == SQLITE_ROW;
}

Status read_rows(sqlite3* db, const std::string& path, int stream_id, DetectionSet* set) {
  int rc = 0;
  Stmt stmt = sqlite::prepare(
      db, "SELECT t_ns, data FROM target_detections WHERE stream_id=?1 AND target_key=?2 ORDER BY t_ns", &rc);
  if (rc != SQLITE_OK) {
    return make_error(Errc::kCorrupt, path + ": stored detections unreadable: " + sqlite::errmsg(db));
  }
  sqlite3_bind_int(stmt.get(), 1, stream_id);
  bind_text(stmt.get(), 2, set->target_key);
  while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    set->detections.push_back({sqlite3_column_int64(stmt.get(), 0), column_text(stmt.get(), 1)});
  }
  if (rc != SQLITE_DONE) {
    return make_error(Errc::kCorrupt, path + ": stored detections unreadable: " + sqlite::errmsg(db));
  }
  return {};
}

/// Inserts the set's rows inside the caller's transaction.
Status insert_set(sqlite3* db, int stream_id, const DetectionSet& set, const std::string& created) {
  int rc = 0;
  Stmt del = sqlite::prepare(db, "DELETE FROM target_detections WHERE stream_id=?1 AND target_key=?2", &rc);
  if (rc != SQLITE_OK) return make_error(Errc::kIo, sqlite::errmsg(db));
  sqlite3_bind_int(del.get(), 1, stream_id);
  bind_text(del.get(), 2, set.target_key);
  if (sqlite3_step(del.get()) != SQLITE_DONE) return make_error(Errc::kIo, sqlite::errmsg(db));
  Stmt head = sqlite::prepare(db, "INSERT OR REPLACE INTO target_detection_sets VALUES(?1,?2,?3,?4,?5)", &rc);
  if (rc != SQLITE_OK) return make_error(Errc::kIo, sqlite::errmsg(db));
  sqlite3_bind_int(head.get(), 1, stream_id);
  bind_text(head.get(), 2, set.target_key);
  bind_text(head.get(), 3, set.description);
  sqlite3_bind_int64(head.get(), 4, set.frames);
  bind_text(head.get(), 5, created);
  if (sqlite3_step(head.get()) != SQLITE_DONE) return make_error(Errc::kIo, sqlite::errmsg(db));
  Stmt row = sqlite::prepare(db, "INSERT OR REPLACE INTO target_detections VALUES(?1,?2,?3,?4)", &rc);
  if (rc != SQLITE_OK) return make_error(Errc::kIo, sqlite::errmsg(db));
  for (const StoredDetection& d : set.detections) {
    sqlite3_bind_int(row.get(), 1, stream_id);
    bind_text(row.get(), 2, set.target_key);
    sqlite3_bind_int64(row.get(), 3, d.t_ns);
    bind_text(row.get(), 4, d.data);
    const int step = sqlite3_step(row.get());
    sqlite3_reset(row.get());
    if (step != SQLITE_DONE) return make_error(Errc::kIo, sqlite::errmsg(db));
  }
  return {};
}

Result<std::optional<DetectionSet>> read_set(const std::string& log_path, FileKind kind, int stream_id,
                                             const std::string& target_key) {
  auto db = open_file(log_path, false, kind);
  if (!db.ok()) return db.error();
  if (!has_table(db->get(), "target_detection_sets")) return std::optional<DetectionSet>{};
  // One read transaction: the set row and its detections are one snapshot.
  (void)sqlite::exec(db->get(), "BEGIN");
  int rc = 0;
  Stmt stmt = sqlite::prepare(db->get(),
                              "SELECT description, frames, created_utc FROM target_detection_sets "
                              "WHERE stream_id=?1 AND target_key=?2",
                              &rc);
  if (rc != SQLITE_OK) {
    return make_error(Errc::kCorrupt,
                      log_path + ": stored detections unreadable: " + sqlite::errmsg(db->get()));
  }
  sqlite3_bind_int(stmt.get(), 1, stream_id);
  bind_text(stmt.get(), 2, target_key);
  rc = sqlite3_step(stmt.get());
  if (rc == SQLITE_DONE) return std::optional<DetectionSet>{};
  if (rc != SQLITE_ROW) {
    return make_error(Errc::kCorrupt,
                      log_path + ": stored detections unreadable: " + sqlite::errmsg(db->get()));
  }
  DetectionSet set;
  set.target_key = target_key;
  set.description = column_text(stmt.get(), 0);
  set.frames = sqlite3_column_int64(stmt.get(), 1);
  set.created_utc = column_text(stmt.get(), 2);
  IMUCAL_TRY(read_rows(db->get(), log_path, stream_id, &set));
  (void)sqlite::exec(db->get(), "COMMIT");
  return std::optional<DetectionSet>(std::move(set));
}

Status write_set(const std::string& log_path, FileKind kind, int stream_id, const DetectionSet& set) {
  if (set.target_key.empty()) return make_error(Errc::kInvalidArgument, "a detection set needs a target key");
  // A file without write permission is read-only to every user: root, whom the mode does not
  // stop, does not write into it either.
  struct stat st {};
  if (::stat(log_path.c_str(), &st) == 0 && (st.st_mode & 0222) == 0) {
    return make_error(Errc::kIo, std::string(kind_name(kind)) + " " + log_path +
                                     " is read-only (no write permission): detections not stored; "
                                     "chmod u+w it to store them");
  }
  auto db = open_file(log_path, true, kind);
  if (!db.ok()) return db.error();
  sqlite3* h = db->get();
  if (sqlite3_db_readonly(h, "main") == 1) {
    return make_error(Errc::kIo,
                      std::string(kind_name(kind)) + " " + log_path + " is read-only: detections not stored");
  }
  auto failed = [&](const std::string& why) -> Status {
    const int code = sqlite3_extended_errcode(h);
    (void)sqlite::exec(h, "ROLLBACK");
    std::string message =
        std::string(kind_name(kind)) + " " + log_path + ": storing detections failed: " + why;
    if (code == SQLITE_READONLY_DIRECTORY || (code & 0xff) == SQLITE_CANTOPEN)
      message += " (its folder must be writable for the journal)";
    return make_error(Errc::kIo, message + "; the file is unchanged");
  };
  // The journal mode the log has (DELETE once closed, WAL while recording) is kept; FULL sync
  // makes the commit durable.
  if (sqlite::exec(h, "PRAGMA synchronous=FULL") != SQLITE_OK) return failed(sqlite::errmsg(h));
  if (sqlite::exec(h, "BEGIN IMMEDIATE") != SQLITE_OK) return failed(sqlite::errmsg(h));
  if (sqlite::exec(h, kDetectionSchemaSql) != SQLITE_OK) return failed(sqlite::errmsg(h));
  if (auto s = insert_set(h, stream_id, set, utc_now_iso8601()); !s.ok()) return failed(s.error().message);
  if (sqlite::exec(h, "COMMIT") != SQLITE_OK) return failed(sqlite::errmsg(h));
  return {};
}

}  // namespace

Result<std::optional<DetectionSet>> read_target_detections(const std::string& log_path, int stream_id,
                                                           const std::string& target_key) {
  return read_set(log_path, FileKind::kLog, stream_id, target_key);
}

Status write_target_detections(const std::string& log_path, int stream_id, const DetectionSet& set) {
  return write_set(log_path, FileKind::kLog, stream_id, set);
}

namespace {

/// The cache is imucal's own file: a symbolic link, FIFO, device or folder at its path is
/// refused (never followed or opened), whatever it points to.
Status check_cache_path(const std::string& cache_path) {
  struct stat st {};
  if (::lstat(cache_path.c_str(), &st) != 0 || S_ISREG(st.st_mode)) return {};
  return make_error(Errc::kIo, "the detection cache " + cache_path +
                                   (S_ISLNK(st.st_mode) ? " is a symbolic link" : " is not a regular file") +
                                   ": not followed or opened; remove it (the cache is made again) or pass "
                                   "--no-cache");
}

/// True when the file at `path` is a damaged detection cache: not an SQLite database at all
/// (garbage, cut short), or one whose header carries the cache's application id. Another
/// program's SQLite file (a session log among them) is not.
bool damaged_cache(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char header[72] = {};
  in.read(header, sizeof header);
  if (in.gcount() < static_cast<std::streamsize>(sizeof header) ||
      std::string(header, 16) != std::string("SQLite format 3\0", 16))
    return true;
  const auto byte = [&](int i) { return static_cast<std::uint32_t>(static_cast<unsigned char>(header[i])); };
  const std::uint32_t id = byte(68) << 24 | byte(69) << 16 | byte(70) << 8 | byte(71);
  return id == static_cast<std::uint32_t>(kDetectionCacheApplicationId);
}

}  // namespace

Result<std::optional<DetectionSet>> read_detection_cache(const std::string& cache_path,
                                                         const std::string& target_key) {
  IMUCAL_TRY(check_cache_path(cache_path));
  std::error_code ec;
  if (!std::filesystem::exists(cache_path, ec)) return std::optional<DetectionSet>{};
  return read_set(cache_path, FileKind::kCache, 0, target_key);
}

Status write_detection_cache(const std::string& cache_path, const DetectionSet& set) {
  const std::filesystem::path parent = std::filesystem::path(cache_path).parent_path();
  std::error_code ec;
  if (!parent.empty()) std::filesystem::create_directories(parent, ec);
  if (ec) {
    return make_error(Errc::kIo,
                      "cannot create the detection cache folder " + parent.string() + ": " + ec.message());
  }
  IMUCAL_TRY(check_cache_path(cache_path));
  Status written = write_set(cache_path, FileKind::kCache, 0, set);
  if (written.ok() || written.error().code != Errc::kCorrupt || !damaged_cache(cache_path)) return written;
  // A damaged cache would refuse every later run: a new one holding this set takes its place in
  // one rename (the others' sets are searched again when asked for).
  const std::string fresh = cache_path + ".new-" + std::to_string(::getpid());
  std::filesystem::remove(fresh, ec);
  Status made = write_set(fresh, FileKind::kCache, 0, set);
  // The damaged file's journal must not be played back into its successor.
  if (made.ok()) {
    for (const char* suffix : {"-journal", "-wal", "-shm"}) std::filesystem::remove(cache_path + suffix, ec);
  }
  if (made.ok() && ::rename(fresh.c_str(), cache_path.c_str()) != 0)
    made = make_error(
        Errc::kIo, "cannot replace the damaged detection cache " + cache_path + ": " + std::strerror(errno));
  if (!made.ok()) {
    std::filesystem::remove(fresh, ec);
    return made.error().context("the detection cache " + cache_path + " is damaged (" +
                                written.error().message + ") and was not replaced");
  }
  return {};
}

}  // namespace imucal::log
