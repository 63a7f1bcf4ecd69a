// SPDX-License-Identifier: BSD-3-Clause
#include "core/rig_config.hpp"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "core/rig_config_fields.hpp"
#include "core/text_file.hpp"
#include "core/text_format.hpp"

namespace imucal {

const char* imu_bus_name(ImuBus bus) {
  switch (bus) {
    case ImuBus::kSpi:
      return "spi";
    case ImuBus::kI2c:
      return "i2c";
    case ImuBus::kSim:
      return "sim";
  }
  return "?";
}

const char* imu_driver_name(ImuDriver driver) {
  switch (driver) {
    case ImuDriver::kDirect:
      return "direct";
    case ImuDriver::kIio:
      return "iio";
    case ImuDriver::kAuto:
      return "auto";
  }
  return "?";
}

const char* camera_backend_name(CameraBackend backend) {
  switch (backend) {
    case CameraBackend::kV4l2:
      return "v4l2";
    case CameraBackend::kLibcamera:
      return "libcamera";
    case CameraBackend::kAravis:
      return "aravis";
    case CameraBackend::kSim:
      return "sim";
  }
  return "?";
}

const char* storage_backend_name(StorageBackend backend) {
  switch (backend) {
    case StorageBackend::kFile:
      return "file";
    case StorageBackend::kNvmem:
      return "nvmem";
    case StorageBackend::kI2cEeprom:
      return "i2c-eeprom";
  }
  return "?";
}

namespace {

using rig_config_detail::kSessionNumbers;

constexpr double kRotationTolerance = 1e-4;

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string join(const std::vector<std::string>& items, const std::string& sep = ", ") {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? sep : "") + items[i];
  return out;
}

/// Parses one configuration document, keeping the source name for error messages.
class ConfigParser {
 public:
  ConfigParser(std::string source, std::string base_dir)
      : source_(std::move(source)), base_dir_(std::move(base_dir)) {}

  Result<RigConfig> parse(const std::string& text);

 private:
  Error error(const YAML::Node& node, const std::string& path, const std::string& what) const {
    std::string where = source_;
    if (node.IsDefined() && !node.Mark().is_null()) where += ":" + std::to_string(node.Mark().line + 1);
    return make_error(Errc::kInvalidArgument,
                      where + ": " + (path.empty() ? "" : printable(path, 120) + ": ") + what);
  }

  Status check_map(const YAML::Node& node, const std::string& path,
                   const std::vector<std::string>& allowed) const;
  Result<long long> get_int(const YAML::Node& node, const std::string& path) const;
  Result<double> get_double(const YAML::Node& node, const std::string& path) const;
  Result<std::string> get_string(const YAML::Node& node, const std::string& path) const;
  Result<std::vector<double>> get_doubles(const YAML::Node& node, const std::string& path) const;

  Status parse_imu(const YAML::Node& node, ImuConfig& imu) const;
  Status parse_imu_driver(const YAML::Node& node, ImuConfig& imu) const;
  Status parse_data_ready(const YAML::Node& node, ImuConfig& imu) const;
  Status parse_mounting(const YAML::Node& node, Eigen::Matrix3d& R_rig_imu) const;
  Status parse_camera(const YAML::Node& node, const std::string& path, CameraConfig& cam) const;
  /// The camera's optional shutter keys (docs/config.md, `cameras[]`).
  Status parse_shutter(const YAML::Node& node, const std::string& path, CameraConfig& cam) const;
  Status parse_target(const YAML::Node& node, RigConfig& config) const;
  Status parse_storage(const YAML::Node& node, StorageConfig& storage) const;
  Status parse_session(const YAML::Node& node, SessionConfig& session) const;
  Status parse_live_view(const YAML::Node& node, LiveViewConfig& live) const;
  Status parse_sides(const YAML::Node& node, RigSides& sides) const;

  std::string source_;
  std::string base_dir_;
};

Status ConfigParser::check_map(const YAML::Node& node, const std::string& path,
                               const std::vector<std::string>& allowed) const {
  if (!node.IsMap()) return error(node, path, "expected a mapping with keys " + join(allowed));
  std::vector<std::string> seen;
  for (const auto& kv : node) {
    const std::string key = kv.first.Scalar();
    if (std::find(seen.begin(), seen.end(), key) != seen.end()) {
      return error(kv.first, path.empty() ? key : path + "." + key,
                   "given twice; only one value can apply (YAML would keep the first silently)");
    }
    seen.push_back(key);
    if (std::find(allowed.begin(), allowed.end(), key) != allowed.end()) continue;
    std::string hint;
    std::size_t best = 3;
    for (const auto& a : allowed) {
      const std::size_t d = edit_distance(key, a);
      if (d < best) {
        best = d;
        hint = " (did you mean '" + a + "'?)";
      }
    }
    return error(kv.first, path.empty() ? key : path + "." + key,
                 "unknown key" + hint + "; allowed keys here: " + join(allowed));
  }
  return {};
}

Result<long long> ConfigParser::get_int(const YAML::Node& node, const std::string& path) const {
  if (!node.IsScalar()) return error(node, path, "expected an integer");
  const std::string& s = node.Scalar();
  long long v = 0;
  const char* first = s.data();
  const char* last = s.data() + s.size();
  int base = 10;
  if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
    first += 2;
    base = 16;
  }
  auto [ptr, ec] = std::from_chars(first, last, v, base);
  if (ec != std::errc() || ptr != last || first == last) {
    return error(node, path, "'" + printable(s) + "' is not an integer (decimal, or hex with 0x)");
  }
  return v;
}

