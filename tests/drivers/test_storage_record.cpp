// SPDX-License-Identifier: BSD-3-Clause
// The calibration record (drivers/storage/record.hpp): encode/decode round trip, and every
// header field corrupted is refused with its own reason.

#include <gtest/gtest.h>

#include <cstring>
#include <numeric>
#include <vector>

#include "drivers/storage/record.hpp"

namespace imucal::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes payload_of(std::size_t n) {
  Bytes p(n);
  std::iota(p.begin(), p.end(), std::uint8_t{7});
  return p;
}

void put_u32(Bytes& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// Recomputes the header CRC so that a corrupted field is seen by its own check, not the CRC's.
void reseal_header(Bytes& b) { put_u32(b, 20, crc32(std::span<const std::uint8_t>(b).first(20))); }

TEST(StorageRecord, Crc32MatchesTheStandardCheckValue) {
  const char* text = "123456789";
  const std::span<const std::uint8_t> bytes(reinterpret_cast<const std::uint8_t*>(text), 9);
  EXPECT_EQ(crc32(bytes), 0xCBF43926u);  // the CRC-32/ISO-HDLC check value
}

TEST(StorageRecord, RoundTripsAndIgnoresTrailingBytes) {
  for (std::size_t n : {0u, 1u, 100u, 3000u}) {
    const Bytes payload = payload_of(n);
    Bytes bytes = encode_record(42, payload);
    ASSERT_EQ(bytes.size(), kRecordHeaderBytes + n);
    EXPECT_EQ(std::memcmp(bytes.data(), "IMCR", 4), 0);
    bytes.insert(bytes.end(), 17, 0xFF);  // the rest of a slot
    const DecodedRecord d = decode_record(bytes);
    ASSERT_TRUE(d.record) << d.reason;
    EXPECT_EQ(d.defect, RecordDefect::kNone);
    EXPECT_EQ(d.record->sequence, 42u);
    EXPECT_EQ(d.record->payload, payload);
    EXPECT_EQ(record_extent(bytes), kRecordHeaderBytes + n);
  }
}

TEST(StorageRecord, ErasedAndShortInputsAreNotRecords) {
  EXPECT_EQ(decode_record(Bytes(64, 0xFF)).defect, RecordDefect::kErased);
  EXPECT_EQ(decode_record(Bytes(64, 0x00)).defect, RecordDefect::kErased);
  EXPECT_EQ(decode_record(Bytes{}).defect, RecordDefect::kTruncated);
  const Bytes bytes = encode_record(1, payload_of(10));
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const DecodedRecord d = decode_record(std::span<const std::uint8_t>(bytes).first(n));
    EXPECT_FALSE(d.record) << "prefix of " << n << " bytes accepted";
    EXPECT_FALSE(d.reason.empty());
  }
}

struct FieldCase {
  const char* field;
  std::size_t at;
  std::uint32_t value;
  int width;
  bool reseal;
  RecordDefect expected;
  const char* reason_part;
};

TEST(StorageRecord, EveryCorruptedHeaderFieldIsRejectedWithItsReason) {
  const FieldCase cases[] = {
      {"magic", 0, 0x41424344, 4, true, RecordDefect::kBadMagic, "magic"},
      {"version", 4, 2, 2, true, RecordDefect::kNewerVersion, "format version 2, written by a newer imucal"},
      {"version 0", 4, 0, 2, true, RecordDefect::kUnsupportedVersion, "format version 0"},
      {"version (unsealed)", 4, 2, 2, false, RecordDefect::kBadHeaderCrc, "header CRC32"},
      {"header length (too small)", 6, 8, 2, true, RecordDefect::kBadHeaderLength, "header length 8"},
      {"header length (too large)", 6, 4000, 2, true, RecordDefect::kBadHeaderLength, "header length 4000"},
      {"sequence", 8, 43, 4, false, RecordDefect::kBadHeaderCrc, "header CRC32"},
      {"payload length (long)", 12, 0x7FFFFFFF, 4, true, RecordDefect::kPayloadTooLong, "runs past"},
      {"payload length (short)", 12, 5, 4, true, RecordDefect::kBadPayloadCrc, "payload CRC32"},
      {"payload length (unsealed)", 12, 5, 4, false, RecordDefect::kBadHeaderCrc, "header CRC32"},
      {"payload CRC", 16, 0x12345678, 4, true, RecordDefect::kBadPayloadCrc, "payload CRC32"},
      {"header CRC", 20, 0x12345678, 4, false, RecordDefect::kBadHeaderCrc, "header CRC32"},
  };
  const Bytes good = encode_record(42, payload_of(64));
  for (const auto& c : cases) {
    Bytes b = good;
    for (int i = 0; i < c.width; ++i) b[c.at + i] = static_cast<std::uint8_t>(c.value >> (8 * i));
    if (c.reseal) reseal_header(b);
    const DecodedRecord d = decode_record(b);
    EXPECT_FALSE(d.record) << c.field;
    EXPECT_EQ(d.defect, c.expected) << c.field << ": " << d.reason;
    EXPECT_NE(d.reason.find(c.reason_part), std::string::npos) << c.field << ": " << d.reason;
  }
}

TEST(StorageRecord, EverySingleBitFlipIsDetected) {
  const Bytes good = encode_record(9, payload_of(40));
  for (std::size_t byte = 0; byte < good.size(); ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      Bytes b = good;
      b[byte] ^= static_cast<std::uint8_t>(1u << bit);
      EXPECT_FALSE(decode_record(b).record) << "flip of byte " << byte << " bit " << bit << " accepted";
    }
  }
}

TEST(StorageRecord, ALongerHeaderOfALaterVersionIsNewerNotDamaged) {
  // Version 2 with a 32-byte header: the header CRC sits in its last four bytes.
  Bytes b = encode_record(3, payload_of(8));
  b.insert(b.begin() + 20, 8, 0);
  b[4] = 2;
  b[6] = 32;
  put_u32(b, 28, crc32(std::span<const std::uint8_t>(b).first(28)));
  const DecodedRecord d = decode_record(b);
  EXPECT_EQ(d.defect, RecordDefect::kNewerVersion) << d.reason;
  EXPECT_NE(d.reason.find("written by a newer imucal"), std::string::npos) << d.reason;
}

}  // namespace
}  // namespace imucal::drivers
