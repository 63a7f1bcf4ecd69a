// SPDX-License-Identifier: BSD-3-Clause
// The session log on SQLite, its reader: SessionLogReader::open, the checks of a file before
// and after SQLite opens it, and the salvage of a damaged one. The writer is in
// session_log_sqlite_writer.cpp. Schema and guarantees: docs/session-log.md.

#include "log/session_log_sqlite.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <future>
#include <iterator>
#include <limits>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <system_error>
#include <thread>
#include <utility>

#include "core/text_format.hpp"
#include "core/version.hpp"
#include "log/dataset_io.hpp"
#include "log/session_log.hpp"

namespace imucal::log {

using sqlite::Stmt;
using namespace sqlite;  // the row helpers and metadata keys

namespace {

class SqliteSessionLogReader final : public SessionLogReader {
 public:
  SqliteSessionLogReader(std::string path, const SessionLogReaderOptions& options)
      : path_(std::move(path)), options_(options) {}

  Status open();

  const SessionLogHealth& health() const override { return health_; }
  const std::map<std::string, std::string>& metadata() const override { return metadata_; }
  const std::map<int, ImuStreamInfo>& imu_streams() const override { return imu_streams_; }
  const std::map<int, CameraStreamInfo>& camera_streams() const override { return camera_streams_; }

  Result<int> find_imu_stream(const std::string& name) const override {
    return find_stream(imu_streams_, name, "IMU");
  }
  Result<int> find_camera_stream(const std::string& name) const override {
    return find_stream(camera_streams_, name, "camera");
  }

  Status for_each_imu(int stream_id, TimeNs t0_ns, TimeNs t1_ns,
                      const std::function<bool(const ImuSample&)>& visit) const override;
  Status for_each_frame(int stream_id, TimeNs t0_ns, TimeNs t1_ns,
                        const std::function<bool(const CameraFrame&)>& visit) const override;
  Result<std::vector<TimeNs>> frame_times(int stream_id) const override;
  Result<std::uint64_t> frame_fingerprint(int stream_id) const override;
  Result<std::vector<Event>> events() const override { return events_; }
  Result<std::int64_t> imu_count(int stream_id) const override;
  Result<std::int64_t> frame_count(int stream_id) const override;
  Result<std::vector<ImuSample>> take_imu(int stream_id) override;

 private:
  template <class Info>
  static Result<int> find_stream(const std::map<int, Info>& streams, const std::string& name,
                                 const char* kind) {
    for (const auto& [id, info] : streams) {
      if (name.empty() || info.name == name) return id;
    }
    std::string names;
    for (const auto& [id, info] : streams) names += (names.empty() ? "" : ", ") + info.name;
    if (name.empty())
      return make_error(Errc::kNotFound, std::string("the session log has no ") + kind + " stream");
    return make_error(Errc::kNotFound, std::string("the session log has no ") + kind + " stream named '" +
                                           name + "' (it has: " + (names.empty() ? "none" : names) + ")");
  }

  Error sql_error(const std::string& what) const {
    return make_error(Errc::kCorrupt,
                      "session log " + path_ + ": " + what + ": " + sqlite::errmsg(db_.get()));
  }
  void note_damage(const std::string& what) const;
  // Copies the blob in column `col` (its CRC in `col + 1`) into frame->data; false, with the
  // damage noted, when the data does not match its CRC.
  bool load_frame_data(sqlite3_stmt* stmt, int col, CameraFrame* frame) const;

  Status read_schema();
  Status read_metadata();
  void read_streams();
  void scan_imu();
  void scan_frames();
  void read_events();
  void apply_salvage();
  // Visits the rows of `sql` (rowid first, "WHERE rowid >= ?1 ORDER BY rowid") in storage
  // order. At a damaged page it looks for the next readable row by seeking ever further ahead
  // (rowids are assigned in insertion order), so rows behind a damaged leaf page are still
  // found when the pages above it are intact. Returns the number of damaged stretches skipped.
  int scan_skipping_damage(const char* sql, const char* table, const std::function<void(sqlite3_stmt*)>& row);
  // Per stream: the rows and a sum of a hash of each row's (rowid, stream, t_ns). The table's in
  // storage order (no index), false with SQLite's message at an unreadable page; the time
  // index's alone (a covering scan), false when unreadable or out of order. Equal digests mean
  // the index holds exactly the table's rows and times, so reads through it miss none.
  struct StreamDigest {
    std::int64_t count = 0;
    std::uint64_t sum = 0;
    // Whether the table holds the stream's rows in time order (a writer appends them so), and
    // the first and last times seen; the index and the table agree by count and sum alone.
    bool in_time_order = true;
    std::int64_t first_t = std::numeric_limits<std::int64_t>::max();
    std::int64_t last_t = std::numeric_limits<std::int64_t>::min();
    bool operator==(const StreamDigest& o) const { return count == o.count && sum == o.sum; }
    // Adds the digest of the rows that follow this one's in storage order.
    void append(const StreamDigest& later) {
      in_time_order =
          in_time_order && later.in_time_order && (count == 0 || later.count == 0 || last_t <= later.first_t);
      if (count == 0) first_t = later.first_t;
      if (later.count > 0) last_t = later.last_t;
      count += later.count;
      sum += later.sum;
    }
  };
  using Digests = std::map<int, StreamDigest>;
  using ImuRows = std::map<int, std::vector<ImuSample>>;
  // Rows with rowid in (after, upto].
  struct RowidRange {
    sqlite3_int64 after = std::numeric_limits<sqlite3_int64>::min();
    sqlite3_int64 upto = std::numeric_limits<sqlite3_int64>::max();
  };
  // The digest of the table's rows in `range`, in storage order, on `db`; with `rows`, the IMU
  // table's samples are read by the same walk and kept per stream, the first stream's with
  // room for `room` samples.
  bool digest_table(sqlite3* db, const char* table, RowidRange range, Digests* out, std::string* error,
                    ImuRows* rows, std::size_t room) const;
  // The table's largest rowid, found without a walk; 0 when unknown or the table is empty.
  sqlite3_int64 max_rowid(const char* table) const;
  // The time index agrees with its table; the counts per stream when it does, and the streams
  // whose rows the table holds in time order. The index and the table's last rows are walked on
  // a second connection meanwhile when the file is known not to change between the walks
  // (walk_index_aside_).
  bool index_agrees(const char* table, const char* index, std::map<int, std::int64_t>* counts,
                    std::set<int>* in_time_order, bool* table_ok, std::string* table_error,
                    ImuRows* rows = nullptr) const;

