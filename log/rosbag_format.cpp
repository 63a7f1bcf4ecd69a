// SPDX-License-Identifier: BSD-3-Clause
#include "log/rosbag_format.hpp"

#include <bzlib.h>
#include <lz4frame.h>

#include <climits>
#include <cstring>
#include <memory>

namespace imucal::log::rosbag::format {

std::uint64_t ros_time(TimeNs t_ns) {
  const auto ns = static_cast<std::uint64_t>(t_ns);
  const std::uint64_t sec = ns / 1'000'000'000ULL;
  const std::uint64_t nsec = ns % 1'000'000'000ULL;
  return (sec & 0xffffffffULL) | (nsec << 32);
}

Result<TimeNs> time_ns(std::uint64_t stored) {
  const std::uint64_t sec = stored & 0xffffffffULL;
  const std::uint64_t nsec = stored >> 32;
  if (nsec >= 1'000'000'000ULL) {
    return make_error(Errc::kCorrupt,
                      "a time with " + std::to_string(nsec) + " nanoseconds (at most 999999999)");
  }
  return static_cast<TimeNs>(sec * 1'000'000'000ULL + nsec);
}

Result<Fields> Fields::parse(std::span<const std::uint8_t> bytes) {
  Fields out;
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    if (bytes.size() - pos < 4) return make_error(Errc::kCorrupt, "a header field's length is cut short");
    const std::uint32_t len = le32(bytes.data() + pos);
    pos += 4;
    if (len > bytes.size() - pos) {
      return make_error(Errc::kCorrupt, "a header field of " + std::to_string(len) +
                                            " bytes in a header of " + std::to_string(bytes.size()));
    }
    const std::string_view field(reinterpret_cast<const char*>(bytes.data() + pos), len);
    pos += len;
    const std::size_t eq = field.find('=');
    if (eq == std::string_view::npos || eq == 0)
      return make_error(Errc::kCorrupt, "a header field without a name");
    out.fields_.insert_or_assign(std::string(field.substr(0, eq)), std::string(field.substr(eq + 1)));
  }
  return out;
}

Result<std::string_view> Fields::raw(std::string_view name, std::size_t size) const {
  auto it = fields_.find(name);
  if (it == fields_.end())
    return make_error(Errc::kCorrupt, "a record without its field '" + std::string(name) + "'");
  if (size != 0 && it->second.size() != size) {
    return make_error(Errc::kCorrupt, "the field '" + std::string(name) + "' has " +
                                          std::to_string(it->second.size()) + " bytes, not " +
                                          std::to_string(size));
  }
  return std::string_view(it->second);
}

Result<std::uint8_t> Fields::op() const {
  auto v = raw("op", 1);
  if (!v.ok()) return v.error();
  return static_cast<std::uint8_t>((*v)[0]);
}

Result<std::uint32_t> Fields::u32(std::string_view name) const {
  auto v = raw(name, 4);
  if (!v.ok()) return v.error();
  return le32(reinterpret_cast<const std::uint8_t*>(v->data()));
}

Result<std::uint64_t> Fields::u64(std::string_view name) const {
  auto v = raw(name, 8);
  if (!v.ok()) return v.error();
  return le64(reinterpret_cast<const std::uint8_t*>(v->data()));
}

Result<std::string> Fields::text(std::string_view name) const {
  auto v = raw(name, 0);
  if (!v.ok()) return v.error();
  return std::string(*v);
}

FieldWriter& FieldWriter::add(std::string_view name, std::string_view value) {
  put32(bytes_, static_cast<std::uint32_t>(name.size() + 1 + value.size()));
  bytes_.insert(bytes_.end(), name.begin(), name.end());
  bytes_.push_back('=');
  bytes_.insert(bytes_.end(), value.begin(), value.end());
  return *this;
}

FieldWriter& FieldWriter::add_op(std::uint8_t op) {
  const char c = static_cast<char>(op);
  return add("op", std::string_view(&c, 1));
}

FieldWriter& FieldWriter::add_u32(std::string_view name, std::uint32_t value) {
  std::vector<std::uint8_t> v;
  put32(v, value);
  return add(name, std::string_view(reinterpret_cast<const char*>(v.data()), v.size()));
}

FieldWriter& FieldWriter::add_u64(std::string_view name, std::uint64_t value) {
  std::vector<std::uint8_t> v;
  put64(v, value);
  return add(name, std::string_view(reinterpret_cast<const char*>(v.data()), v.size()));
}

void append_record(std::vector<std::uint8_t>& out, const std::vector<std::uint8_t>& header,
                   std::span<const std::uint8_t> data) {
  put32(out, static_cast<std::uint32_t>(header.size()));
  out.insert(out.end(), header.begin(), header.end());
  put32(out, static_cast<std::uint32_t>(data.size()));
  out.insert(out.end(), data.begin(), data.end());
}

Result<std::vector<RecordView>> parse_records(std::span<const std::uint8_t> bytes) {
  std::vector<RecordView> out;
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    const std::size_t start = pos;
    auto broken = [&](const std::string& what) {
      return make_error(Errc::kCorrupt, "the record at byte " + std::to_string(start) + " of the chunk's " +
                                            std::to_string(bytes.size()) + ": " + what);
    };
    if (bytes.size() - pos < 4) return broken("its header length is cut short");
    const std::uint32_t header_len = le32(bytes.data() + pos);
    pos += 4;
    if (header_len > bytes.size() - pos || bytes.size() - pos - header_len < 4) {
      return broken("a header of " + std::to_string(header_len) + " bytes runs past the chunk's end");
    }
    auto fields = Fields::parse(bytes.subspan(pos, header_len));
    if (!fields.ok()) return broken(fields.error().message);
    pos += header_len;
    const std::uint32_t data_len = le32(bytes.data() + pos);
    pos += 4;
    if (data_len > bytes.size() - pos) {
      return broken("its data of " + std::to_string(data_len) + " bytes run past the chunk's end");
    }
    out.push_back({std::move(*fields), bytes.subspan(pos, data_len)});
    pos += data_len;
  }
  return out;
}