Result<double> ConfigParser::get_double(const YAML::Node& node, const std::string& path) const {
  if (!node.IsScalar()) return error(node, path, "expected a number");
  const std::string& s = node.Scalar();
  const auto v = parse_finite_number(s);
  if (!v) return error(node, path, "'" + printable(s) + "' is not a finite number");
  return *v;
}

Result<std::string> ConfigParser::get_string(const YAML::Node& node, const std::string& path) const {
  if (!node.IsScalar()) return error(node, path, "expected a string");
  if (!valid_utf8(node.Scalar()))
    return error(node, path, "'" + printable(node.Scalar()) + "' is not UTF-8 text (save the file as UTF-8)");
  return node.Scalar();
}

Result<std::vector<double>> ConfigParser::get_doubles(const YAML::Node& node, const std::string& path) const {
  if (!node.IsSequence()) return error(node, path, "expected a list of numbers");
  std::vector<double> out;
  for (std::size_t i = 0; i < node.size(); ++i) {
    auto v = get_double(node[i], path + "[" + std::to_string(i) + "]");
    if (!v.ok()) return v.error();
    out.push_back(*v);
  }
  return out;
}

// Reads `key` of `map` into `out` when present, checking it with `cond` (an expression in x); `allowed`
// describes the accepted values for the message.
#define IMUCAL_CFG_INT(map, key, path, out, cond, allowed)                                               \
  if (const YAML::Node n_ = (map)[key]; n_) {                                                            \
    auto v_ = get_int(n_, path);                                                                         \
    if (!v_.ok()) return v_.error();                                                                     \
    const long long x = *v_;                                                                             \
    if (!(cond)) return error(n_, path, printable(n_.Scalar()) + " is not allowed (" + (allowed) + ")"); \
    (out) = static_cast<int>(x);                                                                         \
  }

Status ConfigParser::parse_imu(const YAML::Node& node, ImuConfig& imu) const {
  IMUCAL_TRY(check_map(
      node, "imu",
      {"bus", "device", "driver", "iio_device", "i2c_address", "spi_config_speed_hz", "spi_data_speed_hz",
       "accel_range_g", "gyro_range_dps", "rate_hz", "dlpf_hz", "data_ready", "mounting"}));
  const YAML::Node bus = node["bus"];
  if (!bus) return error(node, "imu.bus", "missing (spi, i2c or sim)");
  auto bus_name = get_string(bus, "imu.bus");
  if (!bus_name.ok()) return bus_name.error();
  if (*bus_name == "spi") {
    imu.bus = ImuBus::kSpi;
    imu.device = "/dev/spidev0.0";
  } else if (*bus_name == "i2c") {
    imu.bus = ImuBus::kI2c;
    imu.device = "/dev/i2c-1";
  } else if (*bus_name == "sim") {
    imu.bus = ImuBus::kSim;
    imu.device = "sim";
  } else {
    return error(bus, "imu.bus", "'" + *bus_name + "' is not allowed (spi, i2c or sim)");
  }

  if (const YAML::Node n = node["device"]) {
    auto d = get_string(n, "imu.device");
    if (!d.ok()) return d.error();
    if (imu.bus == ImuBus::kSim && *d != "sim") {
      return error(n, "imu.device", "must be 'sim' (or absent) with bus: sim");
    }
    if (imu.bus != ImuBus::kSim && (d->empty() || (*d)[0] != '/')) {
      return error(n, "imu.device", "'" + *d + "' is not a device path (e.g. /dev/spidev0.0 or /dev/i2c-1)");
    }
    imu.device = *d;
  }
  IMUCAL_TRY(parse_imu_driver(node, imu));
  // Keys that belong to the other bus are mistakes, not options to ignore.
  for (const char* key : {"spi_config_speed_hz", "spi_data_speed_hz"}) {
    if (node[key] && imu.bus != ImuBus::kSpi) {
      return error(node[key], std::string("imu.") + key, "applies only to bus: spi");
    }
  }
  if (node["i2c_address"] && imu.bus != ImuBus::kI2c) {
    return error(node["i2c_address"], "imu.i2c_address", "applies only to bus: i2c");
  }
  IMUCAL_CFG_INT(node, "i2c_address", "imu.i2c_address", imu.i2c_address, x == 0x68 || x == 0x69,
                 "0x68 with AD0 low, 0x69 with AD0 high");
  IMUCAL_CFG_INT(node, "spi_config_speed_hz", "imu.spi_config_speed_hz", imu.spi_config_speed_hz,
                 x >= 100'000 && x <= 1'000'000,
                 "100000..1000000: the MPU-6000 takes register writes at 1 MHz at most");
  IMUCAL_CFG_INT(node, "spi_data_speed_hz", "imu.spi_data_speed_hz", imu.spi_data_speed_hz,
                 x >= 100'000 && x <= 20'000'000,
                 "100000..20000000: the MPU-6000 reads sensor registers at 20 MHz at most");
  IMUCAL_CFG_INT(node, "accel_range_g", "imu.accel_range_g", imu.accel_range_g,
                 x == 2 || x == 4 || x == 8 || x == 16, "allowed: 2, 4, 8, 16");
  IMUCAL_CFG_INT(node, "gyro_range_dps", "imu.gyro_range_dps", imu.gyro_range_dps,
                 x == 250 || x == 500 || x == 1000 || x == 2000, "allowed: 250, 500, 1000, 2000");
  IMUCAL_CFG_INT(
      node, "dlpf_hz", "imu.dlpf_hz", imu.dlpf_hz,
      std::find(std::begin(kMpu6000DlpfHz), std::end(kMpu6000DlpfHz), x) != std::end(kMpu6000DlpfHz),
      "allowed: 256, 188, 98, 42, 20, 10, 5 (gyro bandwidth of DLPF_CFG 0..6)");
  if (const YAML::Node n = node["rate_hz"]) {
    auto r = get_double(n, "imu.rate_hz");
    if (!r.ok()) return r.error();
    imu.rate_hz = *r;
  }
  // SMPLRT_DIV: rate = base / (1 + div), div in 0..255; base is 8 kHz with DLPF_CFG 0, else 1 kHz.
  const double base_hz = imu.dlpf_hz == 256 ? 8000.0 : 1000.0;
  const double divisor = base_hz / imu.rate_hz;
  if (!(imu.rate_hz > 0) || std::abs(divisor - std::round(divisor)) > 1e-9 || divisor < 1 || divisor > 256) {
    const YAML::Node n = node["rate_hz"] ? node["rate_hz"] : node;
    std::ostringstream msg;
    msg << imu.rate_hz << " Hz cannot be produced with dlpf_hz " << imu.dlpf_hz << ": the rate must be "
        << base_hz << " / N for an integer N in 1..256 (e.g. " << base_hz << ", " << base_hz / 2 << ", "
        << base_hz / 5 << ", " << base_hz / 10 << ")";
    return error(n, "imu.rate_hz", msg.str());
  }

  if (const YAML::Node n = node["data_ready"]) IMUCAL_TRY(parse_data_ready(n, imu));
  if (const YAML::Node n = node["mounting"]) IMUCAL_TRY(parse_mounting(n, imu.R_rig_imu));
  return {};
}