  std::string path_;
  SessionLogReaderOptions options_;
  // No writer holds the log and nothing was found damaged before the table checks: a
  // connection of its own can walk the index (and part of the table) in parallel and see the
  // same rows (index_agrees).
  bool walk_index_aside_ = false;
  OpenHere open_here_;  // declared before db_: registered until SQLite has closed the file
  sqlite::Db db_;
  mutable SessionLogHealth health_;
  std::map<std::string, std::string> metadata_;
  std::map<int, ImuStreamInfo> imu_streams_;
  std::map<int, CameraStreamInfo> camera_streams_;
  std::set<std::string> tables_;
  std::vector<Event> events_;
  std::map<int, std::int64_t> imu_counts_, frame_counts_;
  // Streams whose whole read can walk the table in storage order (which is their time order),
  // several times faster than a walk of the index with a lookup of every row.
  std::set<int> imu_table_in_time_order_;

  // When the IMU table or its time index cannot be trusted, the readable samples are held
  // here per stream, sorted by time, and reads are served from memory.
  bool imu_in_memory_ = false;
  ImuRows imu_memory_;
  // Streams read whole while opening (preload_imu) and not yet taken, sorted by time.
  ImuRows imu_preloaded_;
  // Likewise for frames; `data` of these is loaded on demand by rowid (or held, when it came
  // from the salvage scanner).
  struct FrameRef {
    CameraFrame frame;  // without data unless `has_data`
    sqlite3_int64 rowid = 0;
    bool has_data = false;
  };
  bool frames_in_memory_ = false;
  std::map<int, std::vector<FrameRef>> frame_memory_;
};

void SqliteSessionLogReader::note_damage(const std::string& what) const {
  health_.damaged = true;
  if (!health_.damage_message.empty()) health_.damage_message += "; ";
  health_.damage_message += what;
}

bool SqliteSessionLogReader::load_frame_data(sqlite3_stmt* stmt, int col, CameraFrame* frame) const {
  const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(stmt, col));
  const auto bytes = static_cast<std::size_t>(sqlite3_column_bytes(stmt, col));
  const auto stored = static_cast<std::uint32_t>(sqlite3_column_int64(stmt, col + 1));
  if (bytes > 0 && data == nullptr) return false;
  if (sqlite::crc32(data, bytes) != stored) {
    note_damage("image data of the frame at t_ns=" + std::to_string(frame->t_ns) +
                " is corrupt (CRC mismatch); the frame was skipped");
    return false;
  }
  frame->data.assign(data, data + bytes);
  return true;
}

Status SqliteSessionLogReader::open() {
  IMUCAL_TRY(precheck_file(path_));
  struct stat st {};
  bool live = false;
  if (::stat(path_.c_str(), &st) == 0) {
    live = being_written(path_, st);
    open_here_ = OpenHere(st);  // from here on SQLite may hold locks on the file
  }
  const WalCheck wal = live ? WalCheck{} : check_wal(path_);
  if (!wal.damage.empty()) note_damage(wal.damage);
  // The header's page count may have been written by a checkpoint that could not extend the
  // file (a full disk): pages the -wal holds are read from there, and a page missing from both
  // fails its read (the strict VFS), which the table scans report.
  if (!wal.commits_replayed && !live) {
    if (const std::string truncated = truncation_of(path_); !truncated.empty()) note_damage(truncated);
  }
  // A live log's writer has its -wal; and its file must not be opened and closed here (OpenHere).
  const bool wal_mode = !live && in_wal_mode(path_);
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(path_.c_str(), &raw, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX,
                                 sqlite::strict_vfs_name());
  db_.reset(raw);
  if (rc != SQLITE_OK) {
    return make_error(Errc::kNotFound, "cannot open session log " + path_ + ": " + sqlite::errmsg(raw));
  }
  // No memory mapping (a file truncated underneath would fault); extra checks of every page
  // as it is read so that damage shows up as an error, early.
  (void)sqlite::exec(db_.get(), "PRAGMA mmap_size=0; PRAGMA cell_size_check=ON;");
  // One read transaction for all checks, so that a log still being written is seen as one
  // consistent snapshot (the table and index counts must agree).
  (void)sqlite::exec(db_.get(), "BEGIN");
  if (Status schema = read_schema(); !schema.ok()) {
    if (!wal_mode || !tables_.empty()) return schema;
    return make_error(Errc::kCorrupt, no_tables_in_wal_mode(path_, wal));
  }
  IMUCAL_TRY(read_metadata());
  read_streams();
  walk_index_aside_ = !live && !health_.damaged;
  scan_imu();
  scan_frames();
  read_events();
  (void)sqlite::exec(db_.get(), "COMMIT");
  if (health_.damaged) apply_salvage();
  const auto complete = metadata_.find(kKeyComplete);
  health_.complete = complete != metadata_.end() && complete->second == "1";
  // A closed log's writer checkpointed its -wal; a torn one beside it came from elsewhere.
  if (health_.complete && wal.torn_tail && wal.damage.empty())
    note_damage("its write-ahead log " + path_ +
                "-wal ends in frames no commit completes, which the writer of "
                "a closed log never leaves: it was truncated or damaged, and what it held is lost");
  return {};
}

Status SqliteSessionLogReader::read_schema() {
  for (int attempt = 0; attempt < 2; ++attempt) {
    int rc = 0;
    Stmt stmt = sqlite::prepare(db_.get(), "SELECT name FROM sqlite_schema WHERE type='table'", &rc);
    while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW)
      tables_.insert(column_text(stmt.get(), 0));
    if (rc == SQLITE_DONE) break;
    const int primary = sqlite3_extended_errcode(db_.get()) & 0xff;
    if (primary == SQLITE_NOTADB) {
      return make_error(Errc::kCorrupt, path_ + " is not a session log (" + sqlite::errmsg(db_.get()) + ")");
    }
    if (primary == SQLITE_BUSY || primary == SQLITE_CANTOPEN) {
      return make_error(Errc::kIo, "cannot read session log " + path_ + ": " + sqlite::errmsg(db_.get()) +
                                       " (a log still being written needs write access to its directory for "
                                       "the -shm file)");
    }
    if (attempt == 1 || !sqlite::is_corruption(primary)) {
      return make_error(Errc::kCorrupt, "session log " + path_ +
                                            " is damaged beyond recovery: its schema is "
                                            "unreadable (" +
                                            sqlite::errmsg(db_.get()) + ")");
    }
    // A truncated file fails the page-count check before anything is read; reading what
    // remains is allowed with writable_schema (which changes nothing on a read-only connection).
    tables_.clear();
    (void)sqlite::exec(db_.get(), "PRAGMA writable_schema=ON");
  }
  if (!tables_.contains("metadata")) {
    return make_error(Errc::kCorrupt, path_ +
                                          " is an SQLite database but not a session log (it has no metadata "
                                          "table); pass an .imulog file");
  }
  return {};
}

