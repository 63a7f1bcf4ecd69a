// SPDX-License-Identifier: BSD-3-Clause
// sensor_msgs/msg/Imu, Image and CompressedImage in CDR, as ROS 2 serializes them (log/rosbag2.hpp):
// a 4-byte encapsulation header (0x00 0x01: little-endian CDR), then the fields, each aligned to
// its size counted from the end of that header; strings are a uint32 length that counts the
// terminating NUL, then the characters and the NUL; sequences a uint32 count, then the elements.

#include <cstring>

#include "log/rosbag2.hpp"
#include "log/rosbag_format.hpp"

namespace imucal::log::rosbag2 {
namespace {

class CdrCursor {
 public:
  explicit CdrCursor(std::span<const std::uint8_t> data) : data_(data) {
    if (data.size() < 4) {
      ok_ = false;
    } else {
      little_ = data[1] == 0x01 || data[1] == 0x03;  // CDR_LE, PL_CDR_LE
      pos_ = 4;
    }
  }
  bool ok() const { return ok_; }
  bool little_endian() const { return little_; }
  std::size_t left() const { return data_.size() - pos_; }

  std::uint8_t u8() { return take(1, 1) ? data_[pos_ - 1] : 0; }
  std::uint32_t u32() { return take(4, 4) ? rosbag::format::le32(data_.data() + pos_ - 4) : 0; }
  std::int32_t i32() { return static_cast<std::int32_t>(u32()); }
  double f64() {
    if (!take(8, 8)) return 0.0;
    const std::uint64_t bits = rosbag::format::le64(data_.data() + pos_ - 8);
    double v = 0.0;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }
  std::string text() {
    const std::uint32_t n = u32();
    if (!take(n, 1)) return {};
    if (n == 0) return {};
    const auto* p = reinterpret_cast<const char*>(data_.data() + pos_ - n);
    return std::string(p, n - 1);  // without the NUL
  }
  std::span<const std::uint8_t> bytes() {
    const std::uint32_t n = u32();
    if (!take(n, 1)) return {};
    return data_.subspan(pos_ - n, n);
  }
  Eigen::Vector3d vec3() {
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v[i] = f64();
    return v;
  }
  /// Trailing bytes up to 3 are CDR's padding of the message to 4 bytes.
  bool finished() const { return ok_ && left() < 4; }

