// The session log on SQLite: SessionLogWriter::create and SessionLogReader::open.
// Schema and guarantees: docs/session-log.md.

#include "log/session_log_sqlite.hpp"

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
namespace {

using sqlite::Stmt;

// Reserved metadata keys, set by the writer only.
constexpr const char* kKeySchemaVersion = "schema_version";
constexpr const char* kKeySoftwareVersion = "software_version";
constexpr const char* kKeyCreatedUtc = "created_utc";
constexpr const char* kKeyComplete = "complete";

// Binds one sample value: NaN as NULL; in raw streams an integral value as INTEGER (exact up
// to 2^53); everything else as REAL (an exact double round trip).
void bind_value(sqlite3_stmt* stmt, int index, double value, bool raw) {
  constexpr double kExactIntLimit = 9007199254740992.0;  // 2^53
  if (std::isnan(value)) {
    sqlite3_bind_null(stmt, index);
  } else if (raw && std::trunc(value) == value && std::fabs(value) <= kExactIntLimit) {
    sqlite3_bind_int64(stmt, index, static_cast<sqlite3_int64>(value));
  } else {
    sqlite3_bind_double(stmt, index, value);
  }
}

double column_value(sqlite3_stmt* stmt, int index) {
  if (sqlite3_column_type(stmt, index) == SQLITE_NULL) return std::numeric_limits<double>::quiet_NaN();
  return sqlite3_column_double(stmt, index);
}

std::string column_text(sqlite3_stmt* stmt, int index) {
  const auto* text = sqlite3_column_text(stmt, index);
  return text ? std::string(reinterpret_cast<const char*>(text)) : std::string();
}

void bind_text(sqlite3_stmt* stmt, int index, const std::string& text) {
  sqlite3_bind_text(stmt, index, text.data(), static_cast<int>(text.size()), SQLITE_TRANSIENT);
}

ImuSample read_sample_columns(sqlite3_stmt* stmt, int first) {
  ImuSample s;
  s.t_ns = sqlite3_column_int64(stmt, first);
  s.accel = {column_value(stmt, first + 1), column_value(stmt, first + 2), column_value(stmt, first + 3)};
  s.gyro = {column_value(stmt, first + 4), column_value(stmt, first + 5), column_value(stmt, first + 6)};
  s.temperature = column_value(stmt, first + 7);
  s.flags = static_cast<std::uint32_t>(sqlite3_column_int64(stmt, first + 8));
  return s;
}

// ------------------------------------------------------------------------------------------
// Writer

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

/// The process that holds a flock on the file with this device and inode (from /proc/locks), or
/// 0 when none is listed. Read without opening the file: closing a descriptor of a file drops
/// every POSIX lock this process holds on it, SQLite's included.
long flock_holder(dev_t dev, ino_t ino) {
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

// ------------------------------------------------------------------------------------------
// Reader

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

// Checks the file before SQLite sees it, so that the common mistakes get a precise message.
Status precheck_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT)
      return make_error(Errc::kNotFound, "no such session log: " + path + " (check the path)");
    return make_error(Errc::kNotFound, "cannot access session log " + path + ": " + std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) {
    return make_error(Errc::kNotFound, path + " is a directory, not a session log (.imulog file)");
  }
  if (!S_ISREG(st.st_mode)) {
    // A FIFO or a device would block the open below or read without end.
    return make_error(Errc::kNotFound, path + " is not a regular file, not a session log (.imulog file)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return make_error(Errc::kNotFound, "cannot read session log " + path + ": " + std::strerror(errno));
  char header[16] = {};
  in.read(header, sizeof header);
  const auto got = static_cast<std::size_t>(in.gcount());
  static constexpr char kMagic[16] = {'S', 'Q', 'L', 'i', 't', 'e', ' ', 'f',
                                      'o', 'r', 'm', 'a', 't', ' ', '3', '\0'};
  if (st.st_size == 0) {
    return make_error(Errc::kCorrupt, path +
                                          " is empty (0 bytes): the recording was lost before its first "
                                          "commit; record the session again");
  }
  if (got < sizeof header || std::memcmp(header, kMagic, sizeof kMagic) != 0) {
    if (std::memcmp(header, kMagic, got) == 0 && got < sizeof header) {
      return make_error(Errc::kCorrupt, path + " is truncated to " + std::to_string(st.st_size) +
                                            " bytes; nothing is readable");
    }
    return make_error(Errc::kCorrupt, path +
                                          " is not a session log (not an SQLite database); pass an .imulog "
                                          "file written by 'imucal record' or the imucal daemon");
  }
  if (st.st_size < 512) {
    return make_error(Errc::kCorrupt, path + " is truncated to " + std::to_string(st.st_size) +
                                          " bytes; nothing is readable");
  }
  return {};
}

// The page count in the file header against the file size: a copy that stopped early, or a
// file cut by a full disk, is shorter than its header says.
std::string truncation_of(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char h[100] = {};
  in.read(reinterpret_cast<char*>(h), sizeof h);
  if (in.gcount() != sizeof h) return {};
  const auto be32 = [&](int at) {
    return (std::uint32_t{h[at]} << 24) | (std::uint32_t{h[at + 1]} << 16) | (std::uint32_t{h[at + 2]} << 8) |
           h[at + 3];
  };
  std::uint64_t page_size = (std::uint64_t{h[16]} << 8) | h[17];
  if (page_size == 1) page_size = 65536;
  // The header page count is valid only when it was written by the same change as the counter.
  if (be32(24) != be32(92)) return {};
  const std::uint64_t expected = page_size * be32(28);
  std::error_code ec;
  const std::uint64_t actual = std::filesystem::file_size(path, ec);
  if (ec || actual >= expected) return {};
  return "the file is truncated: " + std::to_string(actual) + " of " + std::to_string(expected) +
         " bytes present, the rest is lost";
}

/// What the write-ahead log beside a log says about commits SQLite will not replay. SQLite
/// replays the -wal up to its first frame that fails the checksum chain and silently ignores
/// the rest; frames of the same generation (same salts) after that point that end a transaction
/// were committed and are lost. Only called when no writer holds the log (a live -wal grows).
struct WalCheck {
  bool present = false;
  std::string damage;             // committed frames that will not be replayed; empty when none
  bool torn_tail = false;         // the file ends inside a frame, or in frames no commit ends
  bool commits_replayed = false;  // SQLite reads pages of at least one commit from it
};

WalCheck check_wal(const std::string& path) {
  WalCheck out;
  std::ifstream in(path + "-wal", std::ios::binary);
  if (!in) return out;
  out.present = true;
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.empty()) return out;
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  // SQLite ignores a -wal whose header is bad, with every commit in it.
  const auto damaged_header = [&] {
    if (bytes.size() > 32)
      out.damage = "its write-ahead log " + path + "-wal has a damaged header: SQLite ignores all " +
                   std::to_string(bytes.size()) + " bytes of it, with every commit since the last checkpoint";
    return out;
  };
  const auto be32 = [&](std::size_t at) {
    return (std::uint32_t{b[at]} << 24) | (std::uint32_t{b[at + 1]} << 16) | (std::uint32_t{b[at + 2]} << 8) |
           b[at + 3];
  };
  if (bytes.size() < 32) {
    out.torn_tail = true;
    return out;
  }
  const std::uint32_t magic = be32(0);
  const std::uint32_t page_size = be32(8);
  if ((magic != 0x377f0682 && magic != 0x377f0683) || page_size < 512 || page_size > 65536 ||
      (page_size & (page_size - 1)) != 0) {
    return damaged_header();
  }
  const bool big_endian = (magic & 1) != 0;
  const auto word = [&](std::size_t at) {
    return big_endian ? be32(at)
                      : (std::uint32_t{b[at + 3]} << 24) | (std::uint32_t{b[at + 2]} << 16) |
                            (std::uint32_t{b[at + 1]} << 8) | b[at];
  };
  std::uint32_t s0 = 0, s1 = 0;
  const auto sum = [&](std::size_t at, std::size_t n) {
    for (std::size_t i = at; i + 8 <= at + n; i += 8) {
      s0 += word(i) + s1;
      s1 += word(i + 4) + s0;
    }
  };
  sum(0, 24);
  if (s0 != be32(24) || s1 != be32(28)) {
    return damaged_header();
  }
  const std::uint32_t salt1 = be32(16), salt2 = be32(20);
  const std::size_t frame = 24 + page_size;
  const std::size_t frames = (bytes.size() - 32) / frame;
  std::size_t valid = 0, last_commit = 0;  // frames in the intact chain; 1 + the last commit among them
  bool chain = true;
  std::size_t lost_commits = 0, lost_pages = 0;
  for (std::size_t k = 0; k < frames; ++k) {
    const std::size_t at = 32 + k * frame;
    const bool same_generation = be32(at + 8) == salt1 && be32(at + 12) == salt2;
    const bool commit = be32(at + 4) != 0;
    if (chain) {
      sum(at, 8);
      sum(at + 24, page_size);
      if (same_generation && s0 == be32(at + 16) && s1 == be32(at + 20)) {
        valid = k + 1;
        if (commit) last_commit = k + 1;
        continue;
      }
      chain = false;
    }
    if (same_generation) {
      ++lost_pages;
      if (commit) ++lost_commits;
    }
  }
  if (lost_commits > 0) {
    out.damage = "its write-ahead log " + path + "-wal is damaged at frame " + std::to_string(valid + 1) +
                 " of " + std::to_string(frames) + ": " + std::to_string(lost_commits) +
                 " later commit(s) of up to " + std::to_string(lost_pages) +
                 " pages are lost (the log reads as it was at the last intact commit)";
  }
  // A file that ends inside a frame, or in frames no commit completes, is what a writer leaves
  // when it stops while committing (killed, a full disk, a power loss): the log reads as it was
  // at its last commit and is incomplete. Only a closed log with such a tail is damaged.
  const std::size_t partial = (bytes.size() - 32) % frame;
  out.commits_replayed = last_commit > 0;
  out.torn_tail = partial != 0 || valid > last_commit || !chain;
  return out;
}

/// A log in WAL mode (header bytes 18 and 19 are 2) keeps what its writer committed since the
/// last checkpoint in LOG-wal: without it (or with an empty one), an unclosed log may hold no
/// tables at all.
bool wal_mode_without_wal(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char h[20] = {};
  in.read(reinterpret_cast<char*>(h), sizeof h);
  std::error_code ec;
  // Empty counts as missing: opening such a log creates an empty one.
  const auto wal_size = std::filesystem::file_size(path + "-wal", ec);
  return in.gcount() == sizeof h && h[18] == 2 && (ec || wal_size == 0);
}

/// True when a writer holds the log `st` describes (its flock, see lock_for_writing). A file
/// that this process does not have open is tested with a shared flock, held for an instant
/// (writers retry theirs); one open here is looked up in /proc/locks, whose first read costs a
/// process 5-30 ms on some kernels.
bool being_written(const std::string& path, const struct stat& st) {
  if (OpenHere::contains(st)) return flock_holder(st.st_dev, st.st_ino) != 0;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
  if (fd < 0) return flock_holder(st.st_dev, st.st_ino) != 0;
  struct stat opened {};
  bool held = false;
  if (::fstat(fd, &opened) != 0 || opened.st_dev != st.st_dev || opened.st_ino != st.st_ino) {
    held = flock_holder(st.st_dev, st.st_ino) != 0;  // replaced meanwhile
  } else if (::flock(fd, LOCK_SH | LOCK_NB) != 0) {
    held = errno == EWOULDBLOCK;
  }
  ::close(fd);  // drops the shared lock
  return held;
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
  const bool wal_missing = !live && wal_mode_without_wal(path_);
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
    if (!wal_missing) return schema;
    return make_error(Errc::kCorrupt,
                      path_ + " holds no session tables, and its write-ahead log " + path_ +
                          "-wal is missing: a log that was not closed keeps its data there; "
                          "copy that file next to the log (it was lost or not copied with it)");
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