Status SqliteSessionLogReader::read_metadata() {
  int rc = 0;
  Stmt stmt = sqlite::prepare(db_.get(), "SELECT key, value FROM metadata", &rc);
  while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    metadata_[column_text(stmt.get(), 0)] = column_text(stmt.get(), 1);
  }
  if (rc != SQLITE_DONE) note_damage("metadata partly unreadable (" + sqlite::errmsg(db_.get()) + ")");
  const auto version = metadata_.find(kKeySchemaVersion);
  if (version == metadata_.end()) {
    if (health_.damaged) {
      return make_error(Errc::kCorrupt, "session log " + path_ +
                                            " is damaged beyond recovery: its metadata is "
                                            "unreadable (" +
                                            health_.damage_message + ")");
    }
    return make_error(Errc::kCorrupt, path_ + " is not a session log (its metadata has no schema_version)");
  }
  int schema = 0;
  if (std::sscanf(version->second.c_str(), "%d", &schema) != 1 || schema < 1) {
    return make_error(Errc::kCorrupt, path_ + " is not a session log (schema_version '" + version->second +
                                          "' is not a number)");
  }
  if (schema > kSessionLogSchemaVersion) {
    // An input this build cannot read, like a malformed one (exit 3 in every command).
    const auto writer = metadata_.find(kKeySoftwareVersion);
    return make_error(Errc::kCorrupt, "session log " + path_ + " has schema version " +
                                          std::to_string(schema) + " (written by imucal " +
                                          (writer == metadata_.end() ? std::string("?") : writer->second) +
                                          "); this imucal " + kVersion + " reads up to version " +
                                          std::to_string(kSessionLogSchemaVersion) +
                                          ": update imucal to read it");
  }
  for (const char* table : {"imu_streams", "camera_streams", "imu_samples", "frames", "events"}) {
    if (!tables_.contains(table)) {
      note_damage(std::string("table ") + table + " is missing");
    }
  }
  return {};
}

void SqliteSessionLogReader::read_streams() {
  int rc = 0;
  if (tables_.contains("imu_streams")) {
    Stmt stmt = sqlite::prepare(db_.get(), "SELECT * FROM imu_streams ORDER BY id", &rc);
    while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
      sqlite3_stmt* s = stmt.get();
      ImuStreamInfo info;
      info.name = column_text(s, 1);
      info.units = column_text(s, 2) == "raw" ? ImuUnits::kRaw : ImuUnits::kSi;
      info.rate_hz = sqlite3_column_double(s, 3);
      int col = 4;
      for (AxisConversion* conv : {&info.accel, &info.gyro}) {
        for (int i = 0; i < 3; ++i) conv->scale[i] = sqlite3_column_double(s, col++);
        for (int i = 0; i < 3; ++i) conv->offset[i] = sqlite3_column_double(s, col++);
      }
      info.temperature_scale = sqlite3_column_double(s, 16);
      info.temperature_offset = sqlite3_column_double(s, 17);
      info.accel_full_scale_g = sqlite3_column_int(s, 18);
      info.gyro_full_scale_dps = sqlite3_column_int(s, 19);
      info.dlpf_hz = sqlite3_column_int(s, 20);
      info.device = column_text(s, 21);
      imu_streams_[sqlite3_column_int(s, 0)] = std::move(info);
    }
    if (rc != SQLITE_DONE)
      note_damage("IMU stream table partly unreadable (" + sqlite::errmsg(db_.get()) + ")");
  }
  if (tables_.contains("camera_streams")) {
    Stmt stmt = sqlite::prepare(db_.get(), "SELECT * FROM camera_streams ORDER BY id", &rc);
    while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
      sqlite3_stmt* s = stmt.get();
      CameraStreamInfo info;
      info.name = column_text(s, 1);
      info.width = sqlite3_column_int(s, 2);
      info.height = sqlite3_column_int(s, 3);
      info.rate_hz = sqlite3_column_double(s, 4);
      info.backend = column_text(s, 5);
      info.device = column_text(s, 6);
      info.timestamp_source = column_text(s, 7);
      camera_streams_[sqlite3_column_int(s, 0)] = std::move(info);
    }
    if (rc != SQLITE_DONE)
      note_damage("camera stream table partly unreadable (" + sqlite::errmsg(db_.get()) + ")");
  }
}

