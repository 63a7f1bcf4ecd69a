// SPDX-License-Identifier: BSD-3-Clause
// The session log on SQLite, its writer: SessionLogWriter::create, the writer's file lock.
// Schema and guarantees: docs/session-log.md.

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <set>
#include <sstream>
#include <system_error>
#include <utility>

#include "core/text_format.hpp"
#include "core/version.hpp"
#include "log/dataset_io.hpp"
#include "log/session_log.hpp"
#include "log/session_log_sqlite.hpp"

namespace imucal::log {
namespace {

using sqlite::Stmt;
using namespace sqlite;  // the row helpers, metadata keys and OpenHere

/// flock(LOCK_EX | LOCK_NB), tried for up to about 20 ms: a reader that tests for a writer holds
/// a shared lock for an instant (being_written). -1 with errno set when it cannot be had.
int lock_exclusive(int fd) {
  for (int attempt = 0;; ++attempt) {
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) return 0;
    if (errno != EWOULDBLOCK || attempt == 20) return -1;
    ::usleep(1000);
  }
}

/// The writer's exclusive flock(2) on the log file, held from before the file has content until
/// after SQLite closed it. flock locks are apart from the POSIX record locks SQLite takes, but
/// closing any descriptor of the file drops the process's POSIX locks: the descriptor is closed
/// only after SQLite has closed its own.
class WriterLock {
 public:
  WriterLock() = default;
  explicit WriterLock(int fd) : fd_(fd) {
    struct stat st {};
    if (::fstat(fd, &st) == 0) open_here_ = OpenHere(st);
  }
  WriterLock(WriterLock&& o) noexcept : fd_(std::exchange(o.fd_, -1)), open_here_(std::move(o.open_here_)) {}
  WriterLock& operator=(WriterLock&& o) noexcept {
    std::swap(fd_, o.fd_);
    std::swap(open_here_, o.open_here_);
    return *this;
  }
  ~WriterLock() {
    if (fd_ >= 0) ::close(fd_);
  }

 private:
  int fd_ = -1;
  OpenHere open_here_;
};

}  // namespace

long sqlite::flock_holder(dev_t dev, ino_t ino) {
  char want[64];
  std::snprintf(want, sizeof want, "%02x:%02x:%llu", major(dev), minor(dev),
                static_cast<unsigned long long>(ino));
  std::ifstream locks("/proc/locks");
  std::string line;
  while (std::getline(locks, line)) {
    // "1: FLOCK  ADVISORY  WRITE 12345 08:01:654321 0 EOF"
    std::istringstream in(line);
    std::string n, type, mode, access, dev_ino;
    long pid = 0;
    if (in >> n >> type >> mode >> access >> pid >> dev_ino && type == "FLOCK" && dev_ino == want) return pid;
  }
  return 0;
}

namespace {

std::string held_by(int fd) {
  struct stat st {};
  const long pid = ::fstat(fd, &st) == 0 ? flock_holder(st.st_dev, st.st_ino) : 0;
  if (pid <= 0) return "another process";
  std::string comm;
  std::ifstream(std::string("/proc/") + std::to_string(pid) + "/comm") >> comm;
  return "process " + std::to_string(pid) + (comm.empty() ? "" : " (" + comm + ")");
}

/// Takes the writer's lock on the file at `path`: created here (O_EXCL) unless `overwrite`; an
/// existing file is replaced only when no other writer holds it.
Result<WriterLock> lock_for_writing(const std::string& path, bool overwrite) {
  if (overwrite) {
    const int old = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (old >= 0) {
      WriterLock guard(old);
      if (lock_exclusive(old) != 0 && errno == EWOULDBLOCK) {
        return make_error(Errc::kIo, "session log " + path + " is being written by " + held_by(old) +
                                         "; stop that recording first, or write to another file");
      }
    }
    for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
      const std::string victim = path + suffix;
      if (std::remove(victim.c_str()) != 0 && errno != ENOENT) {
        return make_error(Errc::kIo, "cannot replace " + victim + ": " + std::strerror(errno));
      }
    }
  }
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    if (errno == EEXIST) return make_error(Errc::kAlreadyExists, "session log " + path + " already exists");
    return make_error(Errc::kIo, "cannot create session log " + path + ": " + std::strerror(errno) +
                                     " (check that the directory exists and is writable)");
  }
  WriterLock lock(fd);
  // Nobody else can hold a lock on a file this call created; a failure here is the filesystem's.
  if (lock_exclusive(fd) != 0) {
    const int err = errno;
    std::remove(path.c_str());
    return make_error(Errc::kIo, "cannot lock session log " + path + ": " + std::strerror(err));
  }
  return lock;
}