 private:
  bool take(std::size_t n, std::size_t align) {
    if (!ok_) return false;
    const std::size_t offset = pos_ - 4;
    const std::size_t pad = (align - offset % align) % align;
    if (pad > data_.size() - pos_ || n > data_.size() - pos_ - pad) {
      ok_ = false;
      return false;
    }
    pos_ += pad + n;
    return true;
  }
  std::span<const std::uint8_t> data_;
  std::size_t pos_ = 0;
  bool ok_ = true;
  bool little_ = true;
};

struct Header {
  TimeNs stamp_ns = 0;
  std::string frame_id;
};

Result<Header> read_header(CdrCursor& c) {
  if (!c.ok()) return make_error(Errc::kCorrupt, "a CDR message shorter than its encapsulation header");
  if (!c.little_endian()) {
    return make_error(Errc::kUnsupported, "a big-endian CDR message (ROS 2 writes little-endian ones)");
  }
  const std::int32_t sec = c.i32();
  const std::uint32_t nsec = c.u32();
  Header h;
  h.frame_id = c.text();
  if (!c.ok()) return make_error(Errc::kCorrupt, "the message ends inside its header");
  h.stamp_ns = rosbag::format::header_stamp_ns(sec, nsec);
  return h;
}

Status finished(const CdrCursor& c, const char* type) {
  if (!c.ok())
    return make_error(Errc::kCorrupt, std::string("the ") + type + " message is shorter than its fields");
  if (!c.finished()) {
    return make_error(Errc::kCorrupt, std::string("the ") + type + " message has " +
                                          std::to_string(c.left()) + " bytes after its fields");
  }
  return {};
}

/// Appends fields with CDR's alignment.
class CdrWriter {
 public:
  CdrWriter() : out_{0x00, 0x01, 0x00, 0x00} {}
  void u8(std::uint8_t v) { out_.push_back(v); }
  void u32(std::uint32_t v) {
    align(4);
    rosbag::format::put32(out_, v);
  }
  void f64(double v) {
    align(8);
    std::uint64_t bits = 0;
    std::memcpy(&bits, &v, sizeof v);
    rosbag::format::put64(out_, bits);
  }
  void text(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    out_.insert(out_.end(), s.begin(), s.end());
    out_.push_back(0);
  }
  void bytes(std::span<const std::uint8_t> b) {
    u32(static_cast<std::uint32_t>(b.size()));
    out_.insert(out_.end(), b.begin(), b.end());
  }
  void header(TimeNs stamp_ns, const std::string& frame_id) {
    u32(static_cast<std::uint32_t>(stamp_ns / 1'000'000'000));
    u32(static_cast<std::uint32_t>(stamp_ns % 1'000'000'000));
    text(frame_id);
  }
  std::vector<std::uint8_t> take() {
    align(4);
    return std::move(out_);
  }

 private:
  void align(std::size_t n) {
    while ((out_.size() - 4) % n != 0) out_.push_back(0);
  }
  std::vector<std::uint8_t> out_;
};

}  // namespace

Result<TimeNs> header_stamp_cdr(std::span<const std::uint8_t> data) {
  CdrCursor c(data);
  auto h = read_header(c);
  if (!h.ok()) return h.error();
  return h->stamp_ns;
}

Result<rosbag::ImuMessage> decode_imu_cdr(std::span<const std::uint8_t> data) {
  CdrCursor c(data);
  auto h = read_header(c);
  if (!h.ok()) return h.error();
  rosbag::ImuMessage m;
  m.stamp_ns = h->stamp_ns;
  m.frame_id = h->frame_id;
  for (int i = 0; i < 4 + 9; ++i) c.f64();  // orientation and its covariance
  m.gyro = c.vec3();
  for (int i = 0; i < 9; ++i) c.f64();
  m.accel = c.vec3();
  for (int i = 0; i < 9; ++i) c.f64();
  IMUCAL_TRY(finished(c, "sensor_msgs/msg/Imu"));
  return m;
}

Result<rosbag::ImageMessage> decode_image_cdr(std::span<const std::uint8_t> data) {
  CdrCursor c(data);
  auto h = read_header(c);
  if (!h.ok()) return h.error();
  rosbag::ImageMessage m;
  m.stamp_ns = h->stamp_ns;
  m.frame_id = h->frame_id;
  const std::uint32_t height = c.u32();
  const std::uint32_t width = c.u32();
  m.encoding = c.text();
  const bool big_endian = c.u8() != 0;
  const std::uint32_t step = c.u32();
  auto pixels = c.bytes();
  IMUCAL_TRY(finished(c, "sensor_msgs/msg/Image"));
  auto image = rosbag::image_from_fields(width, height, m.encoding, big_endian, step, pixels);
  if (!image.ok()) return image.error();
  m.image = std::move(*image);
  return m;
}

Result<rosbag::CompressedImageMessage> decode_compressed_image_cdr(std::span<const std::uint8_t> data) {
  CdrCursor c(data);
  auto h = read_header(c);
  if (!h.ok()) return h.error();
  rosbag::CompressedImageMessage m;
  m.stamp_ns = h->stamp_ns;
  m.frame_id = h->frame_id;
  m.format = c.text();
  auto bytes = c.bytes();
  IMUCAL_TRY(finished(c, "sensor_msgs/msg/CompressedImage"));
  m.data.assign(bytes.begin(), bytes.end());
  return m;
}

std::vector<std::uint8_t> encode_imu_cdr(const rosbag::ImuMessage& m) {
  CdrWriter w;
  w.header(m.stamp_ns, m.frame_id);
  for (double v : {0.0, 0.0, 0.0, 1.0}) w.f64(v);
  w.f64(-1.0);  // orientation not estimated
  for (int i = 1; i < 9; ++i) w.f64(0.0);
  for (int i = 0; i < 3; ++i) w.f64(m.gyro[i]);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  for (int i = 0; i < 3; ++i) w.f64(m.accel[i]);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  return w.take();
}

std::vector<std::uint8_t> encode_image_cdr(const rosbag::ImageMessage& m) {
  const Image& image = m.image;
  CdrWriter w;
  w.header(m.stamp_ns, m.frame_id);
  w.u32(static_cast<std::uint32_t>(image.height));
  w.u32(static_cast<std::uint32_t>(image.width));
  w.text(image.channels == 3 ? "bgr8" : (image.depth == 16 ? "mono16" : "mono8"));
  w.u8(0);
  w.u32(static_cast<std::uint32_t>(image.row_bytes()));
  w.bytes(image.data);  // 16-bit samples in host order: little-endian on the machines imucal runs on
  return w.take();
}

}  // namespace imucal::log::rosbag2