int SqliteSessionLogReader::scan_skipping_damage(const char* sql, const char* table,
                                                 const std::function<void(sqlite3_stmt*)>& row) {
  // The largest rowid, if the right edge of the table is readable; else search a wide range.
  sqlite3_int64 max_rowid = 0;
  bool max_known = false;
  {
    int rc = 0;
    const std::string max_sql = std::string("SELECT max(rowid) FROM ") + table;
    Stmt stmt = sqlite::prepare(db_.get(), max_sql.c_str(), &rc);
    if (rc == SQLITE_OK && sqlite3_step(stmt.get()) == SQLITE_ROW) {
      max_rowid = sqlite3_column_int64(stmt.get(), 0);
      max_known = true;
    }
  }
  int rc = 0;
  Stmt stmt = sqlite::prepare(db_.get(), sql, &rc);
  if (rc != SQLITE_OK) return 1;
  int skipped = 0;
  sqlite3_int64 last = 0;  // rowids start at 1
  bool any = false;
  sqlite3_int64 from = std::numeric_limits<sqlite3_int64>::min();
  // Every row is taken once, in increasing rowid: a damaged page can hand back rows out of order
  // or again after a resume, and each resume must move past the one before, so the scan ends.
  for (;;) {
    sqlite3_reset(stmt.get());
    sqlite3_bind_int64(stmt.get(), 1, from);
    while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
      const sqlite3_int64 rowid = sqlite3_column_int64(stmt.get(), 0);
      if (any && rowid <= last) continue;
      any = true;
      last = rowid;
      row(stmt.get());
    }
    if (rc == SQLITE_DONE) return skipped;
    if (++skipped > 100000) return skipped;
    // Find the next readable row after what was read (or after the last resume, when nothing
    // was read since): probe base+1, +2, +4, ... and take the first probe that yields a row.
    // base only grows, so every resume moves on and the scan ends.
    const sqlite3_int64 base = std::max(last, from);
    if (base > std::numeric_limits<sqlite3_int64>::max() - (sqlite3_int64{1} << 42)) return skipped;
    bool resumed = false;
    const sqlite3_int64 limit = max_known ? max_rowid : base + (sqlite3_int64{1} << 40);
    for (sqlite3_int64 step = 1; base + step <= limit && step < (sqlite3_int64{1} << 41); step *= 2) {
      sqlite3_reset(stmt.get());
      sqlite3_bind_int64(stmt.get(), 1, base + step);
      rc = sqlite3_step(stmt.get());
      if (rc == SQLITE_DONE) return skipped;
      if (rc == SQLITE_ROW) {
        from = base + step;
        resumed = true;
        break;
      }
    }
    if (!resumed) return skipped;
  }
}

