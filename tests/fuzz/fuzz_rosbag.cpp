// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: the ROS 1 bag reader and message decoders (log/rosbag.hpp) on a damaged bag. The
// input is written to a file and opened as a bag; its connections are read (from the index, or
// from the chunks when the index does not read) and every message is visited and decoded by its
// type. Any bytes must give messages or an error with a message (or damage with its place),
// never a crash, an exception or a sanitizer report.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "log/rosbag.hpp"

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

template <class R>
void decoded(const R& r) {
  if (!r.ok()) require(!r.error().message.empty());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal::log::rosbag;
  static const std::string path = "/tmp/imucal-fuzz-rosbag-" + std::to_string(::getpid()) + ".bag";
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    if (size > 0) require(std::fwrite(data, 1, size, f) == size);
    std::fclose(f);
  }
  auto reader = BagReader::open(path);
  if (!reader.ok()) {
    require(!reader.error().message.empty());
  } else {
    auto connections = (*reader)->connections();
    if (!connections.ok()) require(!connections.error().message.empty());
    BagDamage damage;
    const auto s = (*reader)->for_each_message(
        [](const MessageView& m) {
          decoded(header_stamp(m.data));
          if (m.connection->type == kImuType) decoded(decode_imu(m.data));
          if (m.connection->type == kImageType) decoded(decode_image(m.data));
          if (m.connection->type == kCompressedImageType) decoded(decode_compressed_image(m.data));
          return imucal::Status{};
        },
        damage);
    require(s.ok());
    if (damage.damaged) require(!damage.message.empty() && damage.offset <= damage.size);
  }
  std::remove(path.c_str());
  return 0;
}
