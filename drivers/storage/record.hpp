// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The calibration record as it lies in one storage slot: a fixed header followed by the payload
// (imucal's calibration as CBOR, app/stored_calibration.hpp; opaque bytes here).
//
// Header, little-endian, 24 bytes (docs/storage.md has the byte table):
//   0  magic "IMCR"            4  format version u16 (1)   6  header length u16 (24)
//   8  sequence u32            12 payload length u32       16 CRC32 of the payload
//   20 CRC32 of header bytes 0..19
// The header CRC is always the header's last four bytes, so a later version with a longer
// header is recognised as such (and refused as unsupported) rather than as damage.
//
// decode_record() accepts exactly what encode_record() produces and nothing else: every check
// names what is wrong, no length is trusted before it is checked against the bytes present, and
// nothing is allocated from an unchecked length.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace imucal::drivers {

inline constexpr std::uint32_t kRecordMagic = 0x52434D49;  // "IMCR" read as little-endian u32
inline constexpr std::uint16_t kRecordVersion = 1;
inline constexpr std::size_t kRecordHeaderBytes = 24;
/// The longest header any version may declare: bounds what a reader looks at.
inline constexpr std::size_t kRecordMaxHeaderBytes = 256;

/// CRC-32 (IEEE 802.3, zlib's crc32: reflected polynomial 0xEDB88320, init and final XOR ~0).
std::uint32_t crc32(std::span<const std::uint8_t> bytes);

struct Record {
  std::uint32_t sequence = 0;
  std::vector<std::uint8_t> payload;
};

/// Why bytes are not a record, in the order decode_record() checks.
enum class RecordDefect {
  kNone,
  kErased,              // the header bytes are all 0xFF (erased EEPROM) or all 0x00 (new file)
  kTruncated,           // fewer bytes than a header, or than the header declares
  kBadMagic,            // not an imucal record
  kBadHeaderLength,     // header length outside 24..256
  kBadHeaderCrc,        // the header is damaged (torn write, bit rot)
  kUnsupportedVersion,  // a record of a format version no imucal writes (0)
  kNewerVersion,        // a record of a newer format version: written by a newer imucal, not damage
  kPayloadTooLong,      // the payload length runs past the bytes present (torn or damaged)
  kBadPayloadCrc,       // the payload is damaged (torn write, bit rot)
};

const char* record_defect_name(RecordDefect defect);

struct DecodedRecord {
  std::optional<Record> record;  // set exactly when defect == kNone
  RecordDefect defect = RecordDefect::kNone;
  std::string reason;  // what is wrong, in words; empty for a valid record
};

/// The bytes of a record: header and payload. The caller checks that it fits its slot.
std::vector<std::uint8_t> encode_record(std::uint32_t sequence, std::span<const std::uint8_t> payload);

/// The record at the start of `bytes` (bytes after it are ignored), or why there is none.
DecodedRecord decode_record(std::span<const std::uint8_t> bytes);

/// From a header alone (at least kRecordHeaderBytes bytes): the bytes the whole record spans
/// when the header is intact (magic, length, header CRC), else nothing. Lets a reader fetch
/// only what a record occupies from a slow device instead of the whole slot.
std::optional<std::size_t> record_extent(std::span<const std::uint8_t> header);

}  // namespace imucal::drivers