namespace {

std::uint64_t row_hash(std::int64_t rowid, int stream, std::int64_t t_ns) {
  // splitmix64 of the three, so a changed value anywhere changes the sum.
  std::uint64_t x = static_cast<std::uint64_t>(rowid) * 0x9e3779b97f4a7c15ULL ^
                    static_cast<std::uint64_t>(t_ns) ^ (static_cast<std::uint64_t>(stream) << 48);
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

sqlite3_int64 SqliteSessionLogReader::max_rowid(const char* table) const {
  int rc = 0;
  Stmt stmt = sqlite::prepare(db_.get(), (std::string("SELECT max(rowid) FROM ") + table).c_str(), &rc);
  if (rc != SQLITE_OK || sqlite3_step(stmt.get()) != SQLITE_ROW) return 0;
  return std::max<sqlite3_int64>(sqlite3_column_int64(stmt.get(), 0), 0);
}

bool SqliteSessionLogReader::digest_table(sqlite3* db, const char* table, RowidRange range, Digests* out,
                                          std::string* error, ImuRows* rows, std::size_t room) const {
  int rc = 0;
  // Only the bounds a part has: a test of the rowid against a bound that cannot end the walk
  // still costs 5 % of it.
  std::string where;
  if (range.after != RowidRange{}.after) where = " WHERE rowid > " + std::to_string(range.after);
  if (range.upto != RowidRange{}.upto)
    where += (where.empty() ? " WHERE" : " AND") + std::string(" rowid <= ") + std::to_string(range.upto);
  const std::string sql = std::string("SELECT rowid, stream_id, t_ns") +
                          (rows ? ", ax, ay, az, gx, gy, gz, temperature, flags" : "") + " FROM " + table +
                          " NOT INDEXED" + where;
  Stmt stmt = sqlite::prepare(db, sql.c_str(), &rc);
  // The rows of one stream come in runs: its digest and samples are looked up once per run.
  int run_stream = 0;
  StreamDigest* d = nullptr;
  std::vector<ImuSample>* samples = nullptr;
  while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    const int stream = sqlite3_column_int(stmt.get(), 1);
    const std::int64_t t = sqlite3_column_int64(stmt.get(), 2);
    // A time no writer stores (beyond 2^62 ns) makes the table disagree with any index, so
    // the rows are loaded one by one and such rows left out.
    if (!time_in_range(t)) (*out)[std::numeric_limits<int>::min()].count += 1;
    if (d == nullptr || stream != run_stream) {
      run_stream = stream;
      d = &(*out)[stream];
      if (rows) {
        // A log mostly holds one stream: growing a vector of 51200 samples step by step costs
        // a fifth of this walk.
        const bool first = rows->empty();
        samples = &(*rows)[stream];
        if (first) samples->reserve(room);
      }
    }
    if (d->count++ == 0) d->first_t = t;
    d->sum += row_hash(sqlite3_column_int64(stmt.get(), 0), stream, t);
    if (t < d->last_t) d->in_time_order = false;
    d->last_t = t;
    if (rows) samples->push_back(read_sample_columns(stmt.get(), 2));
  }
  if (rc == SQLITE_DONE) return true;
  *error = sqlite::errmsg(db);
  return false;
}

namespace {

/// The digest of a time index alone (a covering scan) on `db`; false when unreadable or out of
/// order.
template <class Digests>
bool digest_index(sqlite3* db, const char* table, const char* index, Digests* out) {
  int rc = 0;
  const std::string sql = std::string("SELECT rowid, stream_id, t_ns FROM ") + table + " INDEXED BY " +
                          index + " ORDER BY stream_id, t_ns";
  Stmt stmt = sqlite::prepare(db, sql.c_str(), &rc);
  int prev_stream = std::numeric_limits<int>::min();
  std::int64_t prev_t = std::numeric_limits<std::int64_t>::min();
  while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    const int stream = sqlite3_column_int(stmt.get(), 1);
    const std::int64_t t = sqlite3_column_int64(stmt.get(), 2);
    // The index's own order: a changed key puts an entry out of it, and a search through the
    // index would then miss entries.
    if (stream < prev_stream || (stream == prev_stream && t < prev_t)) return false;
    prev_stream = stream;
    prev_t = t;
    auto& d = (*out)[stream];
    d.count += 1;
    d.sum += row_hash(sqlite3_column_int64(stmt.get(), 0), stream, t);
  }
  return rc == SQLITE_DONE;
}

/// A second read-only connection to a log, set up like the reader's own; null when it cannot be
/// opened.
sqlite::Db open_aside(const std::string& path) {
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &raw, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX,
                                 sqlite::strict_vfs_name());
  sqlite::Db db(raw);
  if (rc != SQLITE_OK ||
      sqlite::exec(db.get(), "PRAGMA mmap_size=0; PRAGMA cell_size_check=ON; BEGIN") != SQLITE_OK)
    return sqlite::Db();
  return db;
}

}  // namespace

bool SqliteSessionLogReader::index_agrees(const char* table, const char* index,
                                          std::map<int, std::int64_t>* counts, std::set<int>* in_time_order,
                                          bool* table_ok, std::string* table_error, ImuRows* rows) const {
  Digests from_table, from_index;
  // Only a walk that keeps the samples needs the row count: for their room, and to split.
  const sqlite3_int64 last_rowid = rows ? max_rowid(table) : 0;
  // Room for every row, bounded by what the file can hold (16 bytes a row at the least): a
  // damaged or edited file can claim any rowid.
  std::size_t room = 0;
  if (rows) {
    std::error_code ec;
    const std::uintmax_t bytes = std::filesystem::file_size(path_, ec);
    if (!ec)
      room = static_cast<std::size_t>(
          std::min<std::uintmax_t>(static_cast<std::uintmax_t>(last_rowid), bytes / 16));
  }
  // The walks are independent reads of one unchanging file. On a second core, when there is
  // one, a connection of its own walks the index, and when the samples are kept (eleven
  // columns a row against the index's three) then the table's last 45 % of rows too, which
  // evens the two out for tables of more than kSplitRows rows; the rest is walked here
  // meanwhile. Without the samples the two walks cost about the same and are not split.
  constexpr sqlite3_int64 kSplitRows = 4096;
  RowidRange mine, theirs{0, 0};
  struct Aside {
    bool opened = false, index_ok = false, table_ok = false;
    Digests index, table;
    ImuRows rows;
    std::string error;
  };
  std::future<Aside> aside;
  if (walk_index_aside_ && std::thread::hardware_concurrency() > 1) {
    if (last_rowid > kSplitRows) {
      theirs = {last_rowid - last_rowid / 20 * 9, std::numeric_limits<sqlite3_int64>::max()};  // 45 %
      mine.upto = theirs.after;
    }
    const std::size_t their_room = room - std::min<std::size_t>(room, static_cast<std::size_t>(theirs.after));
    aside = std::async(std::launch::async, [this, table, index, theirs, rows, their_room] {
      Aside a;
      const sqlite::Db db = open_aside(path_);
      if (!db) return a;
      a.opened = true;
      a.index_ok = digest_index(db.get(), table, index, &a.index);
      a.table_ok = theirs.upto == 0 || digest_table(db.get(), table, theirs, &a.table, &a.error,
                                                    rows ? &a.rows : nullptr, their_room);
      return a;
    });
  }
  *table_ok = digest_table(db_.get(), table, mine, &from_table, table_error, rows, room);
  std::optional<Aside> a;
  if (aside.valid()) a = aside.get();
  bool index_ok = false;
  if (a && a->opened) {
    index_ok = a->index_ok;
    from_index = std::move(a->index);
    if (*table_ok && !a->table_ok) *table_error = a->error;
    *table_ok = *table_ok && a->table_ok;
    for (const auto& [stream, d] : a->table) from_table[stream].append(d);
    if (rows && *table_ok) {
      for (auto& [stream, later] : a->rows) {
        auto& samples = (*rows)[stream];
        samples.insert(samples.end(), later.begin(), later.end());
      }
    }
  } else {
    // No second connection: the rest of the table and the index here.
    if (*table_ok && theirs.upto != 0) {
      Digests later;
      *table_ok = digest_table(db_.get(), table, theirs, &later, table_error, rows, room);
      for (const auto& [stream, d] : later) from_table[stream].append(d);
    }
    index_ok = *table_ok && digest_index(db_.get(), table, index, &from_index);
  }
  if (!*table_ok || !index_ok || from_index != from_table) {
    if (rows) rows->clear();
    return false;
  }
  counts->clear();
  in_time_order->clear();
  for (const auto& [stream, d] : from_table) {
    (*counts)[stream] = d.count;
    if (d.in_time_order) in_time_order->insert(stream);
  }
  if (rows) {
    // Rows are in storage (rowid) order: a stable sort by time puts equal times in rowid order,
    // as the index does.
    for (auto& [stream, samples] : *rows) {
      if (in_time_order->contains(stream)) continue;
      std::stable_sort(samples.begin(), samples.end(),
                       [](const ImuSample& a, const ImuSample& b) { return a.t_ns < b.t_ns; });
    }
  }
  return true;
}