// sides: {front: +x, left: +y, top: +z}: each a signed rig axis; the three must be a
// right-handed set, as a real rig's front, left and top are.
Status ConfigParser::parse_sides(const YAML::Node& node, RigSides& sides) const {
  IMUCAL_TRY(check_map(node, "sides", {"front", "left", "top"}));
  const std::pair<const char*, Eigen::Vector3d*> keys[] = {
      {"front", &sides.front}, {"left", &sides.left}, {"top", &sides.top}};
  for (const auto& [key, axis] : keys) {
    const std::string path = std::string("sides.") + key;
    if (!node[key]) return error(node, path, "missing (give front, left and top, e.g. +x, +y, +z)");
    auto text = get_string(node[key], path);
    if (!text.ok()) return text.error();
    std::string t = *text;
    std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return std::tolower(c); });
    if (t.size() != 2 || (t[0] != '+' && t[0] != '-') || t[1] < 'x' || t[1] > 'z') {
      return error(node[key], path, "'" + printable(*text) + "' is not a rig axis (+x, -x, +y, -y, +z, -z)");
    }
    *axis = Eigen::Vector3d::Unit(t[1] - 'x') * (t[0] == '-' ? -1.0 : 1.0);
  }
  if (std::abs(sides.front.dot(sides.left)) > 0.5 || std::abs(sides.front.dot(sides.top)) > 0.5 ||
      std::abs(sides.left.dot(sides.top)) > 0.5) {
    return error(node, "sides", "front, left and top must be three different axes");
  }
  if (sides.front.cross(sides.left).dot(sides.top) < 0.5) {
    return error(node, "sides",
                 "front x left is not top: a rig's front, left and top sides form a right-handed set; "
                 "check the signs (for example front +x, left +y, top +z)");
  }
  return {};
}

// driver and iio_device: who reads the chip, and what they exclude (sim, data_ready).
Status ConfigParser::parse_imu_driver(const YAML::Node& node, ImuConfig& imu) const {
  if (const YAML::Node n = node["driver"]) {
    auto d = get_string(n, "imu.driver");
    if (!d.ok()) return d.error();
    if (*d == "direct") {
      imu.driver = ImuDriver::kDirect;
    } else if (*d == "iio") {
      imu.driver = ImuDriver::kIio;
    } else if (*d == "auto") {
      imu.driver = ImuDriver::kAuto;
    } else {
      return error(n, "imu.driver",
                   "'" + *d +
                       "' is not allowed (direct: imucal's own driver through spidev or i2c-dev; iio: the "
                       "kernel's inv-mpu6050 driver; auto: the kernel's when it owns the chip)");
    }
    if (imu.bus == ImuBus::kSim && imu.driver == ImuDriver::kIio) {
      return error(n, "imu.driver", "iio needs a hardware bus (spi or i2c), not bus: sim");
    }
  }
  if (const YAML::Node n = node["iio_device"]) {
    auto d = get_string(n, "imu.iio_device");
    if (!d.ok()) return d.error();
    if (d->rfind("iio:device", 0) != 0)
      return error(n, "imu.iio_device", "'" + *d + "' is not an IIO device (e.g. iio:device0)");
    if (imu.driver == ImuDriver::kDirect)
      return error(n, "imu.iio_device", "applies only to driver: iio or auto");
    imu.iio_device = *d;
  }
  if (node["data_ready"] && imu.driver == ImuDriver::kIio) {
    return error(node["data_ready"], "imu.data_ready",
                 "applies only to the direct driver: with driver: iio the kernel owns the chip's interrupt");
  }
  return {};
}

