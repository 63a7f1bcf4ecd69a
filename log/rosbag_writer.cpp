// SPDX-License-Identifier: BSD-3-Clause
// BagWriter: a ROS 1 bag 2.0 with its index, as rosbag writes one (log/rosbag.hpp).

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "log/rosbag.hpp"
#include "log/rosbag_format.hpp"

namespace imucal::log::rosbag {

using format::FieldWriter;

namespace {

struct ChunkInfo {
  std::uint64_t position = 0;
  TimeNs start_ns = 0, end_ns = 0;
  std::map<std::uint32_t, std::uint32_t> counts;
};

const char* compression_name(ChunkCompression c) {
  switch (c) {
    case ChunkCompression::kBz2:
      return "bz2";
    case ChunkCompression::kLz4:
      return "lz4";
    case ChunkCompression::kNone:
      break;
  }
  return "none";
}

std::vector<std::uint8_t> connection_record(const Connection& c) {
  FieldWriter data;
  data.add("topic", c.topic)
      .add("type", c.type)
      .add("md5sum", c.md5sum)
      .add("message_definition", c.definition);
  FieldWriter header;
  header.add_op(format::kOpConnection).add_u32("conn", c.id).add("topic", c.topic);
  std::vector<std::uint8_t> out;
  format::append_record(out, header.bytes(), data.bytes());
  return out;
}

}  // namespace

struct BagWriter::State {
  std::string path;
  int fd = -1;
  std::string compression;
  std::size_t chunk_bytes = 0;
  std::uint64_t position = 0;  // bytes written
  std::vector<Connection> connections;
  std::vector<bool> declared;  // a connection's record has gone into a chunk
  std::vector<std::uint8_t> chunk;
  std::map<std::uint32_t, std::vector<std::pair<TimeNs, std::uint32_t>>> chunk_index;
  ChunkInfo current;
  std::vector<ChunkInfo> chunks;
  bool closed = false;

  ~State() {
    if (fd >= 0) ::close(fd);
  }

  Status put(std::span<const std::uint8_t> bytes) {
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        return make_error(Errc::kIo, "writing " + path + ": " + std::strerror(errno));
      }
      done += static_cast<std::size_t>(n);
    }
    position += bytes.size();
    return {};
  }

  std::vector<std::uint8_t> bag_header(std::uint64_t index_pos) const {
    FieldWriter h;
    h.add_op(format::kOpBagHeader)
        .add_u64("index_pos", index_pos)
        .add_u32("conn_count", static_cast<std::uint32_t>(connections.size()))
        .add_u32("chunk_count", static_cast<std::uint32_t>(chunks.size()));
    const std::size_t padding = format::kBagHeaderRecordBytes - 8 - h.bytes().size();
    std::vector<std::uint8_t> out;
    format::append_record(out, h.bytes(), std::vector<std::uint8_t>(padding, ' '));
    return out;
  }

  Status flush_chunk() {
    if (chunk.empty()) return {};
    auto data = format::compress(compression, chunk);
    if (!data.ok()) return data.error();
    current.position = position;
    FieldWriter h;
    h.add_op(format::kOpChunk)
        .add("compression", compression)
        .add_u32("size", static_cast<std::uint32_t>(chunk.size()));
    std::vector<std::uint8_t> out;
    format::append_record(out, h.bytes(), *data);
    for (const auto& [conn, entries] : chunk_index) {
      FieldWriter ih;
      ih.add_op(format::kOpIndex)
          .add_u32("ver", 1)
          .add_u32("conn", conn)
          .add_u32("count", static_cast<std::uint32_t>(entries.size()));
      std::vector<std::uint8_t> idata;
      for (const auto& [t, offset] : entries) {
        format::put64(idata, format::ros_time(t));
        format::put32(idata, offset);
      }
      format::append_record(out, ih.bytes(), idata);
      current.counts[conn] = static_cast<std::uint32_t>(entries.size());
    }
    IMUCAL_TRY(put(out));
    chunks.push_back(current);
    current = {};
    chunk.clear();
    chunk_index.clear();
    return {};
  }
};

BagWriter::BagWriter(std::unique_ptr<State> state) : state_(std::move(state)) {}

BagWriter::~BagWriter() = default;

