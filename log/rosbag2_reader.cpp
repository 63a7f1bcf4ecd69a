// SPDX-License-Identifier: BSD-3-Clause
// Bag2Reader: rosbag2 folders and their sqlite3 and mcap storage files (log/rosbag2.hpp).

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>

#include "log/rosbag2.hpp"
#include "log/rosbag_format.hpp"

namespace imucal::log::rosbag2 {

using rosbag::BagDamage;
using rosbag::Connection;
using rosbag::MessageView;

namespace {

namespace fs = std::filesystem;

constexpr std::string_view kMcapMagic = "\x89MCAP0\r\n";
constexpr std::string_view kSqliteMagic{"SQLite format 3\0", 16};
/// A record or chunk larger than this is damage (rosbag2's mcap chunks are 768 kB by default).
constexpr std::uint64_t kMaxRecordBytes = std::uint64_t{1} << 30;

/// ROS 1's name of a ROS 2 type: "sensor_msgs/msg/Imu" -> "sensor_msgs/Imu".
std::string ros1_type(const std::string& type) {
  const auto at = type.find("/msg/");
  return at == std::string::npos ? type : type.substr(0, at) + "/" + type.substr(at + 5);
}

std::string head_of(const std::string& path, std::size_t n) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return {};  // a FIFO would wait for a writer
  std::string out(n, '\0');
  FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return {};
  out.resize(std::fread(out.data(), 1, n, f));
  std::fclose(f);
  return out;
}

/// "mcap" by its magic; "sqlite3" for an SQLite file named .db3 (imucal's own session logs are
/// SQLite files too); else empty.
std::string storage_of_file(const std::string& path) {
  const std::string head = head_of(path, 16);
  if (head.compare(0, kMcapMagic.size(), kMcapMagic) == 0) return "mcap";
  if (head == kSqliteMagic && fs::path(path).extension() == ".db3") return "sqlite3";
  return {};
}

/// One storage file's messages: connections numbered by the reader across files (by topic).
class StorageFile {
 public:
  virtual ~StorageFile() = default;
  /// The file's topics as (its own id, connection).
  virtual Result<std::vector<std::pair<std::uint32_t, Connection>>> topics() = 0;
  /// Messages with the file's own topic ids (MessageView::connection is set by the caller).
  virtual Status for_each(
      const std::function<Status(std::uint32_t, TimeNs, std::span<const std::uint8_t>)>& visit,
      BagDamage& damage, const std::function<void(double)>& progress) = 0;
};

// ---------------------------------------------------------------------------------------------
// sqlite3

struct SqliteCloser {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
};
struct StmtCloser {
  void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};

class SqliteFile final : public StorageFile {
 public:
  static Result<std::unique_ptr<StorageFile>> open(const std::string& path) {
    sqlite3* raw = nullptr;
    // Read-only and immutable: nothing is written beside an input (no -wal, no -shm, no journal).
    const std::string uri = "file:" + path + "?immutable=1";
    const int rc = sqlite3_open_v2(uri.c_str(), &raw, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
    std::unique_ptr<sqlite3, SqliteCloser> db(raw);
    if (rc != SQLITE_OK) {
      return make_error(Errc::kCorrupt, path + ": " + (raw != nullptr ? sqlite3_errmsg(raw) : "cannot open"));
    }
    auto file = std::unique_ptr<SqliteFile>(new SqliteFile(path, std::move(db)));
    return std::unique_ptr<StorageFile>(std::move(file));
  }

  Result<std::vector<std::pair<std::uint32_t, Connection>>> topics() override {
    auto stmt = prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id");
    if (!stmt.ok()) return stmt.error();
    std::vector<std::pair<std::uint32_t, Connection>> out;
    int rc = SQLITE_ROW;
    while ((rc = sqlite3_step(stmt->get())) == SQLITE_ROW) {
      Connection c;
      c.topic = column_text(stmt->get(), 1);
      c.type = ros1_type(column_text(stmt->get(), 2));
      const std::string format = column_text(stmt->get(), 3);
      if (format != "cdr") {
        return make_error(Errc::kUnsupported, path_ + ": the topic " + c.topic + " is serialized as '" +
                                                  format + "'; imucal reads cdr, what ROS 2 writes");
      }
      out.emplace_back(static_cast<std::uint32_t>(sqlite3_column_int64(stmt->get(), 0)), std::move(c));
    }
    if (rc != SQLITE_DONE)
      return make_error(Errc::kCorrupt, path_ + ": its topics: " + sqlite3_errmsg(db_.get()));
    return out;
  }

  Status for_each(const std::function<Status(std::uint32_t, TimeNs, std::span<const std::uint8_t>)>& visit,
                  BagDamage& damage, const std::function<void(double)>& progress) override {
    sqlite3_int64 total = 1;
    if (auto count = prepare("SELECT COUNT(*) FROM messages");
        count.ok() && sqlite3_step(count->get()) == SQLITE_ROW)
      total = std::max<sqlite3_int64>(1, sqlite3_column_int64(count->get(), 0));
    auto stmt = prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id");
    if (!stmt.ok()) {
      damage = {true, 0, file_size(), 0, stmt.error().message};
      return {};
    }
    std::int64_t n = 0;
    int rc = SQLITE_ROW;
    while ((rc = sqlite3_step(stmt->get())) == SQLITE_ROW) {
      const auto* blob = static_cast<const std::uint8_t*>(sqlite3_column_blob(stmt->get(), 2));
      const auto size = static_cast<std::size_t>(sqlite3_column_bytes(stmt->get(), 2));
      IMUCAL_TRY(visit(static_cast<std::uint32_t>(sqlite3_column_int64(stmt->get(), 0)),
                       static_cast<TimeNs>(sqlite3_column_int64(stmt->get(), 1)), std::span(blob, size)));
      if (++n % 256 == 0 && progress) progress(static_cast<double>(n) / static_cast<double>(total));
    }
    if (rc != SQLITE_DONE) {
      damage = {true, 0, file_size(), 0,
                path_ + ": reading its messages stopped after " + std::to_string(n) + ": " +
                    sqlite3_errmsg(db_.get())};
    }
    return {};
  }

 private:
  SqliteFile(std::string path, std::unique_ptr<sqlite3, SqliteCloser> db)
      : path_(std::move(path)), db_(std::move(db)) {}

  Result<std::unique_ptr<sqlite3_stmt, StmtCloser>> prepare(const char* sql) {
    sqlite3_stmt* raw = nullptr;
    if (sqlite3_prepare_v2(db_.get(), sql, -1, &raw, nullptr) != SQLITE_OK) {
      sqlite3_finalize(raw);
      return make_error(Errc::kCorrupt,
                        path_ + " is not a rosbag2 sqlite3 file (" + sqlite3_errmsg(db_.get()) + ")");
    }
    return std::unique_ptr<sqlite3_stmt, StmtCloser>(raw);
  }
  static std::string column_text(sqlite3_stmt* s, int i) {
    const auto* t = sqlite3_column_text(s, i);
    return t != nullptr ? std::string(reinterpret_cast<const char*>(t)) : std::string();
  }
  std::uint64_t file_size() const {
    std::error_code ec;
    const auto size = fs::file_size(path_, ec);
    return ec ? 0 : size;
  }

  std::string path_;
  std::unique_ptr<sqlite3, SqliteCloser> db_;
};

// ---------------------------------------------------------------------------------------------
// mcap

/// Reads little-endian fields of one record's content.
class McapCursor {
 public:
  explicit McapCursor(std::span<const std::uint8_t> data) : data_(data) {}
  bool ok() const { return ok_; }
  std::uint16_t u16() {
    return take(2) ? static_cast<std::uint16_t>(data_[pos_ - 2] | (data_[pos_ - 1] << 8)) : 0;
  }
  std::uint32_t u32() { return take(4) ? rosbag::format::le32(data_.data() + pos_ - 4) : 0; }
  std::uint64_t u64() { return take(8) ? rosbag::format::le64(data_.data() + pos_ - 8) : 0; }
  std::string text() {
    const std::uint32_t n = u32();
    if (!take(n)) return {};
    return std::string(reinterpret_cast<const char*>(data_.data() + pos_ - n), n);
  }
  std::span<const std::uint8_t> bytes(std::uint64_t n) {
    if (n > data_.size() - pos_ || !take(static_cast<std::size_t>(n))) {
      ok_ = false;
      return {};
    }
    return data_.subspan(pos_ - static_cast<std::size_t>(n), static_cast<std::size_t>(n));
  }
  std::span<const std::uint8_t> rest() { return bytes(data_.size() - pos_); }