// data_ready: {chip, line}, the INT pin's GPIO line.
Status ConfigParser::parse_data_ready(const YAML::Node& n, ImuConfig& imu) const {
  IMUCAL_TRY(check_map(n, "imu.data_ready", {"chip", "line"}));
  GpioLineConfig line;
  if (!n["chip"]) return error(n, "imu.data_ready.chip", "missing (e.g. gpiochip0)");
  auto chip = get_string(n["chip"], "imu.data_ready.chip");
  if (!chip.ok()) return chip.error();
  if (chip->empty()) return error(n["chip"], "imu.data_ready.chip", "is empty (e.g. gpiochip0)");
  line.chip = *chip;
  if (!n["line"]) return error(n, "imu.data_ready.line", "missing (the line offset on the chip)");
  IMUCAL_CFG_INT(n, "line", "imu.data_ready.line", line.line, x >= 0 && x < 4096, "a line offset 0..4095");
  imu.data_ready = line;
  return {};
}

Status ConfigParser::parse_mounting(const YAML::Node& node, Eigen::Matrix3d& R_rig_imu) const {
  IMUCAL_TRY(check_map(node, "imu.mounting", {"R_rig_imu", "rpy_deg"}));
  if (node["R_rig_imu"] && node["rpy_deg"]) {
    return error(node, "imu.mounting", "give either R_rig_imu or rpy_deg, not both");
  }
  if (const YAML::Node n = node["rpy_deg"]) {
    auto v = get_doubles(n, "imu.mounting.rpy_deg");
    if (!v.ok()) return v.error();
    if (v->size() != 3) return error(n, "imu.mounting.rpy_deg", "expected [roll, pitch, yaw] in degrees");
    const double k = M_PI / 180.0;
    R_rig_imu = (Eigen::AngleAxisd((*v)[2] * k, Eigen::Vector3d::UnitZ()) *
                 Eigen::AngleAxisd((*v)[1] * k, Eigen::Vector3d::UnitY()) *
                 Eigen::AngleAxisd((*v)[0] * k, Eigen::Vector3d::UnitX()))
                    .toRotationMatrix();
    return {};
  }
  const YAML::Node n = node["R_rig_imu"];
  if (!n) return error(node, "imu.mounting", "give R_rig_imu (3x3 rows) or rpy_deg [roll, pitch, yaw]");
  const std::string path = "imu.mounting.R_rig_imu";
  std::vector<double> values;
  if (n.IsSequence() && n.size() == 3 && n[0].IsSequence()) {
    for (std::size_t r = 0; r < 3; ++r) {
      auto row = get_doubles(n[r], path + "[" + std::to_string(r) + "]");
      if (!row.ok()) return row.error();
      if (row->size() != 3) return error(n[r], path, "each row needs 3 numbers");
      values.insert(values.end(), row->begin(), row->end());
    }
  } else {
    auto flat = get_doubles(n, path);
    if (!flat.ok()) return flat.error();
    values = *flat;
  }
  if (values.size() != 9) return error(n, path, "expected 3 rows of 3 numbers (or 9 numbers, row-major)");
  Eigen::Matrix3d R;
  for (int i = 0; i < 9; ++i) R(i / 3, i % 3) = values[static_cast<std::size_t>(i)];
  const double ortho = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (ortho > kRotationTolerance) {
    std::ostringstream msg;
    msg << "not orthonormal (largest entry of R^T R - I is " << ortho << ", tolerance " << kRotationTolerance
        << "); give a rotation matrix, or use rpy_deg";
    return error(n, path, msg.str());
  }
  if (R.determinant() < 0) return error(n, path, "has determinant -1 (a reflection, not a rotation)");
  // Project a matrix with visible round-off (e.g. 0.7071) onto the nearest rotation; leave one
  // that is orthonormal to machine precision as written, so normalized output round-trips.
  if (ortho > 1e-12) {
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
    R = svd.matrixU() * svd.matrixV().transpose();
  }
  R_rig_imu = R;
  return {};
}

