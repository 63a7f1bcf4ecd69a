// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// ROS 1 bags (format 2.0, http://wiki.ros.org/Bags/Format/2.0), read and written by the
// project's own code: records of a length-prefixed header ("name=value" fields) and data;
// chunks of connection and message records, stored plain or compressed with bz2 or lz4 (libbz2
// and liblz4's frame format, which is what roslz4 writes); an index after the chunks. Why not
// Debian's librosbag-storage: it cannot open a bag whose index is missing (a recording cut short:
// it wants `rosbag reindex`), it brings pluginlib, console_bridge and Boost's filesystem into the
// programs, and it hands messages back only through ROS's generated message classes, which
// imucal would still have to decode. The messages decoded are the three a calibration needs:
// sensor_msgs/Imu, sensor_msgs/Image and sensor_msgs/CompressedImage (docs/datasets.md).
//
// No function throws; failures are values (core/result.hpp).

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"
#include "log/frame_codec.hpp"

namespace imucal::log::rosbag {

/// A topic as the bag declares it (a connection record).
struct Connection {
  std::uint32_t id = 0;
  std::string topic;
  std::string type;        // "sensor_msgs/Imu"
  std::string md5sum;      // of the message definition, as ROS computes it
  std::string definition;  // the message definition's full text
};

/// One message, borrowed for the length of a visit.
struct MessageView {
  const Connection* connection = nullptr;
  TimeNs receive_ns = 0;  // the time the recorder received it (the record's "time")
  std::span<const std::uint8_t> data;
};

/// Where a bag stops being whole.
struct BagDamage {
  bool damaged = false;
  std::uint64_t offset = 0;  // the byte where the first record that is not whole begins
  std::uint64_t size = 0;    // the file's size
  std::int64_t chunks_read = 0;
  std::string message;  // what is wrong there
};

/// Reads a bag front to back, chunk by chunk; memory is one chunk (a few MB) at a time.
class BagReader {
 public:
  /// Opens `path` and reads the bag header; a file that is not a ROS 1 bag 2.0 is refused
  /// (kCorrupt, or kUnsupported for a ROS 1 bag of format 1.2 and a rosbag2 folder or file).
  [[nodiscard]] static Result<std::unique_ptr<BagReader>> open(const std::string& path);
  ~BagReader();
  BagReader(const BagReader&) = delete;
  BagReader& operator=(const BagReader&) = delete;

  /// Every connection, from the index at the bag's end; when the index is missing or damaged,
  /// from a reading of every chunk (the connection records inside them).
  [[nodiscard]] Result<std::vector<Connection>> connections();

  /// Visits every message in the order the bag stores them. A bag cut short or damaged stops at
  /// the first record that is not whole: the messages of the whole chunks before it have been
  /// visited, `damage` says where (and the call returns ok); a visitor's error ends it with that
  /// error. `progress` gets the fraction of the file read.
  [[nodiscard]] Status for_each_message(const std::function<Status(const MessageView&)>& visit,
                                        BagDamage& damage, const std::function<void(double)>& progress = {});

 private:
  struct State;
  explicit BagReader(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

// ---------------------------------------------------------------------------------------------
// Messages (ROS 1 serialization: little-endian, strings and arrays with a uint32 length).

struct ImuMessage {
  TimeNs stamp_ns = 0;  // header.stamp
  std::string frame_id;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();   // angular_velocity, rad/s
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();  // linear_acceleration, m/s^2
};

struct ImageMessage {
  TimeNs stamp_ns = 0;
  std::string frame_id;
  std::string encoding;  // as the message gives it ("mono8", "rgb8", "yuv422", ...)
  Image image;           // gray (8 or 16 bits) or BGR, rows without padding
};

struct CompressedImageMessage {
  TimeNs stamp_ns = 0;
  std::string frame_id;
  std::string format;  // as the message gives it ("png", "jpeg", "mono8; png compressed ")
  std::vector<std::uint8_t> data;
};

inline constexpr const char* kImuType = "sensor_msgs/Imu";
inline constexpr const char* kImageType = "sensor_msgs/Image";
inline constexpr const char* kCompressedImageType = "sensor_msgs/CompressedImage";

/// The header.stamp of any of the three (each begins with a std_msgs/Header).
[[nodiscard]] Result<TimeNs> header_stamp(std::span<const std::uint8_t> data);

/// Decoders: a message shorter or longer than its fields, or an image whose size, step and data
/// disagree, is kCorrupt; an image encoding other than mono8, mono16, bgr8, rgb8, yuv422 (and
/// their 8UC1, 16UC1, 8UC3 names) is kUnsupported, named.
[[nodiscard]] Result<ImuMessage> decode_imu(std::span<const std::uint8_t> data);
[[nodiscard]] Result<ImageMessage> decode_image(std::span<const std::uint8_t> data);
[[nodiscard]] Result<CompressedImageMessage> decode_compressed_image(std::span<const std::uint8_t> data);

/// An image message's fields as an Image: the checks and conversions of decode_image (shared
/// with the ROS 2 decoder, log/rosbag2.hpp).
[[nodiscard]] Result<Image> image_from_fields(std::uint32_t width, std::uint32_t height,
                                              const std::string& encoding, bool big_endian,
                                              std::uint32_t step, std::span<const std::uint8_t> pixels);

/// Encoders, the inverse of the decoders (an 8-bit gray image as mono8, 16-bit as mono16, BGR
/// as bgr8); `seq` is the header's sequence number.
std::vector<std::uint8_t> encode_imu(const ImuMessage& message, std::uint32_t seq);
std::vector<std::uint8_t> encode_image(const ImageMessage& message, std::uint32_t seq);

/// The md5sum and full definition ROS gives the three types (what a connection record holds, and
/// what Kalibr's rosbag checks a message's class against).
const char* message_md5sum(const std::string& type);
const char* message_definition(const std::string& type);

// ---------------------------------------------------------------------------------------------
// Writing.

enum class ChunkCompression { kNone, kBz2, kLz4 };

/// Writes a bag: messages are buffered into chunks of about `chunk_bytes`, each followed by its
/// index records; close() writes the connections and chunk infos and points the bag header at
/// them, which is what rosbag needs to open a bag without reindexing.
class BagWriter {
 public:
  /// Creates `path` (it must not exist).
  [[nodiscard]] static Result<std::unique_ptr<BagWriter>> create(
      const std::string& path, ChunkCompression compression = ChunkCompression::kNone,
      std::size_t chunk_bytes = 768 * 1024);
  ~BagWriter();
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  /// Declares a topic of `type` (one of the three above); returns its connection id.
  [[nodiscard]] Result<std::uint32_t> add_connection(const std::string& topic, const std::string& type);
  [[nodiscard]] Status write(std::uint32_t connection, TimeNs receive_ns, std::span<const std::uint8_t> data);
  /// Writes the last chunk and the index; the bag is whole only after it.
  [[nodiscard]] Status close();

 private:
  struct State;
  explicit BagWriter(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace imucal::log::rosbag
