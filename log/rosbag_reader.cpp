// SPDX-License-Identifier: BSD-3-Clause
// BagReader: a ROS 1 bag 2.0 read front to back (log/rosbag.hpp).

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>

#include "log/rosbag.hpp"
#include "log/rosbag_format.hpp"

namespace imucal::log::rosbag {

using format::Fields;

namespace {

/// A connection header longer than this is damage (a real one, definition included, is a few kB).
constexpr std::uint32_t kMaxHeaderBytes = 16u << 20;
/// Nor does a chunk hold more than this uncompressed (rosbag's are 768 kB by default).
constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{1} << 30;

/// A record read from the file: its fields and data.
struct FileRecord {
  Fields fields;
  std::vector<std::uint8_t> data;
  std::uint64_t next = 0;  // the offset after it
};

Result<Connection> connection_from(const Fields& record, std::span<const std::uint8_t> data) {
  auto id = record.u32("conn");
  if (!id.ok()) return id.error();
  auto topic = record.text("topic");
  if (!topic.ok()) return topic.error();
  auto fields = Fields::parse(data);
  if (!fields.ok()) return fields.error().context("the connection of topic " + *topic);
  Connection c;
  c.id = *id;
  c.topic = *topic;
  auto type = fields->text("type");
  if (!type.ok()) return type.error().context("the connection of topic " + *topic);
  c.type = *type;
  if (auto md5 = fields->text("md5sum"); md5.ok()) c.md5sum = *md5;
  if (auto def = fields->text("message_definition"); def.ok()) c.definition = *def;
  return c;
}

}  // namespace

struct BagReader::State {
  std::string path;
  int fd = -1;
  std::uint64_t size = 0;
  std::uint64_t first_record = 0;  // after the bag header record
  std::uint64_t index_pos = 0;
  std::map<std::uint32_t, Connection> connections;

  ~State() {
    if (fd >= 0) ::close(fd);
  }

  Status read_at(std::uint64_t offset, void* out, std::size_t n) const {
    auto* p = static_cast<char*>(out);
    while (n > 0) {
      const ssize_t got = ::pread(fd, p, n, static_cast<off_t>(offset));
      if (got < 0) {
        if (errno == EINTR) continue;
        return make_error(Errc::kIo, path + ": read failed at byte " + std::to_string(offset) + ": " +
                                         std::strerror(errno));
      }
      if (got == 0) return make_error(Errc::kCorrupt, "the file ends");
      p += got;
      offset += static_cast<std::uint64_t>(got);
      n -= static_cast<std::size_t>(got);
    }
    return {};
  }

  /// The record at `offset`; kCorrupt (a sentence naming the byte) when it is not whole.
  Result<FileRecord> read_record(std::uint64_t offset) const {
    auto cut = [&](const std::string& what) {
      return make_error(Errc::kCorrupt, "the record at byte " + std::to_string(offset) + " " + what);
    };
    std::uint8_t len[4];
    if (size - offset < 4) return cut("is cut short: the file ends inside its header's length");
    IMUCAL_TRY(read_at(offset, len, 4));
    const std::uint32_t header_len = format::le32(len);
    if (header_len > kMaxHeaderBytes)
      return cut("claims a header of " + std::to_string(header_len) + " bytes");
    if (size - offset - 4 < std::uint64_t{header_len} + 4)
      return cut("is cut short: the file ends inside its header");
    std::vector<std::uint8_t> header(header_len);
    IMUCAL_TRY(read_at(offset + 4, header.data(), header_len));
    IMUCAL_TRY(read_at(offset + 4 + header_len, len, 4));
    const std::uint32_t data_len = format::le32(len);
    const std::uint64_t data_at = offset + 8 + header_len;
    if (size - data_at < data_len) {
      return cut("is cut short: its " + std::to_string(data_len) +
                 " bytes of data run past the file's end (" + std::to_string(size) + " bytes)");
    }
    auto fields = Fields::parse(header);
    if (!fields.ok()) return cut("has a damaged header: " + fields.error().message);
    FileRecord r{std::move(*fields), std::vector<std::uint8_t>(data_len), data_at + data_len};
    IMUCAL_TRY(read_at(data_at, r.data.data(), data_len));
    return r;
  }

