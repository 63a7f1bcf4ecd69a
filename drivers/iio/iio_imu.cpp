// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/iio/iio_imu.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <regex>
#include <sstream>

namespace imucal::drivers::iio {

namespace fs = std::filesystem;
namespace mpu = drivers::mpu6000;

namespace {

// The kernel driver's scale lists (inv_mpu_core.c, in_accel_scale_available and
// in_anglvel_scale_available), in the order of the ranges: +-2..16 g, +-250..2000 deg/s.
constexpr std::array<const char*, 4> kAccelScales = {"0.000598", "0.001196", "0.002392", "0.004785"};
constexpr std::array<const char*, 4> kGyroScales = {"0.000133090", "0.000266181", "0.000532362",
                                                    "0.001064724"};
constexpr double kMinRateHz = 4.0;
constexpr double kMaxRateHz = 1000.0;

// Channels read from each scan, in IioScan's order.
constexpr std::array<const char*, 8> kChannels = {"in_accel_x",   "in_accel_y",   "in_accel_z",
                                                  "in_anglvel_x", "in_anglvel_y", "in_anglvel_z",
                                                  "in_temp",      "in_timestamp"};

// The value of a sysfs attribute without its line end; some attributes also end in a NUL
// (current_timestamp_clock's show copies sizeof "monotonic\n").
std::optional<std::string> read_text(const std::string& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  std::stringstream ss;
  ss << in.rdbuf();
  std::string s = ss.str();
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ' || s.back() == '\0')) s.pop_back();
  return s;
}

Status write_text(const std::string& path, const std::string& value) {
  // O_TRUNC as a shell's redirection does: sysfs ignores it, a plain file (the tests' tree) needs it.
  const int fd = ::open(path.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    return make_error(e == ENOENT ? Errc::kNotFound : Errc::kIo,
                      "cannot open " + path + " to write '" + value + "': " + std::strerror(e));
  }
  const std::string line = value + "\n";
  const ssize_t n = ::write(fd, line.data(), line.size());
  const int e = errno;
  ::close(fd);
  if (n < 0) {
    return make_error(e == EBUSY ? Errc::kDevice : Errc::kIo,
                      "writing '" + value + "' to " + path + " was refused: " + std::strerror(e));
  }
  return {};
}

std::optional<double> read_number(const std::string& path) {
  auto text = read_text(path);
  if (!text) return std::nullopt;
  try {
    std::size_t used = 0;
    const double v = std::stod(*text, &used);
    if (used == 0) return std::nullopt;
    return v;
  } catch (...) {
    return std::nullopt;
  }
}

bool name_supported(const std::string& name) {
  return std::any_of(kSupportedNames.begin(), kSupportedNames.end(),
                     [&](const char* n) { return name == n; });
}

// Names the inv-mpu6050 driver gives (its I2C/SPI id tables): the family, not only what imucal
// drives, so that a rig with another member is told why it is not used.
bool inv_mpu_family(const std::string& name) {
  static const std::regex family(
      "^(mpu(6000|6050|6500|6515|6880|9150|9250|9255)|icm(20608|20609|20689|20602|20690)|iam20680)$");
  return std::regex_match(name, family);
}

}  // namespace

std::vector<IioDeviceInfo> find_inv_mpu_devices(const std::string& sysfs_root) {
  std::vector<IioDeviceInfo> found;
  std::error_code ec;
  if (!fs::is_directory(sysfs_root, ec)) return found;
  for (const auto& entry : fs::directory_iterator(sysfs_root, ec)) {
    const std::string id = entry.path().filename().string();
    if (id.rfind("iio:device", 0) != 0) continue;
    auto name = read_text(entry.path().string() + "/name");
    if (!name || !inv_mpu_family(*name)) continue;
    IioDeviceInfo info;
    info.id = id;
    info.name = *name;
    // /sys/bus/iio/devices/iio:deviceN links to the device under its parent, the bus device
    // the chip is bound to: /sys/devices/.../i2c-1/1-0068/iio:device0.
    std::error_code lec;
    const fs::path real = fs::canonical(entry.path(), lec);
    if (!lec) info.parent = real.parent_path().filename().string();
    info.has_buffer = fs::is_directory(entry.path() / "scan_elements", lec);
    found.push_back(info);
  }
  std::sort(found.begin(), found.end(),
            [](const IioDeviceInfo& a, const IioDeviceInfo& b) { return a.id < b.id; });
  return found;
}

std::string bus_parent_name(const std::string& device_node, bool i2c, int i2c_address) {
  const std::string base = fs::path(device_node).filename().string();
  std::smatch m;
  if (i2c) {
    static const std::regex re("^i2c-([0-9]+)$");
    if (!std::regex_match(base, m, re)) return {};
    char buf[32];
    std::snprintf(buf, sizeof buf, "%s-%04x", m[1].str().c_str(), i2c_address);
    return buf;
  }
  static const std::regex re("^spidev([0-9]+)\\.([0-9]+)$");
  if (!std::regex_match(base, m, re)) return {};
  return "spi" + m[1].str() + "." + m[2].str();
}

bool parse_scan_type(const std::string& text, ScanElement& e) {
  // [be|le]:[s|u]bits/storagebits[Xrepeat]>>shift
  static const std::regex re("^(be|le):([su])([0-9]+)/([0-9]+)(X[0-9]+)?>>([0-9]+)$");
  std::smatch m;
  if (!std::regex_match(text, m, re)) return false;
  e.big_endian = m[1] == "be";
  e.is_signed = m[2] == "s";
  e.real_bits = std::stoi(m[3]);
  e.storage_bits = std::stoi(m[4]);
  e.shift = std::stoi(m[6]);
  if (m[5].matched) return false;  // repeated channels: not a channel inv-mpu6050 has
  const bool storage_ok =
      e.storage_bits == 8 || e.storage_bits == 16 || e.storage_bits == 32 || e.storage_bits == 64;
  return storage_ok && e.real_bits > 0 && e.real_bits + e.shift <= e.storage_bits;
}

std::size_t layout_scan(std::vector<ScanElement>& elements) {
  std::sort(elements.begin(), elements.end(),
            [](const ScanElement& a, const ScanElement& b) { return a.index < b.index; });
  std::size_t at = 0;
  std::size_t largest = 1;
  for (ScanElement& e : elements) {
    const std::size_t bytes = static_cast<std::size_t>(e.storage_bits) / 8;
    at = (at + bytes - 1) / bytes * bytes;
    e.offset = at;
    at += bytes;
    largest = std::max(largest, bytes);
  }
  return (at + largest - 1) / largest * largest;
}

IioImu::~IioImu() {
  if (enabled_) (void)set_buffer(false);
  if (fd_ >= 0) ::close(fd_);
}

Result<std::unique_ptr<IioImu>> IioImu::open(const IioImuOptions& options) {
  const auto devices = find_inv_mpu_devices(options.sysfs_root);
  std::unique_ptr<IioImu> imu(new IioImu());
  const IioDeviceInfo* chosen = nullptr;
  for (const IioDeviceInfo& d : devices) {
    if (!options.device.empty() ? d.id == options.device
                                : (options.parent.empty() || d.parent == options.parent)) {
      chosen = &d;
      break;
    }
  }
  if (chosen == nullptr) {
    std::string seen;
    for (const IioDeviceInfo& d : devices)
      seen += (seen.empty() ? "" : ", ") + d.id + " (" + d.name + " on " + d.parent + ")";
    const std::string what = !options.device.empty() ? options.device + " (imu.iio_device)"
                             : options.parent.empty()
                                 ? "an inv-mpu6050 IIO device"
                                 : "an inv-mpu6050 IIO device bound to " + options.parent;
    return make_error(
        Errc::kNotFound,
        "no " + what + " under " + options.sysfs_root +
            (seen.empty() ? ": the kernel's inv-mpu6050 driver has no device here (is the module "
                            "loaded and the chip in the device tree?); without it use imu.driver: direct"
                          : "; found " + seen + " (set imu.iio_device to one of them)"));
  }
  imu->info_ = *chosen;
  if (!name_supported(imu->info_.name)) {
    return make_error(Errc::kUnsupported, imu->info_.id + " is an " + imu->info_.name +
                                              ": imucal drives the MPU-6000 and MPU-6050 only");
  }
  imu->dir_ = options.sysfs_root + "/" + imu->info_.id;
  imu->node_ = options.dev_root + "/" + imu->info_.id;
  if (!imu->info_.has_buffer) {
    return make_error(
        Errc::kUnsupported,
        imu->describe() +
            " has no buffer: the kernel's inv-mpu6050 driver sets one up only when the chip has an "
            "interrupt (\"no IRQ, no trigger, no buffer\"), and without it there are no per-sample "
            "times. Give the chip its INT line in the device tree (interrupts = <...>), or unbind "
            "the kernel driver and use imu.driver: direct");
  }
  IMUCAL_TRY(imu->configure(options));
  return imu;
}

Status IioImu::configure(const IioImuOptions& o) {
  const std::string who = describe();
  if (read_text(attr("buffer/enable")).value_or("0") == "1") {
    return make_error(Errc::kDevice,
                      who +
                          " is streaming to another reader (buffer/enable is 1): stop it first "
                          "(another imucal, iio_readdev, a sensor daemon)");
  }
  // The kernel stamps scans on CLOCK_REALTIME unless told otherwise.
  if (auto st = write_text(attr("current_timestamp_clock"), "monotonic"); !st.ok())
    return st.error().context(who + ": choosing CLOCK_MONOTONIC for its timestamps");
  if (read_text(attr("current_timestamp_clock")).value_or("") != "monotonic")
    return make_error(Errc::kDevice, who + ": current_timestamp_clock does not read back as monotonic");

  if (!(o.rate_hz >= kMinRateHz && o.rate_hz <= kMaxRateHz)) {
    std::ostringstream os;
    os << "imu.rate_hz " << o.rate_hz
       << " is outside what the kernel's inv-mpu6050 driver gives (4 to 1000 Hz, "
       << "1000 / (1 + divider)); the direct driver reaches 8000 Hz (imu.driver: direct)";
    return make_error(Errc::kUnsupported, os.str());
  }
  IMUCAL_TRY(write_text(attr("sampling_frequency"), std::to_string(std::lround(o.rate_hz))));
  const auto rate = read_number(attr("sampling_frequency"));
  if (!rate) return make_error(Errc::kDevice, who + ": sampling_frequency does not read back as a number");
  rate_hz_ = *rate;
  if (std::abs(rate_hz_ - o.rate_hz) > 0.01 * o.rate_hz) {
    std::ostringstream os;
    os << who << " runs at " << rate_hz_ << " Hz when asked for " << o.rate_hz
       << " Hz: the kernel's inv-mpu6050 driver gives 1000 / (1 + divider) Hz; set imu.rate_hz to such a "
          "rate "
          "(1000, 500, 333, 250, 200, 100, 50, ...)";
    return make_error(Errc::kUnsupported, os.str());
  }

  const auto ai = static_cast<std::size_t>(o.accel_range);
  const auto gi = static_cast<std::size_t>(o.gyro_range);
  IMUCAL_TRY(write_text(attr("in_accel_scale"), kAccelScales[ai]));
  IMUCAL_TRY(write_text(attr("in_anglvel_scale"), kGyroScales[gi]));
  const auto as = read_number(attr("in_accel_scale"));
  const auto gs = read_number(attr("in_anglvel_scale"));
  if (!as || !gs || std::abs(*as - std::stod(kAccelScales[ai])) > 1e-9 ||
      std::abs(*gs - std::stod(kGyroScales[gi])) > 1e-12) {
    return make_error(Errc::kDevice, who + ": the scales do not read back as written (in_accel_scale " +
                                         read_text(attr("in_accel_scale")).value_or("?") +
                                         ", in_anglvel_scale " +
                                         read_text(attr("in_anglvel_scale")).value_or("?") + ")");
  }
  accel_scale_ = *as;
  gyro_scale_ = *gs;
  // deg C = (raw + offset) * scale / 1000 (scale in milli-degrees per count).
  const auto ts = read_number(attr("in_temp_scale"));
  const auto to = read_number(attr("in_temp_offset"));
  if (!ts || !to) return make_error(Errc::kDevice, who + ": in_temp_scale or in_temp_offset cannot be read");
  temp_scale_ = *ts / 1000.0;
  temp_offset_c_ = *to * *ts / 1000.0;

  IMUCAL_TRY(enable_scan_elements());
  const std::uint32_t per_10ms = static_cast<std::uint32_t>(std::ceil(rate_hz_ / 100.0));
  const std::uint32_t length = o.buffer_scans > 0
                                   ? o.buffer_scans
                                   : std::max<std::uint32_t>(128, static_cast<std::uint32_t>(2.0 * rate_hz_));
  const std::uint32_t watermark =
      o.watermark_scans > 0 ? o.watermark_scans : std::max<std::uint32_t>(1, per_10ms);
  IMUCAL_TRY(write_text(attr("buffer/length"), std::to_string(length)));
  IMUCAL_TRY(write_text(attr("buffer/watermark"), std::to_string(std::min(watermark, length))));

  fd_ = ::open(node_.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) {
    const int e = errno;
    return make_error(e == ENOENT  ? Errc::kNotFound
                      : e == EBUSY ? Errc::kDevice
                                   : Errc::kIo,
                      "cannot open " + node_ + ": " + std::strerror(e) +
                          (e == EBUSY    ? " (another program has it open: stop it first)"
                           : e == EACCES ? " (run as a user allowed to read it, or add a udev rule)"
                                         : ""));
  }
  buffer_.assign(scan_bytes_ * 64, 0);
  IMUCAL_TRY(set_buffer(true));
  return {};
}

Status IioImu::enable_scan_elements() {
  const std::string dir = attr("scan_elements");
  std::error_code ec;
  // Everything off first (a magnetometer's channels, a previous reader's choice), then ours on.
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string f = entry.path().filename().string();
    if (f.size() > 3 && f.compare(f.size() - 3, 3, "_en") == 0) {
      const std::string channel = f.substr(0, f.size() - 3);
      if (std::find(kChannels.begin(), kChannels.end(), channel) == kChannels.end())
        IMUCAL_TRY(write_text(entry.path().string(), "0"));
    }
  }
  if (ec) return make_error(Errc::kIo, "cannot list " + dir + ": " + ec.message());
  elements_.clear();
  for (const char* ch : kChannels) {
    const std::string base = dir + "/" + ch;
    if (auto st = write_text(base + "_en", "1"); !st.ok()) {
      return st.error().context(describe() + ": enabling its " + ch +
                                " channel (a kernel without the temperature "
                                "in the buffer is older than Linux 5.x?)");
    }
    ScanElement e;
    e.name = ch;
    const auto index = read_number(base + "_index");
    const auto type = read_text(base + "_type");
    if (!index || !type || !parse_scan_type(*type, e)) {
      return make_error(Errc::kDevice, describe() + ": the scan element " + ch +
                                           " has an index or type imucal "
                                           "cannot read ('" +
                                           type.value_or("?") + "')");
    }
    e.index = static_cast<int>(*index);
    if ((std::string(ch) == "in_timestamp") != (e.storage_bits == 64) ||
        (e.storage_bits != 64 && e.storage_bits != 16)) {
      return make_error(Errc::kDevice,
                        describe() + ": the scan element " + ch + " is " + *type +
                            ", not the 16-bit data or 64-bit timestamp of the inv-mpu6050 driver");
    }
    elements_.push_back(e);
  }
  scan_bytes_ = layout_scan(elements_);
  for (std::size_t c = 0; c < kChannels.size(); ++c) {
    for (std::size_t i = 0; i < elements_.size(); ++i)
      if (elements_[i].name == kChannels[c]) slot_[c] = static_cast<int>(i);
  }
  return {};
}