// Walks the IMU table in storage order (which needs no index) and checks the time index
// against it. Any error switches to serving samples from memory.
void SqliteSessionLogReader::scan_imu() {
  if (!tables_.contains("imu_samples")) return;
  bool table_ok = false;
  std::string table_error;
  if (index_agrees("imu_samples", "imu_samples_by_time", &imu_counts_, &imu_table_in_time_order_, &table_ok,
                   &table_error, options_.preload_imu ? &imu_preloaded_ : nullptr))
    return;
  // Load what the table yields, in storage order, and sort.
  imu_in_memory_ = true;
  std::int64_t loaded = 0, impossible = 0;
  const int skipped = scan_skipping_damage(
      "SELECT rowid, stream_id, t_ns, ax, ay, az, gx, gy, gz, temperature, flags FROM imu_samples "
      "WHERE rowid >= ?1 ORDER BY rowid",
      "imu_samples", [&](sqlite3_stmt* s) {
        if (!time_in_range(sqlite3_column_int64(s, 2))) {
          ++impossible;
          return;
        }
        imu_memory_[sqlite3_column_int(s, 1)].push_back(read_sample_columns(s, 2));
        ++loaded;
      });
  if (impossible > 0) {
    note_damage(std::to_string(impossible) +
                " IMU samples have timestamps beyond 2^62 ns, which no writer stores; they were left out");
  }
  if (table_ok) {
    if (impossible == 0)
      note_damage("the IMU time index is damaged (all " + std::to_string(loaded) +
                  " samples were read from the table instead)");
  } else {
    note_damage("IMU sample table damaged (" + table_error + "): " + std::to_string(loaded) +
                " samples readable, samples lost in " + std::to_string(std::max(skipped, 1)) +
                " place(s) (from the first damaged page to the next readable one)");
  }
}

void SqliteSessionLogReader::scan_frames() {
  if (!tables_.contains("frames")) return;
  bool table_ok = false;
  std::string table_error;
  std::set<int> in_time_order;  // frames are always read through the index: their rows are large
  if (index_agrees("frames", "frames_by_time", &frame_counts_, &in_time_order, &table_ok, &table_error))
    return;
  frames_in_memory_ = true;
  std::int64_t loaded = 0, impossible = 0;
  const int skipped = scan_skipping_damage(
      "SELECT rowid, stream_id, t_ns, width, height, encoding, exposure_ns, sequence, flags FROM frames "
      "WHERE rowid >= ?1 ORDER BY rowid",
      "frames", [&](sqlite3_stmt* s) {
        if (!time_in_range(sqlite3_column_int64(s, 2))) {
          ++impossible;
          return;
        }
        FrameRef ref;
        ref.rowid = sqlite3_column_int64(s, 0);
        ref.frame.t_ns = sqlite3_column_int64(s, 2);
        ref.frame.width = sqlite3_column_int(s, 3);
        ref.frame.height = sqlite3_column_int(s, 4);
        ref.frame.encoding = column_text(s, 5);
        ref.frame.exposure_ns = sqlite3_column_int64(s, 6);
        ref.frame.sequence = static_cast<std::uint32_t>(sqlite3_column_int64(s, 7));
        ref.frame.flags = static_cast<std::uint32_t>(sqlite3_column_int64(s, 8));
        frame_memory_[sqlite3_column_int(s, 1)].push_back(std::move(ref));
        ++loaded;
      });
  if (impossible > 0) {
    note_damage(std::to_string(impossible) +
                " frames have timestamps beyond 2^62 ns, which no writer stores; they were left out");
  }
  if (table_ok) {
    if (impossible == 0)
      note_damage("the frame time index is damaged (all " + std::to_string(loaded) +
                  " frames were read from the table instead)");
  } else {
    note_damage("frame table damaged (" + table_error + "): " + std::to_string(loaded) +
                " frames readable, frames lost in " + std::to_string(std::max(skipped, 1)) + " place(s)");
  }
}

