// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Non-volatile storage for the calibration record, behind one interface, with three backends
// chosen by the rig configuration's `storage:` section (docs/config.md, docs/storage.md):
//  - file:       a plain file, created at its size when missing; pwrite(2) + fsync(2);
//  - nvmem:      the kernel's nvmem sysfs file of an EEPROM (at24), fixed size, never created;
//  - i2c-eeprom: a 24Cxx EEPROM through i2c-dev, page writes and ACK polling done here.
// Errors are values whose messages say what to check. Not thread-safe.

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/bus/device_io.hpp"

namespace imucal::drivers {

class StorageDevice {
 public:
  virtual ~StorageDevice() = default;
  /// Bytes addressable on the device.
  virtual std::uint64_t size() const = 0;
  /// Reads out.size() bytes at `offset`; the range must lie inside size().
  [[nodiscard]] virtual Status read(std::uint64_t offset, std::span<std::uint8_t> out) = 0;
  /// Writes `data` at `offset`; the range must lie inside size(). Returns when the device took
  /// the bytes, which is not yet durable: call sync().
  [[nodiscard]] virtual Status write(std::uint64_t offset, std::span<const std::uint8_t> data) = 0;
  /// Makes every write so far durable.
  [[nodiscard]] virtual Status sync() = 0;
  /// For messages: the backend and its path, e.g. "file /var/lib/imucal/calibration.bin".
  virtual std::string name() const = 0;
};

/// kRead opens read-only and never creates anything; kWrite opens read-write (and lets the file
/// backend create its file).
enum class StorageAccess { kRead, kWrite };

/// Checks that [offset, offset + n) lies inside a device of `size` bytes (for backends).
[[nodiscard]] Status check_range(const std::string& name, std::uint64_t size, std::uint64_t offset,
                                 std::uint64_t n);

/// A plain file. With kWrite, a missing file is created (mode 0644) at `min_size` bytes of
/// zeros, fsynced, and its folder fsynced so that the new name survives a power cut; with kRead,
/// a missing file is an error (kNotFound) and the file is opened read-only. A file shorter than `min_size` is
/// an error that says what to change: it is never grown behind the user's back.
[[nodiscard]] Result<std::unique_ptr<StorageDevice>> open_file_storage(const std::string& path,
                                                                       std::uint64_t min_size,
                                                                       StorageAccess access);

/// An nvmem sysfs file (/sys/bus/nvmem/devices/NAME/nvmem): its size is the EEPROM's, from
/// stat(2); it is never created or truncated. Writes go in pieces of at most `chunk_bytes`
/// (sysfs passes at most one memory page per write call to the driver). at24 completes each
/// write cycle before its write returns, so sync() has nothing to flush.
[[nodiscard]] Result<std::unique_ptr<StorageDevice>> open_nvmem_storage(const std::string& path,
                                                                        std::uint64_t min_size,
                                                                        StorageAccess access,
                                                                        std::size_t chunk_bytes = 4096);

struct I2cEepromOptions {
  std::uint8_t address = 0x50;   // 0x50..0x57
  std::uint64_t size_bytes = 0;  // bytes used on the chip (from the start of its memory)
  std::size_t page_bytes = 32;   // write page: a write never crosses a page boundary
  int address_bytes = 2;         // word address width: 1 (24c01..24c16) or 2 (24c32 and larger)
  /// Longest write cycle to wait for by ACK polling (24Cxx datasheets: 5 ms, 10 ms for some).
  std::chrono::milliseconds write_timeout{25};
};

/// A raw 24Cxx EEPROM on an i2c-dev node. Uses I2C_RDWR combined transactions when the adapter
/// can, else SMBus I2C-block transfers (1-byte addressing only: an SMBus-only adapter cannot
/// send a 2-byte word address followed by a read). With 1-byte addressing, bytes above 255 are
/// in blocks at the following I2C addresses, as 24c04..24c16 (and the kernel's at24) do.
/// After each page write the chip is polled (it does not acknowledge while it programs) until
/// it answers or `write_timeout` passes. An address owned by a kernel driver (at24) is refused
/// with EBUSY: use the nvmem backend then, or unbind at24. `io` as in I2cDevBus.
[[nodiscard]] Result<std::unique_ptr<StorageDevice>> open_i2c_eeprom_storage(
    const std::string& device, const I2cEepromOptions& options, std::unique_ptr<DeviceIo> io = nullptr);

/// The backend the configuration names, sized to hold [offset_bytes, offset_bytes + size_bytes).
[[nodiscard]] Result<std::unique_ptr<StorageDevice>> open_storage_device(const StorageConfig& config,
                                                                         StorageAccess access);

}  // namespace imucal::drivers