 private:
  bool take(std::size_t n) {
    if (!ok_ || n > data_.size() - pos_) {
      ok_ = false;
      return false;
    }
    pos_ += n;
    return true;
  }
  std::span<const std::uint8_t> data_;
  std::size_t pos_ = 0;
  bool ok_ = true;
};

constexpr std::uint8_t kOpSchema = 0x03, kOpChannel = 0x04, kOpMessage = 0x05, kOpChunk = 0x06,
                       kOpDataEnd = 0x0f, kOpFooter = 0x02;

class McapFile final : public StorageFile {
 public:
  static Result<std::unique_ptr<StorageFile>> open(const std::string& path) {
    auto file = std::unique_ptr<McapFile>(new McapFile(path));
    file->fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (file->fd_ < 0) return make_error(Errc::kIo, path + ": " + std::strerror(errno));
    struct stat st {};
    if (::fstat(file->fd_, &st) != 0) return make_error(Errc::kIo, path + ": " + std::strerror(errno));
    file->size_ = static_cast<std::uint64_t>(st.st_size);
    return std::unique_ptr<StorageFile>(std::move(file));
  }
  ~McapFile() override {
    if (fd_ >= 0) ::close(fd_);
  }

  Result<std::vector<std::pair<std::uint32_t, Connection>>> topics() override {
    // The channels as the data section declares them (a summary section is optional).
    BagDamage damage;
    IMUCAL_TRY(walk([](std::uint32_t, TimeNs, std::span<const std::uint8_t>) { return Status{}; }, damage, {},
                    /*messages=*/false));
    std::vector<std::pair<std::uint32_t, Connection>> out;
    for (const auto& [id, c] : channels_) out.emplace_back(id, c);
    return out;
  }

