// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: the ROS 2 bag reader's mcap storage and the CDR decoders (log/rosbag2.hpp). An input
// that begins with the mcap magic is written to a file and read as a rosbag2 (its channels, then
// every message visited and decoded by its type); any other input is decoded as a CDR Imu, Image
// and CompressedImage message. Any bytes must give messages or an error with a message (or damage
// with its place), never a crash, an exception or a sanitizer report.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <string>

#include "log/rosbag2.hpp"

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

template <class R>
void decoded(const R& r) {
  if (!r.ok()) require(!r.error().message.empty());
}

void decode_all(std::span<const std::uint8_t> data) {
  using namespace imucal::log::rosbag2;
  decoded(header_stamp_cdr(data));
  decoded(decode_imu_cdr(data));
  decoded(decode_image_cdr(data));
  decoded(decode_compressed_image_cdr(data));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal::log;
  if (size < 8 || std::memcmp(data, "\x89MCAP0\r\n", 8) != 0) {
    decode_all(std::span(data, size));
    return 0;
  }
  static const std::string path = "/tmp/imucal-fuzz-rosbag2-" + std::to_string(::getpid()) + ".mcap";
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    require(std::fwrite(data, 1, size, f) == size);
    std::fclose(f);
  }
  auto reader = rosbag2::Bag2Reader::open(path);
  if (!reader.ok()) {
    require(!reader.error().message.empty());
  } else {
    auto connections = (*reader)->connections();
    if (!connections.ok()) require(!connections.error().message.empty());
    rosbag::BagDamage damage;
    const auto s = (*reader)->for_each_message(
        [](const rosbag::MessageView& m) {
          decode_all(m.data);
          return imucal::Status{};
        },
        damage);
    if (!s.ok()) require(!s.error().message.empty());
    if (damage.damaged) require(!damage.message.empty() && damage.offset <= damage.size);
  }
  std::remove(path.c_str());
  return 0;
}
