// SPDX-License-Identifier: BSD-3-Clause
// sensor_msgs/Imu, Image and CompressedImage in ROS 1 serialization (log/rosbag.hpp).

#include <cstring>
#include <string_view>

#include "log/rosbag.hpp"
#include "log/rosbag_format.hpp"

namespace imucal::log::rosbag {
namespace {

/// The widest image side taken (as the EuRoC import's).
constexpr std::uint32_t kMaxImageSide = 32768;

/// Reads fields in order; the first read past the end makes every later one fail.
class Cursor {
 public:
  explicit Cursor(std::span<const std::uint8_t> data) : data_(data) {}
  bool ok() const { return ok_; }
  bool at_end() const { return pos_ == data_.size(); }
  std::size_t left() const { return data_.size() - pos_; }

  std::uint8_t u8() { return take(1) ? data_[pos_ - 1] : 0; }
  std::uint32_t u32() { return take(4) ? format::le32(data_.data() + pos_ - 4) : 0; }
  double f64() {
    if (!take(8)) return 0.0;
    const std::uint64_t bits = format::le64(data_.data() + pos_ - 8);
    double v = 0.0;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }
  std::span<const std::uint8_t> bytes() {
    const std::uint32_t n = u32();
    if (!take(n)) return {};
    return data_.subspan(pos_ - n, n);
  }
  std::string text() {
    auto b = bytes();
    return std::string(reinterpret_cast<const char*>(b.data()), b.size());
  }
  Eigen::Vector3d vec3() {
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v[i] = f64();
    return v;
  }