class SqliteSessionLogWriter final : public SessionLogWriter {
 public:
  SqliteSessionLogWriter(std::string path, SessionLogWriterOptions options, sqlite::Db db, WriterLock lock)
      : path_(std::move(path)), options_(options), db_(std::move(db)), lock_(std::move(lock)) {}

  ~SqliteSessionLogWriter() override {
    if (closed_) return;
    // Keep what was appended; the log stays marked incomplete.
    if (in_txn_) (void)commit();
    (void)release();
  }

  Status init() {
    static constexpr const char* kSetup =
        "PRAGMA journal_mode=WAL;"
        "PRAGMA synchronous=FULL;"
        "PRAGMA wal_autocheckpoint=4096;";
    // A staged file has no readers and is discarded on failure: no journal, no syncs until close().
    static constexpr const char* kStagedSetup =
        "PRAGMA journal_mode=OFF;"
        "PRAGMA synchronous=OFF;";
    if (sqlite::exec(db_.get(), options_.staged ? kStagedSetup : kSetup) != SQLITE_OK)
      return sql_error("configure");
    const std::string header = "PRAGMA application_id=" + std::to_string(sqlite::kApplicationId) +
                               ";PRAGMA user_version=" + std::to_string(kSessionLogSchemaVersion) + ";";
    if (sqlite::exec(db_.get(), "BEGIN") != SQLITE_OK) return sql_error("begin");
    if (sqlite::exec(db_.get(), header.c_str()) != SQLITE_OK) return sql_error("write header");
    if (sqlite::exec(db_.get(), sqlite::kSchemaSql) != SQLITE_OK) return sql_error("create schema");
    IMUCAL_TRY(prepare_statements());
    IMUCAL_TRY(put_metadata(kKeySchemaVersion, std::to_string(kSessionLogSchemaVersion)));
    IMUCAL_TRY(put_metadata(kKeySoftwareVersion, kVersion));
    IMUCAL_TRY(put_metadata(kKeyCreatedUtc, utc_now_iso8601()));
    IMUCAL_TRY(put_metadata(kKeyComplete, "0"));
    if (sqlite::exec(db_.get(), "COMMIT") != SQLITE_OK) return sql_error("commit schema");
    return {};
  }

  Status set_metadata(const std::string& key, const std::string& value) override {
    IMUCAL_TRY(check_usable());
    if (key.empty()) return make_error(Errc::kInvalidArgument, "session log metadata key is empty");
    if (key == kKeySchemaVersion || key == kKeySoftwareVersion || key == kKeyCreatedUtc ||
        key == kKeyComplete) {
      return make_error(Errc::kInvalidArgument,
                        "session log metadata key '" + key + "' is set by the writer itself");
    }
    IMUCAL_TRY(begin_if_needed());
    IMUCAL_TRY(put_metadata(key, value));
    return maybe_commit();
  }

