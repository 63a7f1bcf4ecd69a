// SPDX-License-Identifier: BSD-3-Clause
// The A/B calibration store (drivers/storage/calibration_store.hpp) on the in-memory device with
// fault injection: alternation, a power cut at every byte of a write (with and without torn
// bytes after the cut), read-back mismatches, and payloads that do not fit.

#include <gtest/gtest.h>

#include <numeric>
#include <vector>

#include "drivers/storage/calibration_store.hpp"
#include "drivers/storage/fake/memory_storage.hpp"

namespace imucal::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes payload(std::uint8_t tag, std::size_t n) {
  Bytes p(n);
  std::iota(p.begin(), p.end(), tag);
  return p;
}

CalibrationStore open_store(MemoryStorage& dev, std::uint64_t offset, std::uint64_t size) {
  auto s = CalibrationStore::open(dev, offset, size);
  EXPECT_TRUE(s.ok()) << s.error().message;
  return std::move(s).value();
}

TEST(StorageStore, EmptyDeviceHasNoRecordAndThatIsNotAnError) {
  for (std::uint8_t fill : {0x00, 0xFF}) {
    MemoryStorage dev(512, fill);
    auto store = open_store(dev, 0, 512);
    auto latest = store.read_latest();
    ASSERT_TRUE(latest.ok()) << latest.error().message;
    EXPECT_FALSE(latest->record);
    EXPECT_EQ(latest->slot, -1);
    for (const auto& s : latest->slots) EXPECT_EQ(s.defect, RecordDefect::kErased);
  }
}

TEST(StorageStore, WritesAlternateBetweenSlotsWithRisingSequence) {
  MemoryStorage dev(1024);
  auto store = open_store(dev, 128, 512);  // an offset inside the device
  for (int i = 0; i < 5; ++i) {
    const Bytes p = payload(static_cast<std::uint8_t>(i), 50 + static_cast<std::size_t>(i));
    auto w = store.write(p);
    ASSERT_TRUE(w.ok()) << w.error().message;
    EXPECT_EQ(w->slot, i % 2);
    EXPECT_EQ(w->sequence, static_cast<std::uint32_t>(i + 1));
    auto latest = store.read_latest();
    ASSERT_TRUE(latest.ok());
    ASSERT_TRUE(latest->record);
    EXPECT_EQ(latest->record->payload, p);
    EXPECT_EQ(latest->slot, i % 2);
    if (i > 0) {
      auto slots = store.inspect();
      ASSERT_TRUE(slots.ok());
      EXPECT_TRUE((*slots)[0].valid && (*slots)[1].valid);
      EXPECT_EQ((*slots)[static_cast<std::size_t>(1 - i % 2)].sequence, static_cast<std::uint32_t>(i));
    }
  }
  EXPECT_EQ(dev.syncs(), 5);
  // Nothing outside the region was touched.
  for (std::size_t b = 0; b < 128; ++b) ASSERT_EQ(dev.bytes()[b], 0xFF);
  for (std::size_t b = 640; b < 1024; ++b) ASSERT_EQ(dev.bytes()[b], 0xFF);
}

TEST(StorageStore, WritesGoToTheInvalidSlotAndKeepTheValidOne) {
  MemoryStorage dev(512);
  auto store = open_store(dev, 0, 512);
  ASSERT_TRUE(store.write(payload(1, 30)).ok());   // A, seq 1
  ASSERT_TRUE(store.write(payload(2, 30)).ok());   // B, seq 2
  dev.bytes()[store.slot_offset(1) + 30] ^= 0x01;  // B's payload damaged
  auto latest = store.read_latest();
  ASSERT_TRUE(latest.ok() && latest->record);
  EXPECT_EQ(latest->slot, 0);
  EXPECT_EQ(latest->slots[1].defect, RecordDefect::kBadPayloadCrc);
  auto w = store.write(payload(3, 30));
  ASSERT_TRUE(w.ok());
  EXPECT_EQ(w->slot, 1);
  EXPECT_EQ(w->sequence, 2u);
}

