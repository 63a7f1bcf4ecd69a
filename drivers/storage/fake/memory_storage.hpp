// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A StorageDevice in memory, with the faults a real one has: a write cut after a given number
// of bytes (power loss), optionally leaving torn bytes after the cut (a page half programmed),
// and a stuck bit that reads back wrong. Tests and the fuzz target use it; real code never does.

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/storage/storage_device.hpp"

namespace imucal::drivers {

class MemoryStorage final : public StorageDevice {
 public:
  /// `size` bytes, all `fill` (0xFF: an erased EEPROM; 0x00: a new file).
  explicit MemoryStorage(std::size_t size, std::uint8_t fill = 0xFF) : bytes_(size, fill) {}
  /// A device holding `image`.
  explicit MemoryStorage(std::vector<std::uint8_t> image) : bytes_(std::move(image)) {}

  std::uint64_t size() const override { return bytes_.size(); }
  std::string name() const override { return "memory"; }
  Status read(std::uint64_t offset, std::span<std::uint8_t> out) override;
  Status write(std::uint64_t offset, std::span<const std::uint8_t> data) override;
  Status sync() override;

  /// The next write stores only its first `bytes` bytes, then `torn_bytes` bytes of `torn_value`
  /// (clipped to the write), then fails as a power loss would. One-shot.
  void cut_next_write(std::size_t bytes, std::size_t torn_bytes = 0, std::uint8_t torn_value = 0xA5);
  /// Reads of the byte at `offset` return it with `mask` XORed (a stuck or weak cell).
  void corrupt_reads_at(std::uint64_t offset, std::uint8_t mask);

  const std::vector<std::uint8_t>& bytes() const { return bytes_; }
  std::vector<std::uint8_t>& bytes() { return bytes_; }
  int writes() const { return writes_; }
  int syncs() const { return syncs_; }

 private:
  std::vector<std::uint8_t> bytes_;
  std::optional<std::size_t> cut_after_;
  std::size_t torn_bytes_ = 0;
  std::uint8_t torn_value_ = 0;
  std::optional<std::uint64_t> corrupt_offset_;
  std::uint8_t corrupt_mask_ = 0;
  int writes_ = 0;
  int syncs_ = 0;
};

}  // namespace imucal::drivers