namespace {

Result<std::vector<std::uint8_t>> bz2_decompress(std::span<const std::uint8_t> data, std::uint64_t size) {
  std::vector<std::uint8_t> out(size);
  if (data.size() > UINT_MAX || size > UINT_MAX) {
    return make_error(Errc::kCorrupt, "a bz2 chunk of more than 4 GB");
  }
  auto dest_len = static_cast<unsigned int>(size);
  // bzlib's buffer interface takes non-const pointers but does not write the source.
  const int rc = BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(out.data()), &dest_len,
                                            const_cast<char*>(reinterpret_cast<const char*>(data.data())),
                                            static_cast<unsigned int>(data.size()), 0, 0);
  if (rc != BZ_OK) {
    return make_error(Errc::kCorrupt,
                      "its bz2 data do not decompress (bzlib error " + std::to_string(rc) + ")");
  }
  if (dest_len != size) {
    return make_error(Errc::kCorrupt, "its bz2 data decompress to " + std::to_string(dest_len) +
                                          " bytes, where the chunk says " + std::to_string(size));
  }
  return out;
}

struct Lz4Context {
  LZ4F_dctx* ctx = nullptr;
  ~Lz4Context() { LZ4F_freeDecompressionContext(ctx); }
};

Result<std::vector<std::uint8_t>> lz4_decompress(std::span<const std::uint8_t> data, std::uint64_t size) {
  Lz4Context c;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&c.ctx, LZ4F_VERSION))) {
    return make_error(Errc::kInternal, "liblz4 could not make a decompression context");
  }
  std::vector<std::uint8_t> out(size);
  std::size_t done = 0, used = 0;
  for (;;) {
    std::size_t dst = out.size() - done;
    std::size_t src = data.size() - used;
    const std::size_t rc = LZ4F_decompress(c.ctx, out.data() + done, &dst, data.data() + used, &src, nullptr);
    if (LZ4F_isError(rc)) {
      return make_error(Errc::kCorrupt,
                        std::string("its lz4 data do not decompress (") + LZ4F_getErrorName(rc) + ")");
    }
    done += dst;
    used += src;
    if (rc == 0) break;          // the frame is whole
    if (dst == 0 && src == 0) {  // no progress: the data end inside the frame, or `out` is full
      return make_error(Errc::kCorrupt,
                        "its lz4 data end inside their frame or hold more than the chunk says (" +
                            std::to_string(size) + " bytes)");
    }
  }
  if (done != size) {
    return make_error(Errc::kCorrupt, "its lz4 data decompress to " + std::to_string(done) +
                                          " bytes, where the chunk says " + std::to_string(size));
  }
  return out;
}

}  // namespace

Result<std::vector<std::uint8_t>> decompress(const std::string& compression,
                                             std::span<const std::uint8_t> data, std::uint64_t size) {
  if (compression == "none") {
    if (data.size() != size) {
      return make_error(Errc::kCorrupt, "it holds " + std::to_string(data.size()) + " bytes, where it says " +
                                            std::to_string(size));
    }
    return std::vector<std::uint8_t>(data.begin(), data.end());
  }
  if (compression == "bz2") return bz2_decompress(data, size);
  if (compression == "lz4") return lz4_decompress(data, size);
  return make_error(Errc::kUnsupported, "its compression '" + compression + "' is none of none, bz2 and lz4");
}

Result<std::vector<std::uint8_t>> compress(const std::string& compression,
                                           std::span<const std::uint8_t> data) {
  if (compression == "none") return std::vector<std::uint8_t>(data.begin(), data.end());
  if (compression == "bz2") {
    if (data.size() > UINT_MAX / 2)
      return make_error(Errc::kInvalidArgument, "a bz2 chunk of more than 2 GB");
    auto len = static_cast<unsigned int>(data.size() + data.size() / 100 + 600);
    std::vector<std::uint8_t> out(len);
    const int rc = BZ2_bzBuffToBuffCompress(reinterpret_cast<char*>(out.data()), &len,
                                            const_cast<char*>(reinterpret_cast<const char*>(data.data())),
                                            static_cast<unsigned int>(data.size()), 9, 0, 30);
    if (rc != BZ_OK)
      return make_error(Errc::kInternal, "bzlib could not compress a chunk (" + std::to_string(rc) + ")");
    out.resize(len);
    return out;
  }
  if (compression == "lz4") {
    // What roslz4 (ROS's reader) accepts: independent blocks, a content checksum, no content size.
    LZ4F_preferences_t prefs{};
    prefs.frameInfo.blockSizeID = LZ4F_max64KB;
    prefs.frameInfo.blockMode = LZ4F_blockIndependent;
    prefs.frameInfo.contentChecksumFlag = LZ4F_contentChecksumEnabled;
    std::vector<std::uint8_t> out(LZ4F_compressFrameBound(data.size(), &prefs));
    const std::size_t rc = LZ4F_compressFrame(out.data(), out.size(), data.data(), data.size(), &prefs);
    if (LZ4F_isError(rc)) {
      return make_error(Errc::kInternal,
                        std::string("liblz4 could not compress a chunk: ") + LZ4F_getErrorName(rc));
    }
    out.resize(rc);
    return out;
  }
  return make_error(Errc::kInvalidArgument, "no chunk compression '" + compression + "' (none, bz2, lz4)");
}

}  // namespace imucal::log::rosbag::format