  /// Whether the bag header points at an index inside the file.
  bool has_index() const { return index_pos >= first_record && index_pos < size; }

  /// The connections of the index at the bag's end.
  Status read_index_connections() {
    std::map<std::uint32_t, Connection> found;
    for (std::uint64_t at = index_pos; at < size;) {
      auto r = read_record(at);
      if (!r.ok()) return r.error();
      auto op = r->fields.op();
      if (!op.ok()) return op.error();
      if (*op == format::kOpConnection) {
        auto c = connection_from(r->fields, r->data);
        if (!c.ok()) return c.error();
        found[c->id] = std::move(*c);
      } else if (*op != format::kOpChunkInfo) {  // chunk infos: the chunks themselves are read instead
        return make_error(Errc::kCorrupt, "a record of kind " + std::to_string(*op) + " in the index");
      }
      at = r->next;
    }
    connections = std::move(found);
    return {};
  }

  /// The records of the chunk record `r`, uncompressed.
  Result<std::vector<std::uint8_t>> chunk_data(const FileRecord& r, std::string* compression) const {
    auto comp = r.fields.text("compression");
    if (!comp.ok()) return comp.error();
    auto raw_size = r.fields.u32("size");
    if (!raw_size.ok()) return raw_size.error();
    if (*raw_size > kMaxChunkBytes)
      return make_error(Errc::kCorrupt, "a chunk claims " + std::to_string(*raw_size) + " bytes");
    *compression = *comp;
    return format::decompress(*comp, r.data, *raw_size);
  }