void SqliteSessionLogReader::read_events() {
  if (!tables_.contains("events")) return;
  int rc = 0;
  Stmt stmt = sqlite::prepare(db_.get(), "SELECT t_ns, kind, message FROM events NOT INDEXED", &rc);
  while ((rc == SQLITE_OK || rc == SQLITE_ROW) && (rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    events_.push_back(
        {sqlite3_column_int64(stmt.get(), 0), column_text(stmt.get(), 1), column_text(stmt.get(), 2)});
  }
  if (rc != SQLITE_DONE) {
    note_damage("event table damaged (" + sqlite::errmsg(db_.get()) + "): " + std::to_string(events_.size()) +
                " events readable before the damage");
  }
  std::stable_sort(events_.begin(), events_.end(),
                   [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
}

// Sorts what was loaded into memory, so reads come in time order.
void SqliteSessionLogReader::apply_salvage() {
  if (imu_in_memory_) {
    imu_counts_.clear();
    for (auto& [id, samples] : imu_memory_) {
      std::stable_sort(samples.begin(), samples.end(),
                       [](const ImuSample& a, const ImuSample& b) { return a.t_ns < b.t_ns; });
      imu_counts_[id] = static_cast<std::int64_t>(samples.size());
    }
  }
  if (frames_in_memory_) {
    frame_counts_.clear();
    for (auto& [id, frames] : frame_memory_) {
      std::stable_sort(frames.begin(), frames.end(),
                       [](const FrameRef& a, const FrameRef& b) { return a.frame.t_ns < b.frame.t_ns; });
      frame_counts_[id] = static_cast<std::int64_t>(frames.size());
    }
  }
}

Status SqliteSessionLogReader::for_each_imu(int stream_id, TimeNs t0_ns, TimeNs t1_ns,
                                            const std::function<bool(const ImuSample&)>& visit) const {
  if (!imu_streams_.contains(stream_id)) {
    return make_error(Errc::kNotFound,
                      "session log " + path_ + " has no IMU stream with id " + std::to_string(stream_id));
  }
  if (t0_ns >= t1_ns) return {};
  const ImuRows& held = imu_in_memory_ ? imu_memory_ : imu_preloaded_;
  if (const auto it = held.find(stream_id); imu_in_memory_ || it != held.end()) {
    if (it == held.end()) return {};
    const auto& samples = it->second;
    auto first = std::lower_bound(samples.begin(), samples.end(), t0_ns,
                                  [](const ImuSample& s, TimeNs t) { return s.t_ns < t; });
    for (; first != samples.end() && first->t_ns < t1_ns; ++first) {
      if (!visit(*first)) break;
    }
    return {};
  }
  int rc = 0;
  // A whole stream whose rows are stored in time order is read in storage order: the same
  // samples in the same order (the index orders equal times by rowid too).
  const bool whole_in_order =
      t0_ns == kTimeMin && t1_ns == kTimeMax && imu_table_in_time_order_.contains(stream_id);
  Stmt stmt = sqlite::prepare(
      db_.get(),
      whole_in_order ? "SELECT t_ns, ax, ay, az, gx, gy, gz, temperature, flags FROM imu_samples "
                       "NOT INDEXED WHERE stream_id=?1 AND t_ns>=?2 AND t_ns<?3 ORDER BY rowid"
                     : "SELECT t_ns, ax, ay, az, gx, gy, gz, temperature, flags FROM imu_samples "
                       "WHERE stream_id=?1 AND t_ns>=?2 AND t_ns<?3 ORDER BY t_ns",
      &rc);
  if (rc != SQLITE_OK) return sql_error("cannot query IMU samples");
  sqlite3_bind_int(stmt.get(), 1, stream_id);
  sqlite3_bind_int64(stmt.get(), 2, t0_ns);
  sqlite3_bind_int64(stmt.get(), 3, t1_ns);
  while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    if (!visit(read_sample_columns(stmt.get(), 0))) return {};
  }
  if (rc != SQLITE_DONE) {
    note_damage("IMU samples unreadable while reading (" + sqlite::errmsg(db_.get()) + ")");
    return sql_error("IMU samples damaged");
  }
  return {};
}

Status SqliteSessionLogReader::for_each_frame(int stream_id, TimeNs t0_ns, TimeNs t1_ns,
                                              const std::function<bool(const CameraFrame&)>& visit) const {
  if (!camera_streams_.contains(stream_id)) {
    return make_error(Errc::kNotFound,
                      "session log " + path_ + " has no camera stream with id " + std::to_string(stream_id));
  }
  if (t0_ns >= t1_ns) return {};
  int rc = 0;
  if (frames_in_memory_) {
    const auto it = frame_memory_.find(stream_id);
    if (it == frame_memory_.end()) return {};
    Stmt stmt = sqlite::prepare(db_.get(), "SELECT data, data_crc32 FROM frames WHERE rowid=?1", &rc);
    if (rc != SQLITE_OK) return sql_error("cannot query frames");
    const auto& frames = it->second;
    auto first = std::lower_bound(frames.begin(), frames.end(), t0_ns,
                                  [](const FrameRef& f, TimeNs t) { return f.frame.t_ns < t; });
    for (; first != frames.end() && first->frame.t_ns < t1_ns; ++first) {
      CameraFrame frame = first->frame;
      if (!first->has_data) {
        sqlite3_reset(stmt.get());
        sqlite3_bind_int64(stmt.get(), 1, first->rowid);
        if (sqlite3_step(stmt.get()) != SQLITE_ROW) {
          note_damage("image data of the frame at t_ns=" + std::to_string(frame.t_ns) + " is unreadable (" +
                      sqlite::errmsg(db_.get()) + ")");
          continue;
        }
        if (!load_frame_data(stmt.get(), 0, &frame)) continue;
      }
      if (!visit(frame)) break;
    }
    return {};
  }
  Stmt stmt = sqlite::prepare(
      db_.get(),
      "SELECT t_ns, width, height, encoding, exposure_ns, sequence, flags, data, data_crc32 FROM frames "
      "WHERE stream_id=?1 AND t_ns>=?2 AND t_ns<?3 ORDER BY t_ns",
      &rc);
  if (rc != SQLITE_OK) return sql_error("cannot query frames");
  sqlite3_bind_int(stmt.get(), 1, stream_id);
  sqlite3_bind_int64(stmt.get(), 2, t0_ns);
  sqlite3_bind_int64(stmt.get(), 3, t1_ns);
  while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    sqlite3_stmt* s = stmt.get();
    CameraFrame frame;
    frame.t_ns = sqlite3_column_int64(s, 0);
    frame.width = sqlite3_column_int(s, 1);
    frame.height = sqlite3_column_int(s, 2);
    frame.encoding = column_text(s, 3);
    frame.exposure_ns = sqlite3_column_int64(s, 4);
    frame.sequence = static_cast<std::uint32_t>(sqlite3_column_int64(s, 5));
    frame.flags = static_cast<std::uint32_t>(sqlite3_column_int64(s, 6));
    if (!load_frame_data(s, 7, &frame)) continue;
    if (!visit(frame)) return {};
  }
  if (rc != SQLITE_DONE) {
    note_damage("frames unreadable while reading (" + sqlite::errmsg(db_.get()) + ")");
    return sql_error("frames damaged");
  }
  return {};
}

Result<std::vector<TimeNs>> SqliteSessionLogReader::frame_times(int stream_id) const {
  if (!camera_streams_.contains(stream_id)) {
    return make_error(Errc::kNotFound,
                      "session log " + path_ + " has no camera stream with id " + std::to_string(stream_id));
  }
  std::vector<TimeNs> times;
  if (frames_in_memory_) {
    const auto it = frame_memory_.find(stream_id);
    if (it != frame_memory_.end()) {
      for (const auto& ref : it->second) times.push_back(ref.frame.t_ns);
    }
    return times;
  }
  int rc = 0;
  Stmt stmt = sqlite::prepare(db_.get(), "SELECT t_ns FROM frames WHERE stream_id=?1 ORDER BY t_ns", &rc);
  if (rc != SQLITE_OK) return sql_error("cannot query frames");
  sqlite3_bind_int(stmt.get(), 1, stream_id);
  while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) times.push_back(sqlite3_column_int64(stmt.get(), 0));
  if (rc != SQLITE_DONE) return sql_error("frame times damaged");
  return times;
}

