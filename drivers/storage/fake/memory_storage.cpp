// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/storage/fake/memory_storage.hpp"

#include <algorithm>

namespace imucal::drivers {

Status MemoryStorage::read(std::uint64_t offset, std::span<std::uint8_t> out) {
  IMUCAL_TRY(check_range(name(), size(), offset, out.size()));
  std::copy_n(bytes_.begin() + static_cast<std::ptrdiff_t>(offset), out.size(), out.begin());
  if (corrupt_offset_ && *corrupt_offset_ >= offset && *corrupt_offset_ < offset + out.size()) {
    out[static_cast<std::size_t>(*corrupt_offset_ - offset)] ^= corrupt_mask_;
  }
  return {};
}

Status MemoryStorage::write(std::uint64_t offset, std::span<const std::uint8_t> data) {
  IMUCAL_TRY(check_range(name(), size(), offset, data.size()));
  ++writes_;
  const auto at = bytes_.begin() + static_cast<std::ptrdiff_t>(offset);
  if (!cut_after_) {
    std::copy(data.begin(), data.end(), at);
    return {};
  }
  const std::size_t kept = std::min(*cut_after_, data.size());
  const std::size_t torn = std::min(torn_bytes_, data.size() - kept);
  std::copy_n(data.begin(), kept, at);
  std::fill_n(at + static_cast<std::ptrdiff_t>(kept), torn, torn_value_);
  cut_after_.reset();
  return make_error(Errc::kIo, "memory: power lost after " + std::to_string(kept) + " bytes of a write");
}

Status MemoryStorage::sync() {
  ++syncs_;
  return {};
}

void MemoryStorage::cut_next_write(std::size_t bytes, std::size_t torn_bytes, std::uint8_t torn_value) {
  cut_after_ = bytes;
  torn_bytes_ = torn_bytes;
  torn_value_ = torn_value;
}

void MemoryStorage::corrupt_reads_at(std::uint64_t offset, std::uint8_t mask) {
  corrupt_offset_ = offset;
  corrupt_mask_ = mask;
}

}  // namespace imucal::drivers