  Status for_each(const std::function<Status(std::uint32_t, TimeNs, std::span<const std::uint8_t>)>& visit,
                  BagDamage& damage, const std::function<void(double)>& progress) override {
    return walk(visit, damage, progress, /*messages=*/true);
  }

 private:
  explicit McapFile(std::string path) : path_(std::move(path)) {}

  Status read_at(std::uint64_t offset, void* out, std::size_t n) const {
    auto* p = static_cast<char*>(out);
    while (n > 0) {
      const ssize_t got = ::pread(fd_, p, n, static_cast<off_t>(offset));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) return make_error(Errc::kIo, path_ + ": read failed: " + std::strerror(errno));
      if (got == 0) return make_error(Errc::kCorrupt, "the file ends");
      p += got;
      offset += static_cast<std::uint64_t>(got);
      n -= static_cast<std::size_t>(got);
    }
    return {};
  }

  /// Schema and channel records (at the top level or inside a chunk); kCorrupt when malformed.
  Status declare(std::uint8_t op, std::span<const std::uint8_t> content) {
    McapCursor c(content);
    if (op == kOpSchema) {
      const std::uint16_t id = c.u16();
      const std::string name = c.text();
      if (!c.ok()) return make_error(Errc::kCorrupt, "a damaged schema record");
      schemas_[id] = name;
      return {};
    }
    const std::uint16_t id = c.u16();
    const std::uint16_t schema = c.u16();
    Connection conn;
    conn.topic = c.text();
    const std::string encoding = c.text();
    if (!c.ok()) return make_error(Errc::kCorrupt, "a damaged channel record");
    auto it = schemas_.find(schema);
    conn.type = ros1_type(it != schemas_.end() ? it->second : std::string());
    if (encoding != "cdr") {
      return make_error(Errc::kUnsupported, "the topic " + conn.topic + " is encoded as '" + encoding +
                                                "'; imucal reads cdr, what ROS 2 writes");
    }
    channels_.try_emplace(id, std::move(conn));
    return {};
  }

  /// The records of `data` (a chunk's, uncompressed): declarations, then messages to `visit`.
  Status records(std::span<const std::uint8_t> data, bool messages,
                 const std::function<Status(std::uint32_t, TimeNs, std::span<const std::uint8_t>)>& visit) {
    std::vector<std::tuple<std::uint32_t, TimeNs, std::span<const std::uint8_t>>> found;
    for (std::size_t pos = 0; pos < data.size();) {
      if (data.size() - pos < 9) return make_error(Errc::kCorrupt, "a record cut short inside a chunk");
      const std::uint8_t op = data[pos];
      const std::uint64_t len = rosbag::format::le64(data.data() + pos + 1);
      if (len > data.size() - pos - 9)
        return make_error(Errc::kCorrupt, "a record runs past its chunk's end");
      const auto content = data.subspan(pos + 9, static_cast<std::size_t>(len));
      pos += 9 + static_cast<std::size_t>(len);
      if (op == kOpSchema || op == kOpChannel) {
        IMUCAL_TRY(declare(op, content));
      } else if (op == kOpMessage && messages) {
        McapCursor c(content);
        const std::uint16_t channel = c.u16();
        c.u32();  // sequence
        const std::uint64_t log_time = c.u64();
        c.u64();  // publish time
        auto payload = c.rest();
        if (!c.ok()) return make_error(Errc::kCorrupt, "a damaged message record");
        found.emplace_back(channel, static_cast<TimeNs>(log_time), payload);
      }
    }
    for (const auto& [channel, t, payload] : found) IMUCAL_TRY(visit(channel, t, payload));
    return {};
  }