Status ConfigParser::parse_camera(const YAML::Node& node, const std::string& path, CameraConfig& cam) const {
  IMUCAL_TRY(check_map(node, path,
                       {"name", "backend", "device", "width", "height", "rate_hz", "pixel_format", "shutter",
                        "line_delay_us", "readout_direction", "stamp_row"}));
  if (!node["name"]) return error(node, path + ".name", "missing (e.g. cam0)");
  auto name = get_string(node["name"], path + ".name");
  if (!name.ok()) return name.error();
  if (name->empty() || !std::all_of(name->begin(), name->end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
      })) {
    return error(node["name"], path + ".name", "'" + *name + "' is not allowed (letters, digits, _ and -)");
  }
  cam.name = *name;
  if (!node["backend"]) return error(node, path + ".backend", "missing (v4l2, libcamera, aravis or sim)");
  auto backend = get_string(node["backend"], path + ".backend");
  if (!backend.ok()) return backend.error();
  if (*backend == "v4l2") {
    cam.backend = CameraBackend::kV4l2;
    cam.pixel_format = "GREY";
  } else if (*backend == "libcamera") {
    cam.backend = CameraBackend::kLibcamera;
    cam.pixel_format = "YUV420";
  } else if (*backend == "aravis") {
    cam.backend = CameraBackend::kAravis;
    cam.pixel_format = "Mono8";
  } else if (*backend == "sim") {
    cam.backend = CameraBackend::kSim;
    cam.pixel_format = "GREY";
    cam.device = "sim";
  } else {
    return error(node["backend"], path + ".backend",
                 "'" + *backend + "' is not allowed (v4l2, libcamera, aravis or sim)");
  }
  if (const YAML::Node n = node["device"]) {
    auto d = get_string(n, path + ".device");
    if (!d.ok()) return d.error();
    cam.device = *d;
  }
  if (cam.backend == CameraBackend::kV4l2 && cam.device.rfind("/dev/", 0) != 0) {
    return error(node["device"] ? node["device"] : node, path + ".device",
                 "v4l2 needs a device node such as /dev/video0");
  }
  if (cam.backend == CameraBackend::kAravis && cam.device.empty()) {
    return error(node, path + ".device",
                 "aravis needs a device id (see arv-tool-0.8; Fake_1 for the fake camera)");
  }
  if (cam.backend == CameraBackend::kSim && cam.device != "sim") {
    return error(node["device"], path + ".device", "must be 'sim' (or absent) with backend: sim");
  }
  for (const char* key : {"width", "height"}) {
    if (!node[key]) return error(node, path + "." + key, "missing (pixels)");
  }
  IMUCAL_CFG_INT(node, "width", path + ".width", cam.width, x >= 16 && x <= 16384, "16..16384 pixels");
  IMUCAL_CFG_INT(node, "height", path + ".height", cam.height, x >= 16 && x <= 16384, "16..16384 pixels");
  if (!node["rate_hz"]) return error(node, path + ".rate_hz", "missing (frames per second)");
  auto rate = get_double(node["rate_hz"], path + ".rate_hz");
  if (!rate.ok()) return rate.error();
  // 0: the camera's own rate, for a camera without a rate control (libcamera pipelines without
  // FrameDurationLimits); the virtual camera needs a rate.
  if (!(*rate >= 0.0 && *rate <= 1000.0) || (*rate == 0.0 && cam.backend == CameraBackend::kSim)) {
    return error(
        node["rate_hz"], path + ".rate_hz",
        cam.backend == CameraBackend::kSim
            ? "must be > 0 and <= 1000 frames per second"
            : "must be 0 (the camera's own rate, when it has no rate control) to 1000 frames per second");
  }
  cam.rate_hz = *rate;
  if (const YAML::Node n = node["pixel_format"]) {
    auto f = get_string(n, path + ".pixel_format");
    if (!f.ok()) return f.error();
    const bool printable = !f->empty() && std::all_of(f->begin(), f->end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == ' ';
    });
    if (!printable) return error(n, path + ".pixel_format", "'" + *f + "' is not a pixel format name");
    if ((cam.backend == CameraBackend::kV4l2 || cam.backend == CameraBackend::kSim) && f->size() != 4) {
      return error(n, path + ".pixel_format",
                   "'" + *f + "' is not a V4L2 fourcc (4 characters, e.g. GREY, YUYV, Y16 )");
    }
    cam.pixel_format = *f;
  }
  return parse_shutter(node, path, cam);
}

Status ConfigParser::parse_shutter(const YAML::Node& node, const std::string& path, CameraConfig& cam) const {
  cam.shutter = Shutter{};
  std::string kind = "global";
  if (const YAML::Node n = node["shutter"]) {
    auto k = get_string(n, path + ".shutter");
    if (!k.ok()) return k.error();
    if (*k != "global" && *k != "rolling")
      return error(n, path + ".shutter", "'" + *k + "' is not allowed (global or rolling)");
    kind = *k;
  }
  if (kind == "global") {
    for (const char* key : {"line_delay_us", "readout_direction", "stamp_row"})
      if (node[key])
        return error(node[key], path + "." + key, "is for a rolling shutter: add shutter: rolling");
    return {};
  }
  cam.shutter.kind = Shutter::Kind::kRolling;
  if (const YAML::Node n = node["line_delay_us"]) {
    auto d = get_double(n, path + ".line_delay_us");
    if (!d.ok()) return d.error();
    if (!(*d >= 0.0) || *d * 1e-6 * (cam.height - 1) > 1.0)
      return error(n, path + ".line_delay_us",
                   "must be >= 0 microseconds per row (0: estimated), the frame read out within 1 s");
    cam.shutter.line_delay_s = *d * 1e-6;
  }
  if (const YAML::Node n = node["readout_direction"]) {
    auto d = get_string(n, path + ".readout_direction");
    if (!d.ok()) return d.error();
    if (*d != "top_to_bottom" && *d != "bottom_to_top")
      return error(n, path + ".readout_direction",
                   "'" + *d + "' is not allowed (top_to_bottom or bottom_to_top)");
    cam.shutter.readout =
        *d == "bottom_to_top" ? Shutter::Readout::kBottomToTop : Shutter::Readout::kTopToBottom;
  }
  if (const YAML::Node n = node["stamp_row"]) {
    auto r = get_string(n, path + ".stamp_row");
    if (!r.ok()) return r.error();
    if (*r != "first" && *r != "middle" && *r != "last")
      return error(n, path + ".stamp_row", "'" + *r + "' is not allowed (first, middle or last)");
    cam.shutter.stamp_row = *r == "middle" ? Shutter::StampRow::kMiddle
                            : *r == "last" ? Shutter::StampRow::kLast
                                           : Shutter::StampRow::kFirst;
  }
  if (cam.backend == CameraBackend::kSim && !(cam.shutter.line_delay_s > 0.0))
    return error(node, path + ".line_delay_us",
                 "the virtual camera renders a rolling shutter with a line delay > 0");
  return {};
}

