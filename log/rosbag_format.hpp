// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The record layer of ROS 1 bags 2.0, shared by the reader and the writer (rosbag.hpp): op codes,
// little-endian integers and the "name=value" header fields.

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::log::rosbag::format {

inline constexpr std::string_view kMagic = "#ROSBAG V2.0\n";
inline constexpr std::uint8_t kOpMessage = 0x02;
inline constexpr std::uint8_t kOpBagHeader = 0x03;
inline constexpr std::uint8_t kOpIndex = 0x04;
inline constexpr std::uint8_t kOpChunk = 0x05;
inline constexpr std::uint8_t kOpChunkInfo = 0x06;
inline constexpr std::uint8_t kOpConnection = 0x07;
/// The bag header record is padded to this many bytes, so that close() can rewrite it in place.
inline constexpr std::size_t kBagHeaderRecordBytes = 4096;

inline std::uint32_t le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
inline std::uint64_t le64(const std::uint8_t* p) {
  return static_cast<std::uint64_t>(le32(p)) | (static_cast<std::uint64_t>(le32(p + 4)) << 32);
}
inline void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void put64(std::vector<std::uint8_t>& out, std::uint64_t v) {
  put32(out, static_cast<std::uint32_t>(v));
  put32(out, static_cast<std::uint32_t>(v >> 32));
}

/// A ROS time (uint32 seconds, then uint32 nanoseconds) as it is stored: 8 bytes.
std::uint64_t ros_time(TimeNs t_ns);
/// The stored form back to ns; kCorrupt when the nanoseconds are 1e9 or more.
[[nodiscard]] Result<TimeNs> time_ns(std::uint64_t stored);

/// A message header's stamp in ns (ROS 1: uint32 seconds; ROS 2: int32). Nanoseconds of 1e9 or
/// more are the time they add up to: ROS 2's own test bags (rosbag2_py) hold (0 s, 1e9 ns) for 1 s.
inline TimeNs header_stamp_ns(std::int64_t sec, std::uint32_t nsec) {
  return static_cast<TimeNs>(sec) * 1'000'000'000 + nsec;
}

/// The fields of a record's header.
class Fields {
 public:
  [[nodiscard]] static Result<Fields> parse(std::span<const std::uint8_t> bytes);
  bool has(std::string_view name) const { return fields_.find(name) != fields_.end(); }
  [[nodiscard]] Result<std::uint8_t> op() const;
  [[nodiscard]] Result<std::uint32_t> u32(std::string_view name) const;
  [[nodiscard]] Result<std::uint64_t> u64(std::string_view name) const;
  [[nodiscard]] Result<std::string> text(std::string_view name) const;

 private:
  [[nodiscard]] Result<std::string_view> raw(std::string_view name, std::size_t size) const;
  std::map<std::string, std::string, std::less<>> fields_;
};

/// Builds a header: each field a uint32 length and "name=value".
class FieldWriter {
 public:
  FieldWriter& add(std::string_view name, std::string_view value);
  FieldWriter& add_op(std::uint8_t op);
  FieldWriter& add_u32(std::string_view name, std::uint32_t value);
  FieldWriter& add_u64(std::string_view name, std::uint64_t value);
  const std::vector<std::uint8_t>& bytes() const { return bytes_; }

 private:
  std::vector<std::uint8_t> bytes_;
};

/// A record: header length, header, data length, data.
void append_record(std::vector<std::uint8_t>& out, const std::vector<std::uint8_t>& header,
                   std::span<const std::uint8_t> data);

/// A record found in memory (inside a chunk).
struct RecordView {
  Fields fields;
  std::span<const std::uint8_t> data;
};
/// Every record of a chunk's uncompressed data; kCorrupt naming the byte where it breaks.
[[nodiscard]] Result<std::vector<RecordView>> parse_records(std::span<const std::uint8_t> bytes);

/// A chunk's data uncompressed: "none", "bz2" or "lz4" (kUnsupported for another name, kCorrupt
/// when the data do not decompress to exactly `size` bytes).
[[nodiscard]] Result<std::vector<std::uint8_t>> decompress(const std::string& compression,
                                                           std::span<const std::uint8_t> data,
                                                           std::uint64_t size);
/// The inverse, for the writer.
[[nodiscard]] Result<std::vector<std::uint8_t>> compress(const std::string& compression,
                                                         std::span<const std::uint8_t> data);

}  // namespace imucal::log::rosbag::format