Status IioImu::set_buffer(bool on) {
  if (auto st = write_text(attr("buffer/enable"), on ? "1" : "0"); !st.ok()) {
    return st.error().context(describe() + (on ? ": starting its buffer" : ": stopping its buffer"));
  }
  enabled_ = on;
  return {};
}

Status IioImu::restart() {
  std::error_code ec;
  if (!fs::exists(dir_, ec)) {
    return make_error(Errc::kNotFound,
                      describe() + " went away (the kernel driver was unbound or the chip removed)");
  }
  IMUCAL_TRY(set_buffer(false));
  carry_ = 0;
  ++stats_.restarts;
  return set_buffer(true);
}

void IioImu::decode(const std::uint8_t* scan, IioScan& out) const {
  auto value = [&](int slot) -> std::int64_t {
    const ScanElement& e = elements_[static_cast<std::size_t>(slot_[static_cast<std::size_t>(slot)])];
    const std::size_t n = static_cast<std::size_t>(e.storage_bits) / 8;
    std::uint64_t u = 0;
    for (std::size_t b = 0; b < n; ++b) {
      const std::uint64_t byte = scan[e.offset + (e.big_endian ? b : n - 1 - b)];
      u = (u << 8) | byte;
    }
    u >>= e.shift;
    if (e.real_bits < 64) u &= (std::uint64_t{1} << e.real_bits) - 1;
    if (e.is_signed && e.real_bits < 64 && (u >> (e.real_bits - 1)) != 0)
      u |= ~((std::uint64_t{1} << e.real_bits) - 1);
    return static_cast<std::int64_t>(u);
  };
  for (int i = 0; i < 3; ++i) {
    out.accel[static_cast<std::size_t>(i)] = static_cast<std::int16_t>(value(i));
    out.gyro[static_cast<std::size_t>(i)] = static_cast<std::int16_t>(value(3 + i));
  }
  out.temp = static_cast<std::int16_t>(value(6));
  out.t_ns = value(7);
}