Status ConfigParser::parse_target(const YAML::Node& node, RigConfig& config) const {
  if (node.IsScalar()) {
    std::filesystem::path p(node.Scalar());
    if (p.is_relative()) p = std::filesystem::path(base_dir_) / p;
    auto text = read_text_file(p.string(), kMaxConfigFileBytes);
    if (!text.ok()) return error(node, "target", "target file: " + text.error().message);
    auto t = parse_target_yaml(*text, p.string());
    if (!t.ok()) return error(node, "target", t.error().message);
    config.target = *t;
    return {};
  }
  if (!node.IsMap())
    return error(node, "target", "expected a Kalibr target mapping or a path to a target YAML");
  // Kalibr keys for either target type; parse_target_yaml checks which ones the type needs.
  IMUCAL_TRY(check_map(node, "target",
                       {"target_type", "targetCols", "targetRows", "rowSpacingMeters", "colSpacingMeters",
                        "tagCols", "tagRows", "tagSize", "tagSpacing", "codeOffset"}));
  YAML::Emitter out;
  out << node;
  auto t = parse_target_yaml(out.c_str(), source_);
  if (!t.ok()) {
    std::string msg = t.error().message;
    if (msg.rfind(source_ + ": ", 0) == 0) msg = msg.substr(source_.size() + 2);
    return error(node, "target", msg);
  }
  config.target = *t;
  return {};
}

Status ConfigParser::parse_storage(const YAML::Node& node, StorageConfig& storage) const {
  IMUCAL_TRY(check_map(node, "storage",
                       {"backend", "path", "i2c_device", "i2c_address", "page_bytes", "address_bytes",
                        "size_bytes", "offset_bytes", "program_gyro_offsets"}));
  if (!node["backend"]) return error(node, "storage.backend", "missing (file, nvmem or i2c-eeprom)");
  auto backend = get_string(node["backend"], "storage.backend");
  if (!backend.ok()) return backend.error();
  if (*backend == "file") {
    storage.backend = StorageBackend::kFile;
  } else if (*backend == "nvmem") {
    storage.backend = StorageBackend::kNvmem;
  } else if (*backend == "i2c-eeprom") {
    storage.backend = StorageBackend::kI2cEeprom;
  } else {
    return error(node["backend"], "storage.backend",
                 "'" + *backend + "' is not allowed (file, nvmem or i2c-eeprom)");
  }
  const bool i2c = storage.backend == StorageBackend::kI2cEeprom;
  for (const char* key : {"i2c_device", "i2c_address", "page_bytes", "address_bytes"}) {
    if (node[key] && !i2c)
      return error(node[key], std::string("storage.") + key, "applies only to backend: i2c-eeprom");
  }
  if (node["path"] && i2c)
    return error(node["path"], "storage.path", "does not apply to backend: i2c-eeprom (use i2c_device)");
  if (!i2c) {
    if (!node["path"] && storage.backend == StorageBackend::kNvmem) {
      return error(node, "storage.path", "missing (e.g. /sys/bus/nvmem/devices/0-00500/nvmem)");
    }
    if (const YAML::Node n = node["path"]) {
      auto p = get_string(n, "storage.path");
      if (!p.ok()) return p.error();
      if (p->empty()) return error(n, "storage.path", "is empty");
      storage.path = *p;
    }
  } else {
    if (!node["i2c_device"]) return error(node, "storage.i2c_device", "missing (e.g. /dev/i2c-1)");
    auto d = get_string(node["i2c_device"], "storage.i2c_device");
    if (!d.ok()) return d.error();
    if (d->rfind("/dev/", 0) != 0)
      return error(node["i2c_device"], "storage.i2c_device",
                   "'" + *d + "' is not a device path (e.g. /dev/i2c-1)");
    storage.i2c_device = *d;
    IMUCAL_CFG_INT(node, "i2c_address", "storage.i2c_address", storage.i2c_address, x >= 0x50 && x <= 0x57,
                   "an EEPROM address 0x50..0x57");
    IMUCAL_CFG_INT(node, "page_bytes", "storage.page_bytes", storage.page_bytes,
                   x >= 1 && x <= 256 && (x & (x - 1)) == 0,
                   "the EEPROM's write page, a power of two 1..256 (24c02: 8, 24c32: 32; see its datasheet)");
    IMUCAL_CFG_INT(node, "address_bytes", "storage.address_bytes", storage.address_bytes, x == 1 || x == 2,
                   "1 (24c01..24c16) or 2 (24c32 and larger)");
  }
  IMUCAL_CFG_INT(node, "size_bytes", "storage.size_bytes", storage.size_bytes, x >= 256 && x <= (1 << 24),
                 "256..16777216 bytes; two A/B slots must fit");
  IMUCAL_CFG_INT(node, "offset_bytes", "storage.offset_bytes", storage.offset_bytes, x >= 0 && x <= (1 << 24),
                 "0..16777216 bytes");
  if (const YAML::Node n = node["program_gyro_offsets"]) {
    if (!n.IsScalar() || (n.Scalar() != "true" && n.Scalar() != "false"))
      return error(n, "storage.program_gyro_offsets", "expected true or false");
    storage.program_gyro_offsets = n.Scalar() == "true";
  }
  return {};
}