// The heart of the A/B scheme: cut the write of a new record after every byte count, with and
// without torn bytes after the cut, and check that the reader gets the old record or the new
// one, complete, and never nothing.
void cut_everywhere(std::size_t torn_bytes, std::uint8_t torn_value, bool prior_in_target) {
  const Bytes old_p = payload(10, 60), new_p = payload(200, 70);
  const std::size_t record_bytes = kRecordHeaderBytes + new_p.size();
  for (std::size_t cut = 0; cut <= record_bytes; ++cut) {
    MemoryStorage dev(512);
    auto store = open_store(dev, 0, 512);
    // With prior_in_target, the slot being written held an older valid record (seq 1).
    if (prior_in_target) {
      ASSERT_TRUE(store.write(payload(99, 80)).ok());
    }
    ASSERT_TRUE(store.write(old_p).ok());
    const std::uint32_t old_seq = prior_in_target ? 2 : 1;
    dev.cut_next_write(cut, torn_bytes, torn_value);
    auto w = store.write(new_p);
    auto latest = store.read_latest();
    ASSERT_TRUE(latest.ok()) << latest.error().message;
    ASSERT_TRUE(latest->record) << "nothing readable after a cut at byte " << cut;
    const bool got_old = latest->record->payload == old_p && latest->record->sequence == old_seq;
    const bool got_new = latest->record->payload == new_p && latest->record->sequence == old_seq + 1;
    ASSERT_TRUE(got_old || got_new) << "cut at byte " << cut << " (torn " << torn_bytes << ") gave sequence "
                                    << latest->record->sequence;
    // A cut write never reports success, even when every byte arrived before the power went.
    EXPECT_FALSE(w.ok()) << "cut at byte " << cut;
    if (cut < record_bytes) {
      EXPECT_TRUE(got_old) << "cut at byte " << cut;
    }
    // And the next write after the cut lands, keeping what was readable.
    auto again = store.write(new_p);
    ASSERT_TRUE(again.ok()) << again.error().message;
    auto after = store.read_latest();
    ASSERT_TRUE(after.ok() && after->record);
    EXPECT_EQ(after->record->payload, new_p);
  }
}

TEST(StorageStore, ACutAtEveryByteLeavesTheOldOrTheNewRecord) { cut_everywhere(0, 0, false); }
TEST(StorageStore, ACutAtEveryByteOverAnOlderRecord) { cut_everywhere(0, 0, true); }
TEST(StorageStore, ACutWithTornBytesAfterIt) {
  cut_everywhere(8, 0xA5, true);
  cut_everywhere(32, 0xFF, true);
  cut_everywhere(3, 0x00, false);
}

TEST(StorageStore, AReadBackMismatchIsAFailedWrite) {
  MemoryStorage dev(512);
  auto store = open_store(dev, 0, 512);
  ASSERT_TRUE(store.write(payload(1, 40)).ok());
  dev.corrupt_reads_at(store.slot_offset(1) + 30, 0x10);
  auto w = store.write(payload(2, 40));
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.error().code, Errc::kDevice);
  EXPECT_NE(w.error().message.find("read-back differs"), std::string::npos) << w.error().message;
  EXPECT_NE(w.error().message.find("byte 30"), std::string::npos) << w.error().message;
}

TEST(StorageStore, APayloadThatDoesNotFitIsRefusedBeforeWriting) {
  MemoryStorage dev(512);
  auto store = open_store(dev, 0, 512);
  EXPECT_EQ(store.max_payload_bytes(), 256u - kRecordHeaderBytes);
  auto w = store.write(payload(0, 256 - kRecordHeaderBytes + 1));
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.error().code, Errc::kInvalidArgument);
  EXPECT_EQ(dev.writes(), 0);
  EXPECT_TRUE(store.write(payload(0, 256 - kRecordHeaderBytes)).ok());  // exactly full fits
}

TEST(StorageStore, ARegionOutsideTheDeviceIsRefused) {
  MemoryStorage dev(512);
  EXPECT_FALSE(CalibrationStore::open(dev, 256, 512).ok());
  EXPECT_FALSE(CalibrationStore::open(dev, 0, 40).ok());
}