 private:
  bool take(std::size_t n) {
    if (!ok_ || n > data_.size() - pos_) {
      ok_ = false;
      return false;
    }
    pos_ += n;
    return true;
  }
  std::span<const std::uint8_t> data_;
  std::size_t pos_ = 0;
  bool ok_ = true;
};

struct Header {
  TimeNs stamp_ns = 0;
  std::string frame_id;
};

Result<Header> read_header(Cursor& c) {
  Header h;
  c.u32();  // seq
  const std::uint32_t sec = c.u32();
  const std::uint32_t nsec = c.u32();
  h.frame_id = c.text();
  if (!c.ok()) return make_error(Errc::kCorrupt, "the message ends inside its header");
  h.stamp_ns = format::header_stamp_ns(sec, nsec);
  return h;
}

Status finished(const Cursor& c, const char* type) {
  if (!c.ok())
    return make_error(Errc::kCorrupt, std::string("the ") + type + " message is shorter than its fields");
  if (!c.at_end()) {
    return make_error(Errc::kCorrupt, std::string("the ") + type + " message has " +
                                          std::to_string(c.left()) + " bytes after its fields");
  }
  return {};
}

void put_header(std::vector<std::uint8_t>& out, std::uint32_t seq, TimeNs stamp_ns,
                const std::string& frame_id) {
  format::put32(out, seq);
  const std::uint64_t t = format::ros_time(stamp_ns);
  format::put64(out, t);
  format::put32(out, static_cast<std::uint32_t>(frame_id.size()));
  out.insert(out.end(), frame_id.begin(), frame_id.end());
}

void put_f64(std::vector<std::uint8_t>& out, double v) {
  std::uint64_t bits = 0;
  std::memcpy(&bits, &v, sizeof v);
  format::put64(out, bits);
}

void put_text(std::vector<std::uint8_t>& out, std::string_view s) {
  format::put32(out, static_cast<std::uint32_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}

/// How the pixels of an encoding are stored and what they become.
struct PixelLayout {
  int bytes_per_pixel = 0;
  int channels = 1;  // of the Image made
  int depth = 8;
};

Result<PixelLayout> layout_of(const std::string& encoding) {
  if (encoding == "mono8" || encoding == "8UC1") return PixelLayout{1, 1, 8};
  if (encoding == "mono16" || encoding == "16UC1") return PixelLayout{2, 1, 16};
  if (encoding == "bgr8" || encoding == "rgb8" || encoding == "8UC3") return PixelLayout{3, 3, 8};
  if (encoding == "yuv422") return PixelLayout{2, 3, 8};
  return make_error(Errc::kUnsupported, "an image of encoding '" + encoding +
                                            "' (imucal reads mono8, mono16, bgr8, rgb8 and yuv422)");
}

std::uint8_t clamp_byte(int v) { return static_cast<std::uint8_t>(std::clamp(v, 0, 255)); }

/// One row of yuv422 (U Y0 V Y1 per two pixels, ROS's name for UYVY) as BGR, with the BT.601
/// video-range conversion (1.164 (Y - 16), 1.596 V, 0.813 V + 0.391 U, 2.018 U), in 2^20 units.
void uyvy_row_to_bgr(const std::uint8_t* in, std::uint8_t* out, int width) {
  for (int x = 0; x + 1 < width; x += 2, in += 4) {
    const int u = in[0] - 128, v = in[2] - 128;
    const int ruv = (1 << 19) + 1673527 * v;  // 1.596 v, in 2^20 units
    const int guv = (1 << 19) - 852492 * v - 409993 * u;
    const int buv = (1 << 19) + 2116026 * u;
    for (int k = 0; k < 2; ++k) {
      const int y = std::max(0, in[1 + 2 * k] - 16) * 1220542;  // 1.164 y
      *out++ = clamp_byte((y + buv) >> 20);
      *out++ = clamp_byte((y + guv) >> 20);
      *out++ = clamp_byte((y + ruv) >> 20);
    }
  }
}

Image pixels_to_image(std::span<const std::uint8_t> pixels, std::uint32_t width, std::uint32_t height,
                      std::uint32_t step, const std::string& encoding, const PixelLayout& layout,
                      bool big_endian) {
  Image image =
      Image::zeros(static_cast<int>(width), static_cast<int>(height), layout.channels, layout.depth);
  const std::size_t out_row = image.row_bytes();
  for (std::uint32_t y = 0; y < height; ++y) {
    const std::uint8_t* in = pixels.data() + std::size_t{y} * step;
    std::uint8_t* out = image.data.data() + std::size_t{y} * out_row;
    if (encoding == "yuv422") {
      uyvy_row_to_bgr(in, out, static_cast<int>(width));
    } else if (encoding == "rgb8") {
      for (std::uint32_t x = 0; x < width; ++x) {
        out[3 * x] = in[3 * x + 2];
        out[3 * x + 1] = in[3 * x + 1];
        out[3 * x + 2] = in[3 * x];
      }
    } else if (layout.depth == 16) {
      for (std::uint32_t x = 0; x < width; ++x) {
        const std::uint16_t v = big_endian ? static_cast<std::uint16_t>((in[2 * x] << 8) | in[2 * x + 1])
                                           : static_cast<std::uint16_t>(in[2 * x] | (in[2 * x + 1] << 8));
        std::memcpy(out + 2 * x, &v, 2);  // host order, as Image holds 16-bit samples
      }
    } else {
      std::memcpy(out, in, out_row);
    }
  }
  return image;
}

}  // namespace

Result<TimeNs> header_stamp(std::span<const std::uint8_t> data) {
  Cursor c(data);
  auto header = read_header(c);
  if (!header.ok()) return header.error();
  return header->stamp_ns;
}

Result<ImuMessage> decode_imu(std::span<const std::uint8_t> data) {
  Cursor c(data);
  auto header = read_header(c);
  if (!header.ok()) return header.error();
  ImuMessage m;
  m.stamp_ns = header->stamp_ns;
  m.frame_id = header->frame_id;
  for (int i = 0; i < 4 + 9; ++i) c.f64();  // orientation and its covariance
  m.gyro = c.vec3();
  for (int i = 0; i < 9; ++i) c.f64();
  m.accel = c.vec3();
  for (int i = 0; i < 9; ++i) c.f64();
  IMUCAL_TRY(finished(c, kImuType));
  return m;
}

Result<ImageMessage> decode_image(std::span<const std::uint8_t> data) {
  Cursor c(data);
  auto header = read_header(c);
  if (!header.ok()) return header.error();
  const std::uint32_t height = c.u32();
  const std::uint32_t width = c.u32();
  ImageMessage m;
  m.stamp_ns = header->stamp_ns;
  m.frame_id = header->frame_id;
  m.encoding = c.text();
  const bool big_endian = c.u8() != 0;
  const std::uint32_t step = c.u32();
  auto pixels = c.bytes();
  IMUCAL_TRY(finished(c, kImageType));
  auto image = image_from_fields(width, height, m.encoding, big_endian, step, pixels);
  if (!image.ok()) return image.error();
  m.image = std::move(*image);
  return m;
}

Result<Image> image_from_fields(std::uint32_t width, std::uint32_t height, const std::string& encoding,
                                bool big_endian, std::uint32_t step, std::span<const std::uint8_t> pixels) {
  auto layout = layout_of(encoding);
  if (!layout.ok()) return layout.error();
  if (width == 0 || height == 0 || width > kMaxImageSide || height > kMaxImageSide) {
    return make_error(Errc::kCorrupt, "an image of " + std::to_string(width) + "x" + std::to_string(height) +
                                          " pixels (1 to " + std::to_string(kMaxImageSide) + " a side)");
  }
  if (encoding == "yuv422" && width % 2 != 0) {
    return make_error(Errc::kCorrupt, "a yuv422 image of odd width " + std::to_string(width));
  }
  const std::uint64_t row = std::uint64_t{width} * static_cast<std::uint64_t>(layout->bytes_per_pixel);
  if (step < row || pixels.size() < std::uint64_t{step} * (height - 1) + row) {
    return make_error(Errc::kCorrupt, "a " + std::to_string(width) + "x" + std::to_string(height) + " " +
                                          encoding + " image with a step of " + std::to_string(step) +
                                          " and " + std::to_string(pixels.size()) + " bytes of pixels");
  }
  return pixels_to_image(pixels, width, height, step, encoding, *layout, big_endian);
}

Result<CompressedImageMessage> decode_compressed_image(std::span<const std::uint8_t> data) {
  Cursor c(data);
  auto header = read_header(c);
  if (!header.ok()) return header.error();
  CompressedImageMessage m;
  m.stamp_ns = header->stamp_ns;
  m.frame_id = header->frame_id;
  m.format = c.text();
  auto bytes = c.bytes();
  IMUCAL_TRY(finished(c, kCompressedImageType));
  m.data.assign(bytes.begin(), bytes.end());
  return m;
}

std::vector<std::uint8_t> encode_imu(const ImuMessage& m, std::uint32_t seq) {
  std::vector<std::uint8_t> out;
  out.reserve(64 + m.frame_id.size() + 8 * 43);
  put_header(out, seq, m.stamp_ns, m.frame_id);
  // No orientation: (0, 0, 0, 1) with covariance[0] = -1, ROS's mark for "not estimated".
  for (double v : {0.0, 0.0, 0.0, 1.0}) put_f64(out, v);
  put_f64(out, -1.0);
  for (int i = 1; i < 9; ++i) put_f64(out, 0.0);
  for (int i = 0; i < 3; ++i) put_f64(out, m.gyro[i]);
  for (int i = 0; i < 9; ++i) put_f64(out, 0.0);  // covariance unknown
  for (int i = 0; i < 3; ++i) put_f64(out, m.accel[i]);
  for (int i = 0; i < 9; ++i) put_f64(out, 0.0);
  return out;
}

std::vector<std::uint8_t> encode_image(const ImageMessage& m, std::uint32_t seq) {
  const Image& image = m.image;
  std::vector<std::uint8_t> out;
  out.reserve(64 + m.frame_id.size() + image.data.size());
  put_header(out, seq, m.stamp_ns, m.frame_id);
  format::put32(out, static_cast<std::uint32_t>(image.height));
  format::put32(out, static_cast<std::uint32_t>(image.width));
  put_text(out, image.channels == 3 ? "bgr8" : (image.depth == 16 ? "mono16" : "mono8"));
  out.push_back(0);  // little-endian
  const std::size_t row = image.row_bytes();
  format::put32(out, static_cast<std::uint32_t>(row));
  format::put32(out, static_cast<std::uint32_t>(row * static_cast<std::size_t>(image.height)));
  if (image.depth == 16) {
    for (std::size_t i = 0; i + 1 < image.data.size(); i += 2) {
      std::uint16_t v = 0;
      std::memcpy(&v, image.data.data() + i, 2);
      out.push_back(static_cast<std::uint8_t>(v & 0xff));
      out.push_back(static_cast<std::uint8_t>(v >> 8));
    }
  } else {
    out.insert(out.end(), image.data.begin(), image.data.end());
  }
  return out;
}

}  // namespace imucal::log::rosbag