Result<std::uint64_t> SqliteSessionLogReader::frame_fingerprint(int stream_id) const {
  if (!camera_streams_.contains(stream_id)) {
    return make_error(Errc::kNotFound,
                      "session log " + path_ + " has no camera stream with id " + std::to_string(stream_id));
  }
  int rc = 0;
  Stmt stmt = sqlite::prepare(
      db_.get(),
      "SELECT t_ns, width, height, encoding, data_crc32 FROM frames WHERE stream_id=?1 ORDER BY t_ns", &rc);
  if (rc != SQLITE_OK) return sql_error("cannot query frames");
  sqlite3_bind_int(stmt.get(), 1, stream_id);
  std::uint64_t hash = 14695981039346656037ull;  // FNV-1a 64
  auto mix = [&hash](const void* data, std::size_t size) {
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    for (std::size_t i = 0; i < size; ++i) hash = (hash ^ bytes[i]) * 1099511628211ull;
  };
  while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
    sqlite3_stmt* s = stmt.get();
    const std::int64_t fields[4] = {sqlite3_column_int64(s, 0), sqlite3_column_int64(s, 1),
                                    sqlite3_column_int64(s, 2), sqlite3_column_int64(s, 4)};
    mix(fields, sizeof fields);
    const std::string encoding = column_text(s, 3);
    mix(encoding.data(), encoding.size() + 1);
  }
  if (rc != SQLITE_DONE) return sql_error("frames damaged");
  return hash;
}

Result<std::int64_t> SqliteSessionLogReader::imu_count(int stream_id) const {
  if (!imu_streams_.contains(stream_id)) {
    return make_error(Errc::kNotFound,
                      "session log " + path_ + " has no IMU stream with id " + std::to_string(stream_id));
  }
  const auto it = imu_counts_.find(stream_id);
  return it == imu_counts_.end() ? std::int64_t{0} : it->second;
}

Result<std::int64_t> SqliteSessionLogReader::frame_count(int stream_id) const {
  if (!camera_streams_.contains(stream_id)) {
    return make_error(Errc::kNotFound,
                      "session log " + path_ + " has no camera stream with id " + std::to_string(stream_id));
  }
  const auto it = frame_counts_.find(stream_id);
  return it == frame_counts_.end() ? std::int64_t{0} : it->second;
}

Result<std::vector<ImuSample>> SqliteSessionLogReader::take_imu(int stream_id) {
  const auto it = imu_preloaded_.find(stream_id);
  if (it == imu_preloaded_.end()) return read_imu(stream_id);
  std::vector<ImuSample> samples = std::move(it->second);
  imu_preloaded_.erase(it);
  return samples;
}

}  // namespace

Result<std::unique_ptr<SessionLogReader>> SessionLogReader::open(const std::string& path,
                                                                 const SessionLogReaderOptions& options) {
  auto reader = std::make_unique<SqliteSessionLogReader>(path, options);
  IMUCAL_TRY(reader->open());
  return std::unique_ptr<SessionLogReader>(std::move(reader));
}

}  // namespace imucal::log