Status IioImu::read(std::vector<IioScan>& out) {
  for (;;) {
    const ssize_t n = ::read(fd_, buffer_.data() + carry_, buffer_.size() - carry_);
    if (n < 0) {
      const int e = errno;
      if (e == EINTR) continue;
      if (e == EAGAIN) {
        ++stats_.empty_reads;
        return {};
      }
      return make_error(
          e == ENODEV ? Errc::kNotFound : Errc::kIo,
          "reading " + node_ + ": " + std::strerror(e) +
              (e == ENODEV ? " (the device went away: the kernel driver was unbound or the chip removed)"
                           : ""));
    }
    if (n == 0) {
      ++stats_.empty_reads;
      return {};
    }
    ++stats_.reads;
    const std::size_t have = carry_ + static_cast<std::size_t>(n);
    const std::size_t whole = have / scan_bytes_;
    for (std::size_t i = 0; i < whole; ++i) {
      IioScan s;
      decode(buffer_.data() + i * scan_bytes_, s);
      out.push_back(s);
    }
    stats_.scans += whole;
    carry_ = have - whole * scan_bytes_;
    if (carry_ > 0) {
      stats_.partial_bytes += carry_;
      std::memmove(buffer_.data(), buffer_.data() + whole * scan_bytes_, carry_);
    }
    if (static_cast<std::size_t>(n) < buffer_.size() - (have - static_cast<std::size_t>(n))) return {};
  }
}