Result<std::unique_ptr<BagWriter>> BagWriter::create(const std::string& path, ChunkCompression compression,
                                                     std::size_t chunk_bytes) {
  auto s = std::make_unique<State>();
  s->path = path;
  s->compression = compression_name(compression);
  s->chunk_bytes = std::max<std::size_t>(chunk_bytes, 1);
  s->fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (s->fd < 0) {
    return make_error(errno == EEXIST ? Errc::kAlreadyExists : Errc::kIo, path + ": " + std::strerror(errno));
  }
  const std::string_view magic = format::kMagic;
  IMUCAL_TRY(s->put(std::span(reinterpret_cast<const std::uint8_t*>(magic.data()), magic.size())));
  IMUCAL_TRY(s->put(s->bag_header(0)));  // index_pos 0 until close(): a bag not closed says so
  return std::unique_ptr<BagWriter>(new BagWriter(std::move(s)));
}

Result<std::uint32_t> BagWriter::add_connection(const std::string& topic, const std::string& type) {
  State& s = *state_;
  if (*message_md5sum(type) == '\0') {
    return make_error(Errc::kInvalidArgument, "no message type " + type + " (" + kImuType + ", " +
                                                  kImageType + ", " + kCompressedImageType + ")");
  }
  Connection c;
  c.id = static_cast<std::uint32_t>(s.connections.size());
  c.topic = topic;
  c.type = type;
  c.md5sum = message_md5sum(type);
  c.definition = message_definition(type);
  s.connections.push_back(c);
  s.declared.push_back(false);
  return c.id;
}

Status BagWriter::write(std::uint32_t connection, TimeNs receive_ns, std::span<const std::uint8_t> data) {
  State& s = *state_;
  if (s.closed) return make_error(Errc::kInternal, "a message written to a closed bag");
  if (connection >= s.connections.size())
    return make_error(Errc::kInternal, "a message of an undeclared connection");
  if (!s.declared[connection]) {
    const auto record = connection_record(s.connections[connection]);
    s.chunk.insert(s.chunk.end(), record.begin(), record.end());
    s.declared[connection] = true;
  }
  if (s.chunk_index.empty() && s.current.counts.empty()) s.current.start_ns = s.current.end_ns = receive_ns;
  s.current.start_ns = std::min(s.current.start_ns, receive_ns);
  s.current.end_ns = std::max(s.current.end_ns, receive_ns);
  s.chunk_index[connection].emplace_back(receive_ns, static_cast<std::uint32_t>(s.chunk.size()));
  FieldWriter h;
  h.add_op(format::kOpMessage).add_u32("conn", connection).add_u64("time", format::ros_time(receive_ns));
  format::append_record(s.chunk, h.bytes(), data);
  if (s.chunk.size() >= s.chunk_bytes) return s.flush_chunk();
  return {};
}

Status BagWriter::close() {
  State& s = *state_;
  if (s.closed) return {};
  IMUCAL_TRY(s.flush_chunk());
  const std::uint64_t index_pos = s.position;
  std::vector<std::uint8_t> out;
  for (const auto& c : s.connections) {
    const auto record = connection_record(c);
    out.insert(out.end(), record.begin(), record.end());
  }
  for (const auto& info : s.chunks) {
    FieldWriter h;
    h.add_op(format::kOpChunkInfo)
        .add_u32("ver", 1)
        .add_u64("chunk_pos", info.position)
        .add_u64("start_time", format::ros_time(info.start_ns))
        .add_u64("end_time", format::ros_time(info.end_ns))
        .add_u32("count", static_cast<std::uint32_t>(info.counts.size()));
    std::vector<std::uint8_t> data;
    for (const auto& [conn, n] : info.counts) {
      format::put32(data, conn);
      format::put32(data, n);
    }
    format::append_record(out, h.bytes(), data);
  }
  IMUCAL_TRY(s.put(out));
  const auto header = s.bag_header(index_pos);
  if (::pwrite(s.fd, header.data(), header.size(), static_cast<off_t>(format::kMagic.size())) !=
      static_cast<ssize_t>(header.size())) {
    return make_error(Errc::kIo, "writing " + s.path + "'s header: " + std::strerror(errno));
  }
  if (::fsync(s.fd) != 0) return make_error(Errc::kIo, "syncing " + s.path + ": " + std::strerror(errno));
  s.closed = true;
  return {};
}

}  // namespace imucal::log::rosbag