TEST(StorageStore, ANewerVersionIsReportedNotRead) {
  MemoryStorage dev(512);
  auto store = open_store(dev, 0, 512);
  ASSERT_TRUE(store.write(payload(1, 20)).ok());
  Bytes& b = dev.bytes();
  b[4] = 7;  // version 7, header CRC resealed
  const std::uint32_t crc = crc32(std::span<const std::uint8_t>(b).first(20));
  for (int i = 0; i < 4; ++i) b[20 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
  auto latest = store.read_latest();
  ASSERT_TRUE(latest.ok());
  EXPECT_FALSE(latest->record);
  EXPECT_EQ(latest->slots[0].defect, RecordDefect::kNewerVersion);
  EXPECT_NE(latest->slots[0].reason.find("version 7, written by a newer imucal"), std::string::npos);
}

/// Gives slot `slot` of a 512-byte region at 0 format version `version`, its header CRC resealed.
void set_version(Bytes& b, int slot, std::uint8_t version) {
  const std::size_t at = static_cast<std::size_t>(slot) * 256;
  b[at + 4] = version;
  const std::uint32_t crc = crc32(std::span<const std::uint8_t>(b).subspan(at, 20));
  for (int i = 0; i < 4; ++i) b[at + 20 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
}

// A newer imucal's record is not damage. Before: it was taken for an invalid slot, and the next
// write (which goes to the slot not holding the newest valid record) replaced it.
TEST(StorageStore, ARecordOfANewerVersionIsNeverReplacedUnlessAsked) {
  MemoryStorage dev(512);
  auto store = open_store(dev, 0, 512);
  ASSERT_TRUE(store.write(payload(1, 20)).ok());  // A, sequence 1
  ASSERT_TRUE(store.write(payload(2, 20)).ok());  // B, sequence 2
  set_version(dev.bytes(), 1, 2);                 // B: a newer imucal's record
  const Bytes before = dev.bytes();
  const int writes = dev.writes();
  auto w = store.write(payload(3, 20));
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.error().code, Errc::kInvalidArgument);
  EXPECT_NE(w.error().message.find("slot B holds a record of format version 2, written by a newer imucal"),
            std::string::npos)
      << w.error().message;
  ASSERT_EQ(w.error().remedies.size(), 1u);
  EXPECT_EQ(w.error().remedies[0].option, "replace_newer");
  EXPECT_EQ(dev.writes(), writes);
  EXPECT_TRUE(dev.bytes() == before);
  // Asked explicitly, the write goes where it would have gone.
  auto replaced = store.write(payload(3, 20), StoreWriteOptions{true});
  ASSERT_TRUE(replaced.ok()) << replaced.error().message;
  EXPECT_EQ(replaced->slot, 1);
}

// Before: a region of another file's bytes (a session log named as storage.path) was written over.
TEST(StorageStore, ARegionOfSomethingElseIsNeverWrittenOver) {
  Bytes foreign(512);
  const std::string sqlite = "SQLite format 3";
  std::copy(sqlite.begin(), sqlite.end(), foreign.begin());
  for (std::size_t i = sqlite.size() + 1; i < foreign.size(); ++i)
    foreign[i] = static_cast<std::uint8_t>(i * 7);
  MemoryStorage dev(foreign);
  auto store = open_store(dev, 0, 512);
  auto w = store.write(payload(1, 20));
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.error().code, Errc::kInvalidArgument);
  EXPECT_NE(w.error().message.find("holds data that is not a calibration record"), std::string::npos)
      << w.error().message;
  EXPECT_EQ(dev.writes(), 0);
  EXPECT_TRUE(dev.bytes() == foreign);
  // An erased region (0x00 or 0xFF), or one with imucal's record in a slot, is written as before.
  MemoryStorage erased(Bytes(512, 0xFF));
  auto fresh = open_store(erased, 0, 512);
  EXPECT_TRUE(fresh.write(payload(1, 20)).ok());
}

}  // namespace
}  // namespace imucal::drivers