  /// The messages of the chunk record `r` (their data in `storage`), after its connections have
  /// been added; kCorrupt when any part of the chunk is not whole, so that a chunk is used
  /// entirely or not at all.
  Result<std::vector<MessageView>> chunk_messages(const FileRecord& r, std::vector<std::uint8_t>& storage,
                                                  std::string& compression) {
    auto data = chunk_data(r, &compression);
    if (!data.ok()) return data.error();
    storage = std::move(*data);
    auto records = format::parse_records(storage);
    if (!records.ok()) return records.error();
    for (const auto& rec : *records) {
      auto op = rec.fields.op();
      if (!op.ok()) return op.error();
      if (*op != format::kOpConnection) continue;
      auto c = connection_from(rec.fields, rec.data);
      if (!c.ok()) return c.error();
      connections.try_emplace(c->id, std::move(*c));
    }
    std::vector<MessageView> views;
    for (const auto& rec : *records) {
      if (*rec.fields.op() != format::kOpMessage) continue;
      auto conn = rec.fields.u32("conn");
      if (!conn.ok()) return conn.error();
      auto time = rec.fields.u64("time");
      if (!time.ok()) return time.error();
      auto t = format::time_ns(*time);
      if (!t.ok()) return t.error();
      auto it = connections.find(*conn);
      if (it == connections.end()) {
        return make_error(Errc::kCorrupt, "a message of connection " + std::to_string(*conn) +
                                              ", which the bag never declared");
      }
      views.push_back({&it->second, *t, rec.data});
    }
    return views;
  }
};

BagReader::BagReader(std::unique_ptr<State> state) : state_(std::move(state)) {}
BagReader::~BagReader() = default;

Result<std::unique_ptr<BagReader>> BagReader::open(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (fs::exists(fs::path(path) / "metadata.yaml", ec)) {
      return make_error(Errc::kUnsupported,
                        path + " is a ROS 2 bag (rosbag2 folder); this is a reader of ROS 1 bags");
    }
    return make_error(Errc::kInvalidArgument, path + " is a folder, not a ROS 1 bag file");
  }
  if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) {
    return make_error(Errc::kInvalidArgument,
                      path + " is not a regular file");  // a FIFO would wait for a writer
  }
  auto s = std::make_unique<State>();
  s->path = path;
  s->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (s->fd < 0) {
    return make_error(errno == ENOENT ? Errc::kNotFound : Errc::kIo, path + ": " + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(s->fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    return make_error(Errc::kInvalidArgument, path + " is not a regular file");
  }
  s->size = static_cast<std::uint64_t>(st.st_size);
  char magic[13] = {};
  const std::size_t n = std::min<std::uint64_t>(s->size, sizeof magic);
  if (n > 0) IMUCAL_TRY(s->read_at(0, magic, n));
  const std::string_view head(magic, n);
  if (head != format::kMagic) {
    if (head.starts_with("#ROSBAG V")) {
      return make_error(Errc::kUnsupported, path + " is a ROS 1 bag of format " +
                                                std::string(head.substr(9, 3)) +
                                                "; only format 2.0 (ROS since 2010) is read: `rosbag fix` "
                                                "rewrites an older one");
    }
    if (head.starts_with("SQLite format")) {
      return make_error(Errc::kCorrupt,
                        path +
                            " is not a ROS 1 bag but an SQLite file (an imucal session log is "
                            "read as it is; a ROS 2 bag's storage file is named .db3)");
    }
    return make_error(Errc::kCorrupt, path + " is not a ROS 1 bag (it does not begin with \"#ROSBAG V2.0\")");
  }
  auto header = s->read_record(format::kMagic.size());
  if (!header.ok()) return header.error().context(path + ": its bag header");
  auto op = header->fields.op();
  if (!op.ok() || *op != format::kOpBagHeader) {
    return make_error(Errc::kCorrupt, path + ": the first record is not a bag header");
  }
  auto index_pos = header->fields.u64("index_pos");
  if (!index_pos.ok()) return index_pos.error().context(path + ": its bag header");
  s->first_record = header->next;
  s->index_pos = *index_pos;
  return std::unique_ptr<BagReader>(new BagReader(std::move(s)));
}

Result<std::vector<Connection>> BagReader::connections() {
  State& s = *state_;
  bool from_index = false;
  if (s.has_index()) {
    from_index = s.read_index_connections().ok();
  }
  if (!from_index) {
    // No index (a bag not closed, or cut short): the connection records inside the chunks.
    BagDamage damage;
    IMUCAL_TRY(for_each_message([](const MessageView&) { return Status{}; }, damage));
  }
  std::vector<Connection> out;
  for (const auto& [id, c] : s.connections) out.push_back(c);
  return out;
}

Status BagReader::for_each_message(const std::function<Status(const MessageView&)>& visit, BagDamage& damage,
                                   const std::function<void(double)>& progress) {
  State& s = *state_;
  damage = {};
  damage.size = s.size;
  const bool indexed = s.has_index();
  const std::uint64_t end = indexed ? s.index_pos : s.size;
  auto stop = [&](std::uint64_t at, const std::string& what) {
    damage.damaged = true;
    damage.offset = at;
    damage.message = what;
  };
  std::uint64_t at = s.first_record;
  while (at < end) {
    auto r = s.read_record(at);
    if (!r.ok()) {
      if (r.error().code == Errc::kIo) return r.error();
      stop(at, r.error().message);
      return {};
    }
    auto op = r->fields.op();
    if (!op.ok()) {
      stop(at, "the record at byte " + std::to_string(at) + ": " + op.error().message);
      return {};
    }
    if (*op == format::kOpChunk) {
      std::vector<std::uint8_t> storage;
      std::string compression;
      auto views = s.chunk_messages(*r, storage, compression);
      if (!views.ok()) {
        stop(at, "the chunk at byte " + std::to_string(at) + ": " + views.error().message);
        return {};
      }
      for (const auto& v : *views) IMUCAL_TRY(visit(v));
      ++damage.chunks_read;
    } else if (*op == format::kOpConnection) {
      auto c = connection_from(r->fields, r->data);
      if (!c.ok()) {
        stop(at, "the connection record at byte " + std::to_string(at) + ": " + c.error().message);
        return {};
      }
      s.connections.try_emplace(c->id, std::move(*c));
    } else if (*op != format::kOpIndex && *op != format::kOpChunkInfo) {
      stop(at, "the record at byte " + std::to_string(at) + " is of kind " + std::to_string(*op) +
                   ", which a bag holds nowhere among its chunks");
      return {};
    }
    at = r->next;
    if (progress) progress(static_cast<double>(at) / static_cast<double>(std::max<std::uint64_t>(s.size, 1)));
  }
  if (!indexed) {
    stop(at, s.index_pos == 0
                 ? "the bag was never closed (its header points to no index): a recording stopped "
                   "without closing the bag"
                 : "the bag's index (at byte " + std::to_string(s.index_pos) +
                       ") is past its end: the file was cut short");
  }
  return {};
}

}  // namespace imucal::log::rosbag
