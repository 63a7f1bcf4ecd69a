// SPDX-License-Identifier: BSD-3-Clause
#include "app/streams.hpp"

#include <utility>

namespace imucal::app {

std::string LoadedStream::damage_warning() const {
  if (!damaged()) return {};
  return "the log is damaged (" + reader->health().damage_message + ")";
}

Result<LoadedStream> load_imu_stream(const std::string& path, const std::string& stream_name,
                                     DamagePolicy policy) {
  log::SessionLogReaderOptions options;
  options.preload_imu = true;  // the whole stream is read: once, by the reader's own check
  auto opened = log::SessionLogReader::open(path, options);
  if (!opened.ok()) return opened.error().context("cannot read " + path);
  LoadedStream loaded;
  loaded.reader = std::move(*opened);
  const auto& reader = *loaded.reader;
  if (reader.health().damaged && policy == DamagePolicy::kRefuse) {
    return make_error(Errc::kCorrupt, path + " is damaged (" + reader.health().damage_message +
                                          "); only its readable part can be used")
        .with_remedy("allow_damaged");
  }
  auto id = reader.find_imu_stream(stream_name);
  if (!id.ok()) return id.error().context("no IMU stream in " + path);
  loaded.stream_id = *id;
  loaded.info = reader.imu_streams().at(*id);
  auto samples = loaded.reader->take_imu(*id);
  if (!samples.ok()) return samples.error().context("cannot read the IMU samples of " + path);
  loaded.samples = std::move(*samples);
  return loaded;
}

}  // namespace imucal::app
