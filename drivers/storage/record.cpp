// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/storage/record.hpp"

#include <zlib.h>

#include <algorithm>
#include <climits>
#include <cstdio>

namespace imucal::drivers {
namespace {

std::uint32_t get_u32(std::span<const std::uint8_t> b, std::size_t at) {
  return static_cast<std::uint32_t>(b[at]) | static_cast<std::uint32_t>(b[at + 1]) << 8 |
         static_cast<std::uint32_t>(b[at + 2]) << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
}

std::uint16_t get_u16(std::span<const std::uint8_t> b, std::size_t at) {
  return static_cast<std::uint16_t>(b[at] | b[at + 1] << 8);
}

void put_u32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

void put_u16(std::vector<std::uint8_t>& b, std::size_t at, std::uint16_t v) {
  b[at] = static_cast<std::uint8_t>(v);
  b[at + 1] = static_cast<std::uint8_t>(v >> 8);
}

DecodedRecord defect(RecordDefect d, std::string reason) { return {std::nullopt, d, std::move(reason)}; }

std::string hex32(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08X", v);
  return buf;
}

// Checks what a header must satisfy before any of its lengths may be used: the header length
// and the header CRC. Returns kNone with `header_len` set, or the defect.
RecordDefect check_header(std::span<const std::uint8_t> b, std::size_t& header_len, std::string& reason) {
  if (b.size() < kRecordHeaderBytes) {
    reason = "only " + std::to_string(b.size()) + " bytes, fewer than a record header (" +
             std::to_string(kRecordHeaderBytes) + ")";
    return RecordDefect::kTruncated;
  }
  const auto head = b.first(kRecordHeaderBytes);
  if (std::all_of(head.begin(), head.end(), [](std::uint8_t x) { return x == 0xFF; }) ||
      std::all_of(head.begin(), head.end(), [](std::uint8_t x) { return x == 0x00; })) {
    reason = "erased (no record was ever written here)";
    return RecordDefect::kErased;
  }
  if (const std::uint32_t magic = get_u32(b, 0); magic != kRecordMagic) {
    reason = "magic " + hex32(magic) + " is not an imucal calibration record (" + hex32(kRecordMagic) + ")";
    return RecordDefect::kBadMagic;
  }
  header_len = get_u16(b, 6);
  if (header_len < kRecordHeaderBytes || header_len > kRecordMaxHeaderBytes) {
    reason = "header length " + std::to_string(header_len) + " is outside " +
             std::to_string(kRecordHeaderBytes) + ".." + std::to_string(kRecordMaxHeaderBytes) +
             " (damaged header)";
    return RecordDefect::kBadHeaderLength;
  }
  if (header_len > b.size()) {
    reason = "the header declares " + std::to_string(header_len) + " bytes, only " +
             std::to_string(b.size()) + " are present";
    return RecordDefect::kTruncated;
  }
  const std::uint32_t stored = get_u32(b, header_len - 4);
  const std::uint32_t computed = crc32(b.first(header_len - 4));
  if (stored != computed) {
    reason = "header CRC32 " + hex32(stored) + " does not match its bytes (" + hex32(computed) +
             "): the header is damaged or was torn by an interrupted write";
    return RecordDefect::kBadHeaderCrc;
  }
  return RecordDefect::kNone;
}

}  // namespace

std::uint32_t crc32(std::span<const std::uint8_t> bytes) {
  // zlib's crc32 takes a uInt length; records are far below 4 GiB, but feed it in bounded
  // pieces so the conversion can never truncate.
  uLong crc = ::crc32(0L, Z_NULL, 0);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const std::size_t n = std::min<std::size_t>(bytes.size() - done, UINT_MAX);
    crc = ::crc32(crc, bytes.data() + done, static_cast<uInt>(n));
    done += n;
  }
  return static_cast<std::uint32_t>(crc);
}

