// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// ROS 2 bags (rosbag2), read by the project's own code: a folder with metadata.yaml and its
// storage files, or one storage file, of either storage plug-in:
//   - sqlite3 (.db3): the tables `topics` (id, name, type, serialization_format) and `messages`
//     (topic_id, timestamp, data), read through SQLite;
//   - mcap (.mcap): records (opcode, length, content) and chunks of them, plain or compressed with
//     lz4 (frame format) or zstd (https://mcap.dev/spec).
// Messages are CDR (little-endian) as ROS 2 serializes them; the three types a calibration needs
// are decoded (sensor_msgs/msg/Imu, Image, CompressedImage) into log/rosbag.hpp's structs.
// Why not rosbag2's own libraries: Debian 12 packages no ROS 2.
//
// No function throws; failures are values (core/result.hpp).

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "log/rosbag.hpp"

namespace imucal::log::rosbag2 {

/// Opens a rosbag2 folder (its metadata.yaml names the storage and files; the files are read in
/// its order), or a single .db3 or .mcap file. Connections carry ROS 1's type names
/// ("sensor_msgs/Imu" for "sensor_msgs/msg/Imu"), so that the importer treats both alike.
class Bag2Reader {
 public:
  [[nodiscard]] static Result<std::unique_ptr<Bag2Reader>> open(const std::string& path);
  ~Bag2Reader();
  Bag2Reader(const Bag2Reader&) = delete;
  Bag2Reader& operator=(const Bag2Reader&) = delete;

  [[nodiscard]] Result<std::vector<rosbag::Connection>> connections();
  /// As rosbag::BagReader::for_each_message: messages in storage order; a file cut short or
  /// damaged stops at the first piece that is not whole and `damage` says where.
  [[nodiscard]] Status for_each_message(const std::function<Status(const rosbag::MessageView&)>& visit,
                                        rosbag::BagDamage& damage,
                                        const std::function<void(double)>& progress = {});

 private:
  struct State;
  explicit Bag2Reader(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

/// Whether `path` is a rosbag2 folder (metadata.yaml) or a .db3 or .mcap file (by content).
bool is_rosbag2(const std::string& path);

/// CDR decoders of the three types (an encapsulation header, then the fields with CDR's
/// alignment); the same errors as log/rosbag.hpp's decoders.
[[nodiscard]] Result<TimeNs> header_stamp_cdr(std::span<const std::uint8_t> data);
[[nodiscard]] Result<rosbag::ImuMessage> decode_imu_cdr(std::span<const std::uint8_t> data);
[[nodiscard]] Result<rosbag::ImageMessage> decode_image_cdr(std::span<const std::uint8_t> data);
[[nodiscard]] Result<rosbag::CompressedImageMessage> decode_compressed_image_cdr(
    std::span<const std::uint8_t> data);

/// CDR encoders (little-endian), the inverse of the decoders; for tests and the fuzz seeds.
std::vector<std::uint8_t> encode_imu_cdr(const rosbag::ImuMessage& message);
std::vector<std::uint8_t> encode_image_cdr(const rosbag::ImageMessage& message);

}  // namespace imucal::log::rosbag2