  Result<int> add_imu_stream(const ImuStreamInfo& info) override {
    IMUCAL_TRY(check_usable());
    IMUCAL_TRY(check_new_name(info.name, imu_names_, "IMU"));
    if (!(info.rate_hz >= 0.0) || !std::isfinite(info.rate_hz)) {
      return make_error(Errc::kInvalidArgument,
                        "IMU stream '" + info.name + "': rate_hz must be >= 0 and finite");
    }
    int rc = 0;
    Stmt stmt =
        sqlite::prepare(db_.get(),
                        "INSERT INTO imu_streams VALUES(?1,?2,?3,?4,?5,?6,?7,?8,?9,?10,?11,?12,?13,?14,"
                        "?15,?16,?17,?18,?19,?20,?21,?22)",
                        &rc);
    if (rc != SQLITE_OK) return sql_error("prepare stream insert");
    const int id = next_stream_id_;
    sqlite3_stmt* s = stmt.get();
    sqlite3_bind_int(s, 1, id);
    bind_text(s, 2, info.name);
    bind_text(s, 3, imu_units_name(info.units));
    sqlite3_bind_double(s, 4, info.rate_hz);
    int col = 5;
    for (const AxisConversion* conv : {&info.accel, &info.gyro}) {
      for (int i = 0; i < 3; ++i) sqlite3_bind_double(s, col++, conv->scale[i]);
      for (int i = 0; i < 3; ++i) sqlite3_bind_double(s, col++, conv->offset[i]);
    }
    sqlite3_bind_double(s, 17, info.temperature_scale);
    sqlite3_bind_double(s, 18, info.temperature_offset);
    sqlite3_bind_int(s, 19, info.accel_full_scale_g);
    sqlite3_bind_int(s, 20, info.gyro_full_scale_dps);
    sqlite3_bind_int(s, 21, info.dlpf_hz);
    bind_text(s, 22, info.device);
    IMUCAL_TRY(begin_if_needed());
    if (sqlite3_step(s) != SQLITE_DONE) return fail_with("add IMU stream '" + info.name + "'");
    ++next_stream_id_;
    imu_units_[id] = info.units;
    imu_names_.insert(info.name);
    IMUCAL_TRY(maybe_commit());
    return id;
  }

  Result<int> add_camera_stream(const CameraStreamInfo& info) override {
    IMUCAL_TRY(check_usable());
    IMUCAL_TRY(check_new_name(info.name, camera_names_, "camera"));
    int rc = 0;
    Stmt stmt = sqlite::prepare(db_.get(), "INSERT INTO camera_streams VALUES(?1,?2,?3,?4,?5,?6,?7,?8)", &rc);
    if (rc != SQLITE_OK) return sql_error("prepare stream insert");
    const int id = next_stream_id_;
    sqlite3_stmt* s = stmt.get();
    sqlite3_bind_int(s, 1, id);
    bind_text(s, 2, info.name);
    sqlite3_bind_int(s, 3, info.width);
    sqlite3_bind_int(s, 4, info.height);
    sqlite3_bind_double(s, 5, info.rate_hz);
    bind_text(s, 6, info.backend);
    bind_text(s, 7, info.device);
    bind_text(s, 8, info.timestamp_source);
    IMUCAL_TRY(begin_if_needed());
    if (sqlite3_step(s) != SQLITE_DONE) return fail_with("add camera stream '" + info.name + "'");
    ++next_stream_id_;
    camera_ids_.insert(id);
    camera_names_.insert(info.name);
    IMUCAL_TRY(maybe_commit());
    return id;
  }

  Status append_imu(int stream_id, std::span<const ImuSample> samples) override {
    IMUCAL_TRY(check_usable());
    const auto it = imu_units_.find(stream_id);
    if (it == imu_units_.end()) {
      return make_error(Errc::kInvalidArgument,
                        "append_imu: no IMU stream with id " + std::to_string(stream_id) + " in this log");
    }
    const bool raw = it->second == ImuUnits::kRaw;
    for (const ImuSample& sample : samples) IMUCAL_TRY(check_time("append_imu", sample.t_ns));
    IMUCAL_TRY(begin_if_needed());
    // Whole runs of kImuRowsPerInsert samples go in one statement (one execution of the insert
    // program instead of one per sample), the rest one by one.
    std::size_t done = 0;
    while (done < samples.size()) {
      const bool many = samples.size() - done >= kImuRowsPerInsert;
      sqlite3_stmt* s = many ? insert_imu_many_.get() : insert_imu_.get();
      const std::size_t rows = many ? kImuRowsPerInsert : 1;
      for (std::size_t r = 0; r < rows; ++r) {
        const ImuSample& sample = samples[done + r];
        const int p = static_cast<int>(10 * r);
        sqlite3_bind_int(s, p + 1, stream_id);
        sqlite3_bind_int64(s, p + 2, sample.t_ns);
        for (int i = 0; i < 3; ++i) bind_value(s, p + 3 + i, sample.accel[i], raw);
        for (int i = 0; i < 3; ++i) bind_value(s, p + 6 + i, sample.gyro[i], raw);
        bind_value(s, p + 9, sample.temperature, raw);
        sqlite3_bind_int64(s, p + 10, sample.flags);
      }
      const int rc = sqlite3_step(s);
      sqlite3_reset(s);
      if (rc != SQLITE_DONE) return fail_with("append IMU samples");
      done += rows;
    }
    if (!samples.empty()) note_data_time(samples.front().t_ns, samples.back().t_ns);
    return maybe_commit();
  }