const char* record_defect_name(RecordDefect d) {
  switch (d) {
    case RecordDefect::kNone:
      return "valid";
    case RecordDefect::kErased:
      return "erased";
    case RecordDefect::kTruncated:
      return "truncated";
    case RecordDefect::kBadMagic:
      return "bad magic";
    case RecordDefect::kBadHeaderLength:
      return "bad header length";
    case RecordDefect::kBadHeaderCrc:
      return "bad header CRC";
    case RecordDefect::kUnsupportedVersion:
      return "unsupported version";
    case RecordDefect::kNewerVersion:
      return "newer version";
    case RecordDefect::kPayloadTooLong:
      return "payload too long";
    case RecordDefect::kBadPayloadCrc:
      return "bad payload CRC";
  }
  return "?";
}

std::vector<std::uint8_t> encode_record(std::uint32_t sequence, std::span<const std::uint8_t> payload) {
  std::vector<std::uint8_t> out(kRecordHeaderBytes + payload.size());
  put_u32(out, 0, kRecordMagic);
  put_u16(out, 4, kRecordVersion);
  put_u16(out, 6, static_cast<std::uint16_t>(kRecordHeaderBytes));
  put_u32(out, 8, sequence);
  put_u32(out, 12, static_cast<std::uint32_t>(payload.size()));
  put_u32(out, 16, crc32(payload));
  put_u32(out, 20, crc32(std::span<const std::uint8_t>(out).first(20)));
  std::copy(payload.begin(), payload.end(), out.begin() + kRecordHeaderBytes);
  return out;
}

std::optional<std::size_t> record_extent(std::span<const std::uint8_t> header) {
  std::size_t header_len = 0;
  std::string reason;
  if (check_header(header, header_len, reason) != RecordDefect::kNone) return std::nullopt;
  // A header length other than version 1's means another version: decode_record says so.
  if (header_len != kRecordHeaderBytes) return header_len;
  return header_len + get_u32(header, 12);
}

DecodedRecord decode_record(std::span<const std::uint8_t> b) {
  std::size_t header_len = 0;
  std::string reason;
  if (const RecordDefect d = check_header(b, header_len, reason); d != RecordDefect::kNone) {
    return defect(d, std::move(reason));
  }
  if (const std::uint16_t version = get_u16(b, 4); version > kRecordVersion) {
    return defect(RecordDefect::kNewerVersion,
                  "format version " + std::to_string(version) +
                      ", written by a newer imucal (this one reads "
                      "version " +
                      std::to_string(kRecordVersion) +
                      "): not damage; read it with that imucal, or update this one");
  } else if (version != kRecordVersion) {
    return defect(RecordDefect::kUnsupportedVersion,
                  "format version " + std::to_string(version) + ", this imucal reads version " +
                      std::to_string(kRecordVersion) +
                      ": use the imucal that wrote it, or write a new record");
  }
  if (header_len != kRecordHeaderBytes) {
    return defect(RecordDefect::kBadHeaderLength, "header length " + std::to_string(header_len) +
                                                      ", format version 1 has " +
                                                      std::to_string(kRecordHeaderBytes));
  }
  const std::uint32_t payload_len = get_u32(b, 12);
  if (payload_len > b.size() - header_len) {
    return defect(RecordDefect::kPayloadTooLong,
                  "payload length " + std::to_string(payload_len) + " runs past the " +
                      std::to_string(b.size() - header_len) + " bytes after the header");
  }
  const auto payload = b.subspan(header_len, payload_len);
  const std::uint32_t stored = get_u32(b, 16);
  if (const std::uint32_t computed = crc32(payload); stored != computed) {
    return defect(RecordDefect::kBadPayloadCrc,
                  "payload CRC32 " + hex32(stored) + " does not match its " + std::to_string(payload_len) +
                      " bytes (" + hex32(computed) +
                      "): the payload is damaged or was torn by an interrupted write");
  }
  Record r;
  r.sequence = get_u32(b, 8);
  r.payload.assign(payload.begin(), payload.end());
  return {std::move(r), RecordDefect::kNone, {}};
}

}  // namespace imucal::drivers