Status ConfigParser::parse_live_view(const YAML::Node& node, LiveViewConfig& live) const {
  IMUCAL_TRY(check_map(node, "live_view", {"enabled", "address", "port", "frame_rate_hz", "width"}));
  if (const YAML::Node n = node["enabled"]) {
    if (!n.IsScalar() || (n.Scalar() != "true" && n.Scalar() != "false"))
      return error(n, "live_view.enabled", "expected true or false");
    live.enabled = n.Scalar() == "true";
  }
  if (const YAML::Node n = node["address"]) {
    auto a = get_string(n, "live_view.address");
    if (!a.ok()) return a.error();
    const bool address_chars =
        !a->empty() && a->size() <= 45 && std::all_of(a->begin(), a->end(), [](char c) {
          return std::isxdigit(static_cast<unsigned char>(c)) || c == '.' || c == ':';
        });
    if (!address_chars)
      return error(n, "live_view.address",
                   "'" + printable(*a) +
                       "' is not an IP address (127.0.0.1, the default; 0.0.0.0 for every interface)");
    live.address = *a;
  }
  IMUCAL_CFG_INT(node, "port", "live_view.port", live.port, x >= 1 && x <= 65535, "1..65535");
  if (const YAML::Node n = node["frame_rate_hz"]) {
    auto v = get_double(n, "live_view.frame_rate_hz");
    if (!v.ok()) return v.error();
    if (!(*v >= 0.2 && *v <= 30.0)) return error(n, "live_view.frame_rate_hz", "is not in range 0.2 to 30");
    live.frame_rate_hz = *v;
  }
  IMUCAL_CFG_INT(node, "width", "live_view.width", live.width, x >= 80 && x <= 1920, "80..1920 pixels");
  return {};
}

Status ConfigParser::parse_session(const YAML::Node& node, SessionConfig& session) const {
  std::vector<std::string> allowed = {"steps", "poses", "poses_min", "auto_write"};
  for (const auto& n : kSessionNumbers) allowed.emplace_back(n.key);
  IMUCAL_TRY(check_map(node, "session", allowed));
  for (const auto& entry : kSessionNumbers) {
    const YAML::Node n = node[entry.key];
    if (!n) continue;
    const std::string path = std::string("session.") + entry.key;
    auto v = get_double(n, path);
    if (!v.ok()) return v.error();
    if (*v < entry.min || *v > entry.max) {
      std::ostringstream range;
      range << entry.min << " to " << entry.max;
      return error(n, path, printable(n.Scalar()) + " is not in range " + range.str());
    }
    session.*entry.member = *v;
  }
  IMUCAL_CFG_INT(node, "poses", "session.poses", session.poses, x >= 9 && x <= 200,
                 "9..200; the static method needs at least 9 attitudes");
  IMUCAL_CFG_INT(node, "poses_min", "session.poses_min", session.poses_min, x >= 9 && x <= 200, "9..200");
  if (session.poses_min > session.poses)
    return error(node["poses_min"], "session.poses_min", "is above session.poses");
  if (const YAML::Node n = node["auto_write"]) {
    if (!n.IsScalar() || (n.Scalar() != "true" && n.Scalar() != "false"))
      return error(n, "session.auto_write", "expected true or false");
    session.auto_write = n.Scalar() == "true";
  }
  if (const YAML::Node n = node["steps"]) {
    if (!n.IsSequence()) return error(n, "session.steps", "expected a list of step names");
    const auto& names = session_step_names();
    std::size_t last = 0;
    for (std::size_t i = 0; i < n.size(); ++i) {
      auto name = get_string(n[i], "session.steps");
      if (!name.ok()) return name.error();
      const auto it = std::find(names.begin(), names.end(), *name);
      if (it == names.end()) {
        std::string all;
        for (const auto& s : names) all += (all.empty() ? "" : ", ") + s;
        return error(n[i], "session.steps", "'" + *name + "' is not a step (" + all + ")");
      }
      const auto index = static_cast<std::size_t>(it - names.begin()) + 1;
      if (index <= last)
        return error(n[i], "session.steps", "'" + *name + "' is repeated or out of protocol order");
      last = index;
      session.steps.push_back(*name);
    }
  }
  return {};
}

namespace {

/// Counts the documents of a YAML stream and notes where the second starts.
class DocumentCounter final : public YAML::EventHandler {
 public:
  int documents = 0;
  int second_line = 0;  // 1-based; 0 while there is no second document
  void OnDocumentStart(const YAML::Mark& mark) override {
    if (++documents == 2) second_line = mark.line + 1;
  }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t) override { note(mark); }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override { note(mark); }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t, const std::string&) override {
    note(mark);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
    note(mark);
  }
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
    note(mark);
  }
  void OnMapEnd() override {}

 private:
  // The document start mark of a document after an unreadable token is not always set.
  void note(const YAML::Mark& mark) {
    if (documents == 2 && second_line <= 0) second_line = mark.line + 1;
  }
};