  Status append_frame(int stream_id, const CameraFrame& frame) override {
    IMUCAL_TRY(check_usable());
    if (!camera_ids_.contains(stream_id)) {
      return make_error(Errc::kInvalidArgument, "append_frame: no camera stream with id " +
                                                    std::to_string(stream_id) + " in this log");
    }
    if (frame.data.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
      return make_error(Errc::kInvalidArgument, "append_frame: frame data larger than 2 GiB");
    }
    IMUCAL_TRY(check_time("append_frame", frame.t_ns));
    IMUCAL_TRY(begin_if_needed());
    sqlite3_stmt* s = insert_frame_.get();
    sqlite3_bind_int(s, 1, stream_id);
    sqlite3_bind_int64(s, 2, frame.t_ns);
    sqlite3_bind_int(s, 3, frame.width);
    sqlite3_bind_int(s, 4, frame.height);
    bind_text(s, 5, frame.encoding);
    sqlite3_bind_int64(s, 6, frame.exposure_ns);
    sqlite3_bind_int64(s, 7, frame.sequence);
    sqlite3_bind_int64(s, 8, frame.flags);
    // A zero-length blob still has to be a BLOB, not NULL.
    static constexpr std::uint8_t kEmpty = 0;
    sqlite3_bind_blob(s, 9, frame.data.empty() ? &kEmpty : frame.data.data(),
                      static_cast<int>(frame.data.size()), SQLITE_STATIC);
    sqlite3_bind_int64(s, 10, sqlite::crc32(frame.data.data(), frame.data.size()));
    const int rc = sqlite3_step(s);
    sqlite3_reset(s);
    sqlite3_clear_bindings(s);
    if (rc != SQLITE_DONE) return fail_with("append frame");
    return maybe_commit();
  }

  Status append_event(const Event& event) override {
    IMUCAL_TRY(check_usable());
    IMUCAL_TRY(check_time("append_event", event.t_ns));
    IMUCAL_TRY(begin_if_needed());
    sqlite3_stmt* s = insert_event_.get();
    sqlite3_bind_int64(s, 1, event.t_ns);
    bind_text(s, 2, event.kind);
    bind_text(s, 3, event.message);
    const int rc = sqlite3_step(s);
    sqlite3_reset(s);
    if (rc != SQLITE_DONE) return fail_with("append event");
    return maybe_commit();
  }

  Status flush() override {
    IMUCAL_TRY(check_usable());
    return in_txn_ ? commit() : Status{};
  }

  Status close() override {
    IMUCAL_TRY(check_usable());
    if (options_.staged) {
      // The last commit syncs the file, with all that went before it.
      if (in_txn_) IMUCAL_TRY(commit());
      if (sqlite::exec(db_.get(), "PRAGMA synchronous=FULL") != SQLITE_OK) return fail_with("configure");
    }
    IMUCAL_TRY(begin_if_needed());
    IMUCAL_TRY(put_metadata(kKeyComplete, "1"));
    IMUCAL_TRY(commit());
    // Move everything into the main file. Switching back to a rollback journal leaves a
    // single self-contained file that opens read-only even where no -shm can be created; it
    // fails harmlessly (the log stays in WAL mode) while another process has the log open.
    // A reader in a read transaction keeps the checkpoint from finishing (SQLITE_BUSY): every
    // commit is durable in the -wal already and the next opener moves it in, so the log is
    // complete and closed as it is.
    const int ckpt =
        sqlite3_wal_checkpoint_v2(db_.get(), nullptr, SQLITE_CHECKPOINT_TRUNCATE, nullptr, nullptr);
    if (ckpt != SQLITE_OK && ckpt != SQLITE_BUSY && ckpt != SQLITE_LOCKED) return fail_with("checkpoint");
    if (ckpt == SQLITE_OK) (void)sqlite::exec(db_.get(), "PRAGMA journal_mode=DELETE");
    closed_ = true;
    return release();
  }

