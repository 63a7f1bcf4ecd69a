// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The MPU-6000 through the kernel's own driver (inv-mpu6050, Linux IIO): for a rig whose device
// tree binds the chip to the kernel, so that neither spidev nor i2c-dev can reach it.
//
// The device is found in sysfs (/sys/bus/iio/devices/iio:deviceN whose `name` is mpu6000 or
// mpu6050 -- the kernel names an MPU-6000 on I2C mpu6050, its I2C id table has no mpu6000 --
// and whose parent is the configured bus address), configured through its attributes
// (current_timestamp_clock = monotonic, sampling_frequency, in_accel_scale and in_anglvel_scale
// for the configured ranges), and read through the IIO buffer: the scan elements accel x/y/z,
// temp, anglvel x/y/z and the timestamp are enabled, their layout is taken from
// scan_elements/*_index and *_type (big-endian 16-bit data, a 64-bit timestamp aligned to 8),
// and /dev/iio:deviceN gives whole scans. The kernel driver reads the chip's FIFO on each
// data-ready interrupt and stamps every sample itself (inv_sensors_timestamp: the interrupt's
// time, the chip's period estimated from the interrupt intervals).
//
// What the kernel does not say: a FIFO it reset on overflow ("fifo overflow reset" in dmesg) and
// scans dropped from a full buffer. Both show only as a hole in the timestamps, which the
// acquisition (acquisition/iio_acquisition.hpp) counts.
//
// Paths are options so that the unit tests run the same code on a fake sysfs tree and a FIFO
// standing for the character device (tests/drivers/test_iio_imu.cpp).

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::drivers::iio {

/// Names the kernel's inv-mpu6050 driver gives chips imucal drives the same way (the IIO
/// device's `name`): the MPU-6000 and its I2C-only twin, the MPU-6050.
inline constexpr std::array<const char*, 2> kSupportedNames = {"mpu6000", "mpu6050"};

/// One IIO device of the kernel's inv-mpu6050 driver, as sysfs shows it.
struct IioDeviceInfo {
  std::string id;           // "iio:device0"
  std::string name;         // the `name` attribute: "mpu6000", "mpu6050", "mpu6500", ...
  std::string parent;       // the bus device it is bound to: "1-0068" (I2C bus 1, 0x68), "spi0.0"
  bool has_buffer = false;  // scan_elements exist (the driver has an interrupt)
};

/// Every IIO device under `sysfs_root` (default /sys/bus/iio/devices) whose name the
/// inv-mpu6050 driver gives; an empty list when there is none (or no IIO at all).
std::vector<IioDeviceInfo> find_inv_mpu_devices(const std::string& sysfs_root);

/// The parent sysfs name of the configured bus device: "/dev/i2c-1" with address 0x68 gives
/// "1-0068", "/dev/spidev0.1" gives "spi0.1"; empty when the node's name is neither form.
std::string bus_parent_name(const std::string& device_node, bool i2c, int i2c_address);

struct IioImuOptions {
  std::string sysfs_root = "/sys/bus/iio/devices";
  std::string dev_root = "/dev";
  /// "iio:device0"; empty: the one inv-mpu6050 device bound to `parent` (or the only one).
  std::string device;
  /// The bus device the chip hangs on, as bus_parent_name() gives it; empty: any.
  std::string parent;
  double rate_hz = 200.0;  // the kernel gives 1000 / (1 + divider) Hz, 4..1000
  mpu6000::AccelRange accel_range = mpu6000::AccelRange::k16g;
  mpu6000::GyroRange gyro_range = mpu6000::GyroRange::k2000dps;
  /// The kernel buffer's length in scans; 0: two seconds of samples (at least 128).
  std::uint32_t buffer_scans = 0;
  /// Scans the kernel gathers before the character device turns readable; 0: about 10 ms of
  /// samples (at least 1).
  std::uint32_t watermark_scans = 0;
};

/// One scan from the buffer: counts in the chip's axes, and the kernel's timestamp.
struct IioScan {
  std::array<std::int16_t, 3> accel{};
  std::array<std::int16_t, 3> gyro{};
  std::int16_t temp = 0;
  TimeNs t_ns = 0;
};

/// Where one enabled channel sits in a scan.
struct ScanElement {
  std::string name;  // "in_accel_x", ..., "in_timestamp"
  int index = 0;     // scan_elements/<name>_index
  bool big_endian = false;
  bool is_signed = true;
  int real_bits = 16;
  int storage_bits = 16;
  int shift = 0;
  std::size_t offset = 0;  // bytes from the scan's start
};

/// Parses an IIO scan type ("be:s16/16>>0", "le:s64/64>>0"); false when it is not one.
bool parse_scan_type(const std::string& text, ScanElement& element);

/// Lays out `elements` (sorted by index, each aligned to its own storage size) and returns the
/// scan's size (a multiple of the largest element), as the kernel's iio_compute_scan_bytes().
std::size_t layout_scan(std::vector<ScanElement>& elements);

struct IioStats {
  std::uint64_t reads = 0;          // read() calls that returned scans
  std::uint64_t scans = 0;          // scans decoded
  std::uint64_t empty_reads = 0;    // read() found nothing (EAGAIN)
  std::uint64_t partial_bytes = 0;  // bytes of incomplete scans carried to the next read
  std::uint64_t restarts = 0;       // buffer disabled and enabled again (no data for too long)
};

class IioImu {
 public:
  /// Finds, configures and starts the device. Errors: kNotFound (no such device, no device
  /// bound to the configured bus), kUnsupported (a chip imucal does not drive, no buffer
  /// because the kernel has no interrupt for it, a rate or range it cannot give), kDevice (in
  /// use by another reader, an attribute refused), kIo. Each says what to do.
  [[nodiscard]] static Result<std::unique_ptr<IioImu>> open(const IioImuOptions& options);

  ~IioImu();  // stops the buffer
  IioImu(const IioImu&) = delete;
  IioImu& operator=(const IioImu&) = delete;

  /// Reads every whole scan waiting in the buffer (never blocks) into `out` (appended).
  /// Errors: kNotFound when the device went away (driver unbound), kIo otherwise.
  [[nodiscard]] Status read(std::vector<IioScan>& out);

  /// Disables and enables the buffer again (the kernel driver resets the chip's FIFO).
  [[nodiscard]] Status restart();

  /// The character device's descriptor (non-blocking): readable when scans wait.
  int fd() const { return fd_; }
  const IioDeviceInfo& info() const { return info_; }
  const std::string& node() const { return node_; }
  /// The rate the kernel set (sampling_frequency read back), Hz.
  double rate_hz() const { return rate_hz_; }
  /// SI per count as the kernel states them: m/s^2, rad/s; deg C = temp_scale * raw + temp_offset.
  double accel_scale() const { return accel_scale_; }
  double gyro_scale() const { return gyro_scale_; }
  double temp_scale() const { return temp_scale_; }
  double temp_offset_c() const { return temp_offset_c_; }
  const std::vector<ScanElement>& layout() const { return elements_; }
  std::size_t scan_bytes() const { return scan_bytes_; }
  const IioStats& stats() const { return stats_; }

  /// The chip's offset registers through the calibbias attributes (the same registers and
  /// units the direct driver writes: accel 1/2048 g, gyro 1/32.8 deg/s). Writing pauses a running
  /// buffer: the kernel's driver refuses the attributes while it streams (EBUSY).
  [[nodiscard]] Result<mpu6000::OffsetRegisters> read_offsets() const;
  [[nodiscard]] Status write_offsets(const mpu6000::OffsetRegisters& offsets);

  /// "iio:device0 (mpu6000 on 1-0068, /dev/iio:device0)".
  std::string describe() const;

 private:
  IioImu() = default;
  std::string attr(const std::string& name) const { return dir_ + "/" + name; }
  [[nodiscard]] Status configure(const IioImuOptions& options);
  [[nodiscard]] Status enable_scan_elements();
  [[nodiscard]] Status set_buffer(bool on);
  void decode(const std::uint8_t* scan, IioScan& out) const;

  IioDeviceInfo info_;
  std::string dir_;
  std::string node_;
  int fd_ = -1;
  bool enabled_ = false;
  double rate_hz_ = 0.0;
  double accel_scale_ = 0.0;
  double gyro_scale_ = 0.0;
  double temp_scale_ = 0.0;
  double temp_offset_c_ = 0.0;
  std::vector<ScanElement> elements_;
  std::size_t scan_bytes_ = 0;
  // Where each value sits: accel x/y/z, gyro x/y/z, temp, timestamp (indices into elements_).
  std::array<int, 8> slot_{};
  std::vector<std::uint8_t> buffer_;
  std::size_t carry_ = 0;  // bytes of an incomplete scan at the buffer's start
  IioStats stats_;
};

}  // namespace imucal::drivers::iio