  Result<std::vector<std::uint8_t>> chunk_records(std::span<const std::uint8_t> content) const {
    McapCursor c(content);
    c.u64();  // message start time
    c.u64();  // message end time
    const std::uint64_t size = c.u64();
    const std::uint32_t crc = c.u32();
    const std::string compression = c.text();
    const std::uint64_t length = c.u64();
    auto compressed = c.bytes(length);
    if (!c.ok() || size > kMaxRecordBytes) return make_error(Errc::kCorrupt, "a damaged chunk header");
    std::vector<std::uint8_t> out;
    if (compression == "zstd") {
      out.resize(size);
      const std::size_t rc = ZSTD_decompress(out.data(), out.size(), compressed.data(), compressed.size());
      if (ZSTD_isError(rc) || rc != size) {
        return make_error(Errc::kCorrupt,
                          std::string("its zstd data do not decompress to ") + std::to_string(size) +
                              " bytes" +
                              (ZSTD_isError(rc) ? std::string(" (") + ZSTD_getErrorName(rc) + ")" : ""));
      }
    } else {
      auto plain = rosbag::format::decompress(compression.empty() ? "none" : compression, compressed, size);
      if (!plain.ok()) return plain.error();
      out = std::move(*plain);
    }
    if (crc != 0 && crc32(0L, out.data(), static_cast<uInt>(out.size())) != crc) {
      return make_error(Errc::kCorrupt, "its records fail their CRC");
    }
    return out;
  }

  Status walk(const std::function<Status(std::uint32_t, TimeNs, std::span<const std::uint8_t>)>& visit,
              BagDamage& damage, const std::function<void(double)>& progress, bool messages) {
    damage = {};
    damage.size = size_;
    auto stop = [&](std::uint64_t at, const std::string& what) {
      damage.damaged = true;
      damage.offset = at;
      damage.message = what;
      return Status{};
    };
    std::uint64_t at = kMcapMagic.size();
    while (true) {
      if (size_ - at < 9) return stop(at, "the file ends before its data end record (it was cut short)");
      std::uint8_t head[9];
      IMUCAL_TRY(read_at(at, head, sizeof head));
      const std::uint64_t len = rosbag::format::le64(head + 1);
      if (len > kMaxRecordBytes || len > size_ - at - 9) {
        return stop(at, "the record at byte " + std::to_string(at) + " is cut short or damaged (" +
                            std::to_string(len) + " bytes)");
      }
      if (head[0] == kOpDataEnd || head[0] == kOpFooter) return {};
      std::vector<std::uint8_t> content(static_cast<std::size_t>(len));
      IMUCAL_TRY(read_at(at + 9, content.data(), content.size()));
      Status s;
      if (head[0] == kOpChunk) {
        auto data = chunk_records(content);
        s = data.ok() ? records(*data, messages, visit) : Status(data.error());
        if (s.ok()) ++damage.chunks_read;
      } else {
        // A record outside a chunk (an mcap written without chunks): read as a chunk of one.
        std::vector<std::uint8_t> record(head, head + 9);
        record.insert(record.end(), content.begin(), content.end());
        s = records(record, messages, visit);
      }
      if (!s.ok()) {
        if (s.error().code == Errc::kCorrupt) {
          return stop(at, "the " + std::string(head[0] == kOpChunk ? "chunk" : "record") + " at byte " +
                              std::to_string(at) + ": " + s.error().message);
        }
        return s;
      }
      at += 9 + len;
      if (progress)
        progress(static_cast<double>(at) / static_cast<double>(std::max<std::uint64_t>(size_, 1)));
    }
  }

  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::map<std::uint16_t, std::string> schemas_;
  std::map<std::uint32_t, Connection> channels_;
};

Result<std::unique_ptr<StorageFile>> open_storage(const std::string& path) {
  const std::string storage = storage_of_file(path);
  if (storage == "mcap") return McapFile::open(path);
  if (storage == "sqlite3") return SqliteFile::open(path);
  return make_error(Errc::kCorrupt, path + " is neither a rosbag2 sqlite3 (.db3) nor an mcap file");
}

/// The storage files of a rosbag2 folder, in metadata.yaml's order (else the folder's .db3 and
/// .mcap files by name).
Result<std::vector<std::string>> folder_files(const fs::path& dir) {
  std::vector<std::string> files;
  const fs::path meta = dir / "metadata.yaml";
  std::error_code ec;
  if (fs::exists(meta, ec)) {
    try {
      const YAML::Node info = YAML::LoadFile(meta.string())["rosbag2_bagfile_information"];
      if (info && info["relative_file_paths"]) {
        for (const auto& f : info["relative_file_paths"])
          files.push_back((dir / f.as<std::string>()).string());
      }
    } catch (const YAML::Exception& e) {
      return make_error(Errc::kCorrupt, meta.string() + ": " + e.what());
    }
  }
  if (files.empty()) {
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const auto ext = e.path().extension().string();
      if (ext == ".db3" || ext == ".mcap") files.push_back(e.path().string());
    }
    std::sort(files.begin(), files.end());
  }
  if (files.empty())
    return make_error(Errc::kNotFound, dir.string() + " holds no rosbag2 storage file (.db3, .mcap)");
  return files;
}

}  // namespace