 private:
  Status prepare_statements() {
    int rc = 0;
    insert_imu_ =
        sqlite::prepare(db_.get(), "INSERT INTO imu_samples VALUES(?1,?2,?3,?4,?5,?6,?7,?8,?9,?10)", &rc);
    if (rc != SQLITE_OK) return sql_error("prepare");
    std::string many = "INSERT INTO imu_samples VALUES(?,?,?,?,?,?,?,?,?,?)";
    for (std::size_t r = 1; r < kImuRowsPerInsert; ++r) many += ",(?,?,?,?,?,?,?,?,?,?)";
    insert_imu_many_ = sqlite::prepare(db_.get(), many.c_str(), &rc);
    if (rc != SQLITE_OK) return sql_error("prepare");
    insert_frame_ =
        sqlite::prepare(db_.get(), "INSERT INTO frames VALUES(?1,?2,?3,?4,?5,?6,?7,?8,?9,?10)", &rc);
    if (rc != SQLITE_OK) return sql_error("prepare");
    insert_event_ = sqlite::prepare(db_.get(), "INSERT INTO events VALUES(?1,?2,?3)", &rc);
    if (rc != SQLITE_OK) return sql_error("prepare");
    set_metadata_ = sqlite::prepare(db_.get(), "INSERT OR REPLACE INTO metadata VALUES(?1,?2)", &rc);
    if (rc != SQLITE_OK) return sql_error("prepare");
    return {};
  }

  Status put_metadata(const std::string& key, const std::string& value) {
    sqlite3_stmt* s = set_metadata_.get();
    bind_text(s, 1, key);
    bind_text(s, 2, value);
    const int rc = sqlite3_step(s);
    sqlite3_reset(s);
    if (rc != SQLITE_DONE) return fail_with("write metadata '" + key + "'");
    return {};
  }

  Status check_usable() const {
    if (closed_) return make_error(Errc::kInvalidArgument, "session log " + path_ + " is already closed");
    if (failed_) return *failed_;
    return {};
  }

  static Status check_new_name(const std::string& name, const std::set<std::string>& names,
                               const char* kind) {
    if (name.empty()) return make_error(Errc::kInvalidArgument, std::string(kind) + " stream name is empty");
    if (names.contains(name)) {
      return make_error(Errc::kInvalidArgument, std::string(kind) + " stream '" + name +
                                                    "' already exists in this log; use another name");
    }
    return {};
  }

  Status begin_if_needed() {
    if (in_txn_) return {};
    if (sqlite::exec(db_.get(), "BEGIN") != SQLITE_OK) return fail_with("begin transaction");
    in_txn_ = true;
    txn_start_ns_ = monotonic_now_ns();
    return {};
  }

  static Status check_time(const char* what, TimeNs t_ns) {
    if (time_in_range(t_ns)) return {};
    return make_error(Errc::kInvalidArgument, std::string(what) + ": t_ns=" + std::to_string(t_ns) +
                                                  " is beyond 146 years from the clock's zero (2^62 ns)");
  }

  // The span of sample time the open transaction holds (for commit_data_interval_ns).
  void note_data_time(TimeNs first, TimeNs last) {
    if (!txn_has_data_) {
      txn_data_start_ns_ = first;
      txn_has_data_ = true;
    }
    txn_data_end_ns_ = std::max(txn_data_end_ns_, last);
  }

  Status maybe_commit() {
    if (!in_txn_) return {};
    // The first samples commit at once with what was declared before them: a log killed in its
    // first interval (22,000 samples at time-scale 0) keeps its streams and samples.
    if (txn_has_data_ && !data_committed_ && !options_.staged && options_.commit_data_interval_ns > 0) {
      data_committed_ = true;
      return commit();
    }
    if (monotonic_now_ns() - txn_start_ns_ >= options_.commit_interval_ns) return commit();
    if (options_.commit_data_interval_ns > 0 && txn_has_data_ &&
        txn_data_end_ns_ - txn_data_start_ns_ >= options_.commit_data_interval_ns)
      return commit();
    return {};
  }