/// The line of the second document of `text`, if it has more than one. Throws what the parser
/// throws on malformed text.
std::optional<int> second_document_line(const std::string& text) {
  std::istringstream in(text);
  YAML::Parser parser(in);
  DocumentCounter counter;
  for (int k = 0; k < 2 && parser.HandleNextDocument(counter); ++k) {
  }
  if (counter.documents < 2) return std::nullopt;
  return std::max(counter.second_line, 1);
}

}  // namespace

Result<RigConfig> ConfigParser::parse(const std::string& text) {
  YAML::Node root;
  try {
    // YAML::LoadAll of yaml-cpp 0.7 never returns on some malformed text (", x" grows its list
    // of documents without bound, jbeder/yaml-cpp#1319): the documents are counted here with a
    // bound, and the first is loaded on its own.
    if (const auto second = second_document_line(text)) {
      return make_error(
          Errc::kInvalidArgument,
          source_ + ":" + std::to_string(*second) +
              ": a second YAML document ('---'), or text after the first that YAML cannot read; "
              "a rig configuration is one document");
    }
    root = YAML::Load(text);
  } catch (const YAML::DeepRecursion& e) {
    return make_error(Errc::kInvalidArgument, source_ + ":" + std::to_string(e.mark.line + 1) +
                                                  ": nested more than " + std::to_string(e.depth()) +
                                                  " levels deep: not a rig configuration");
  } catch (const YAML::ParserException& e) {
    return make_error(Errc::kInvalidArgument,
                      source_ + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
  }
  if (!root.IsMap())
    return error(
        root, "",
        "expected a mapping with keys name, imu, sides, cameras, target, storage, session, live_view");
  IMUCAL_TRY(
      check_map(root, "", {"name", "imu", "sides", "cameras", "target", "storage", "session", "live_view"}));
  RigConfig config;
  if (const YAML::Node n = root["name"]) {
    auto name = get_string(n, "name");
    if (!name.ok()) return name.error();
    if (name->empty() || !std::all_of(name->begin(), name->end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
        })) {
      return error(n, "name", "'" + printable(*name) + "' is not allowed (letters, digits, '_', '-', '.')");
    }
    config.name = *name;
  }
  if (!root["imu"]) return error(root, "imu", "missing (the MPU-6000 settings, at least imu.bus)");
  IMUCAL_TRY(parse_imu(root["imu"], config.imu));
  if (const YAML::Node n = root["sides"]) {
    config.sides.emplace();
    IMUCAL_TRY(parse_sides(n, *config.sides));
  }
  if (const YAML::Node n = root["cameras"]) {
    if (!n.IsSequence()) return error(n, "cameras", "expected a list of cameras");
    std::set<std::string> names;
    for (std::size_t i = 0; i < n.size(); ++i) {
      const std::string path = "cameras[" + std::to_string(i) + "]";
      CameraConfig cam;
      IMUCAL_TRY(parse_camera(n[i], path, cam));
      if (!names.insert(cam.name).second) {
        return error(n[i]["name"], path + ".name", "'" + cam.name + "' is used by another camera");
      }
      config.cameras.push_back(cam);
    }
  }
  if (const YAML::Node n = root["target"]) IMUCAL_TRY(parse_target(n, config));
  if (!config.cameras.empty() && !config.target) {
    return error(root, "target",
                 "missing: cameras are configured, so a calibration target is needed "
                 "(a Kalibr target mapping or a path to a target YAML)");
  }
  if (const YAML::Node n = root["storage"]) IMUCAL_TRY(parse_storage(n, config.storage));
  if (const YAML::Node n = root["session"]) IMUCAL_TRY(parse_session(n, config.session));
  if (const YAML::Node n = root["live_view"]) IMUCAL_TRY(parse_live_view(n, config.live_view));
  return config;
}

#undef IMUCAL_CFG_INT

}  // namespace

const std::vector<std::string>& session_step_names() {
  static const std::vector<std::string> names = {"preflight", "warmup", "thermal", "still",  "poses",
                                                 "gsens",     "motion", "solve",   "review", "write"};
  return names;
}

Status validate_rig_config(const RigConfig& config) {
  // Round-trip through the normalized YAML, so code-built configurations obey the same rules.
  auto reparsed = parse_rig_config(rig_config_to_yaml(config), "<rig config>");
  if (!reparsed.ok()) return reparsed.error();
  return {};
}

Result<RigConfig> parse_rig_config(const std::string& text, const std::string& source,
                                   const std::string& base_dir) {
  ConfigParser parser(source, base_dir);
  return parser.parse(text);
}

Result<RigConfig> load_rig_config(const std::string& path) {
  auto text = read_text_file(path, kMaxConfigFileBytes);
  if (!text.ok()) {
    return make_error(text.error().code, "cannot open the rig configuration: " + text.error().message +
                                             " (the default one is config/rig.yaml)");
  }
  const std::string dir = std::filesystem::path(path).parent_path().string();
  return parse_rig_config(*text, path, dir.empty() ? "." : dir);
}

}  // namespace imucal