struct Bag2Reader::State {
  std::vector<std::string> files;
  std::map<std::string, Connection> by_topic;                                // unified, ids 0..n-1
  std::vector<std::map<std::uint32_t, const Connection*>> file_connections;  // per file: its ids
  bool read = false;

  Status read_connections() {
    if (read) return {};
    file_connections.assign(files.size(), {});
    for (std::size_t i = 0; i < files.size(); ++i) {
      auto file = open_storage(files[i]);
      if (!file.ok()) return file.error();
      auto topics = (*file)->topics();
      if (!topics.ok()) return topics.error().context(files[i]);
      for (auto& [id, c] : *topics) {
        auto [it, added] = by_topic.try_emplace(c.topic, c);
        if (added) it->second.id = static_cast<std::uint32_t>(by_topic.size() - 1);
        file_connections[i][id] = &it->second;
      }
    }
    read = true;
    return {};
  }
};

Bag2Reader::Bag2Reader(std::unique_ptr<State> state) : state_(std::move(state)) {}
Bag2Reader::~Bag2Reader() = default;

bool is_rosbag2(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return fs::exists(fs::path(path) / "metadata.yaml", ec);
  return !storage_of_file(path).empty();
}

Result<std::unique_ptr<Bag2Reader>> Bag2Reader::open(const std::string& path) {
  auto s = std::make_unique<State>();
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    auto files = folder_files(path);
    if (!files.ok()) return files.error();
    s->files = std::move(*files);
  } else if (fs::is_regular_file(path, ec)) {
    s->files = {path};
  } else {
    return make_error(
        fs::exists(path, ec) ? Errc::kInvalidArgument : Errc::kNotFound,
        path + (fs::exists(path, ec) ? " is not a file or folder" : ": No such file or folder"));
  }
  for (const auto& f : s->files) {
    if (storage_of_file(f).empty()) {
      return make_error(Errc::kCorrupt, f + " is neither a rosbag2 sqlite3 (.db3) nor an mcap file");
    }
  }
  return std::unique_ptr<Bag2Reader>(new Bag2Reader(std::move(s)));
}

Result<std::vector<Connection>> Bag2Reader::connections() {
  IMUCAL_TRY(state_->read_connections());
  std::vector<Connection> out;
  for (const auto& [topic, c] : state_->by_topic) out.push_back(c);
  std::sort(out.begin(), out.end(), [](const Connection& a, const Connection& b) { return a.id < b.id; });
  return out;
}

Status Bag2Reader::for_each_message(const std::function<Status(const MessageView&)>& visit, BagDamage& damage,
                                    const std::function<void(double)>& progress) {
  State& s = *state_;
  IMUCAL_TRY(s.read_connections());
  damage = {};
  for (std::size_t i = 0; i < s.files.size(); ++i) {
    auto file = open_storage(s.files[i]);
    if (!file.ok()) return file.error();
    const auto& ids = s.file_connections[i];
    IMUCAL_TRY((*file)->for_each(
        [&](std::uint32_t id, TimeNs t, std::span<const std::uint8_t> data) -> Status {
          auto it = ids.find(id);
          if (it == ids.end()) {
            return make_error(Errc::kCorrupt, s.files[i] + ": a message of topic id " + std::to_string(id) +
                                                  ", which the file never declared");
          }
          return visit(MessageView{it->second, t, data});
        },
        damage,
        [&](double f) {
          if (progress) progress((static_cast<double>(i) + f) / static_cast<double>(s.files.size()));
        }));
    if (damage.damaged) {
      damage.message = s.files[i] + ": " + damage.message;
      return {};
    }
  }
  return {};
}

}  // namespace imucal::log::rosbag2