  Status commit() {
    if (sqlite::exec(db_.get(), "COMMIT") != SQLITE_OK) return fail_with("commit");
    in_txn_ = false;
    txn_has_data_ = false;
    txn_data_end_ns_ = kTimeMin;
    return {};
  }

  Error sql_error(const std::string& what) const {
    const int rc = sqlite3_extended_errcode(db_.get());
    const Errc code = (rc & 0xff) == SQLITE_FULL || (rc & 0xff) == SQLITE_IOERR ? Errc::kIo : Errc::kInternal;
    std::string message = "session log " + path_ + ": " + what + " failed: " + sqlite::errmsg(db_.get());
    if ((rc & 0xff) == SQLITE_FULL) message += " (the disk is full: free space and record again)";
    return make_error(code, message);
  }

  // A failed write leaves the transaction in an unknown state: every later call reports it.
  Error fail_with(const std::string& what) {
    Error error = sql_error(what);
    failed_ = error;
    return error;
  }

  Status release() {
    insert_imu_.reset();
    insert_imu_many_.reset();
    insert_frame_.reset();
    insert_event_.reset();
    set_metadata_.reset();
    sqlite3* db = db_.release();
    if (sqlite3_close(db) != SQLITE_OK) {
      const std::string message = sqlite::errmsg(db);
      sqlite3_close_v2(db);
      lock_ = WriterLock{};
      return make_error(Errc::kIo, "session log " + path_ + ": close failed: " + message);
    }
    lock_ = WriterLock{};  // SQLite has closed the file: another writer may have it now
    return {};
  }

  std::string path_;
  SessionLogWriterOptions options_;
  sqlite::Db db_;
  WriterLock lock_;  // declared after db_: released after SQLite closed the file
  static constexpr std::size_t kImuRowsPerInsert = 32;
  Stmt insert_imu_, insert_imu_many_, insert_frame_, insert_event_, set_metadata_;
  std::map<int, ImuUnits> imu_units_;
  std::set<int> camera_ids_;
  std::set<std::string> imu_names_, camera_names_;
  int next_stream_id_ = 1;
  bool in_txn_ = false;
  TimeNs txn_start_ns_ = 0;
  bool txn_has_data_ = false;
  bool data_committed_ = false;  // a transaction holding IMU samples was committed
  TimeNs txn_data_start_ns_ = 0, txn_data_end_ns_ = kTimeMin;
  bool closed_ = false;
  std::optional<Error> failed_;
};

}  // namespace

std::string sqlite::lock_holder(int fd) { return held_by(fd); }

Result<std::unique_ptr<SessionLogWriter>> SessionLogWriter::create(const std::string& path,
                                                                   const SessionLogWriterOptions& options) {
  namespace fs = std::filesystem;
  if (path.empty()) return make_error(Errc::kInvalidArgument, "session log path is empty");
  if (options.commit_interval_ns < 0) {
    return make_error(Errc::kInvalidArgument, "session log commit_interval_ns must be >= 0");
  }
  std::error_code ec;
  const auto status = fs::symlink_status(path, ec);
  if (fs::exists(status)) {
    if (!options.overwrite) {
      return make_error(Errc::kAlreadyExists, "session log " + path + " already exists");
    }
    if (fs::is_directory(status)) {
      return make_error(Errc::kInvalidArgument, "session log path " + path + " is a directory");
    }
    IMUCAL_TRY(check_replaceable(path));
  }
  auto lock = lock_for_writing(path, options.overwrite);
  if (!lock.ok()) return lock.error();
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &raw,
                                 SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  sqlite::Db db(raw);
  if (rc != SQLITE_OK) {
    return make_error(Errc::kIo, "cannot create session log " + path + ": " + sqlite::errmsg(raw) +
                                     " (check that the directory exists and is writable)");
  }
  auto writer = std::make_unique<SqliteSessionLogWriter>(path, options, std::move(db), std::move(*lock));
  if (auto init = writer->init(); !init.ok()) {
    writer.reset();
    for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
    return init.error();
  }
  return std::unique_ptr<SessionLogWriter>(std::move(writer));
}

}  // namespace imucal::log