Result<mpu::OffsetRegisters> IioImu::read_offsets() const {
  mpu::OffsetRegisters r;
  const char* axes = "xyz";
  for (std::size_t i = 0; i < 3; ++i) {
    const auto a = read_number(attr(std::string("in_accel_") + axes[i] + "_calibbias"));
    const auto g = read_number(attr(std::string("in_anglvel_") + axes[i] + "_calibbias"));
    if (!a || !g) return make_error(Errc::kIo, describe() + ": its calibbias attributes cannot be read");
    r.accel[i] = static_cast<std::int16_t>(*a);
    r.gyro[i] = static_cast<std::int16_t>(*g);
  }
  return r;
}

Status IioImu::write_offsets(const mpu::OffsetRegisters& offsets) {
  // The kernel's driver takes calibbias writes only outside buffered mode (write_raw claims
  // direct mode: EBUSY while the buffer is on), so a running buffer pauses for them; the samples
  // of the pause are a gap like any other (the stamps show it).
  const bool was_on = enabled_;
  if (was_on) IMUCAL_TRY(set_buffer(false));
  const char* axes = "xyz";
  Status written;
  for (std::size_t i = 0; i < 3 && written.ok(); ++i) {
    written =
        write_text(attr(std::string("in_accel_") + axes[i] + "_calibbias"), std::to_string(offsets.accel[i]));
    if (written.ok())
      written = write_text(attr(std::string("in_anglvel_") + axes[i] + "_calibbias"),
                           std::to_string(offsets.gyro[i]));
  }
  if (was_on) {
    carry_ = 0;
    IMUCAL_TRY(set_buffer(true));
  }
  return written;
}

std::string IioImu::describe() const {
  return info_.id + " (" + info_.name + (info_.parent.empty() ? "" : " on " + info_.parent) + ", " + node_ +
         ")";
}

}  // namespace imucal::drivers::iio
