// SPDX-License-Identifier: BSD-3-Clause
// Parts of the session log interface that do not depend on the storage engine.

#include "log/session_log.hpp"

namespace imucal::log {

Result<std::vector<ImuSample>> SessionLogReader::read_imu(int stream_id) const {
  std::vector<ImuSample> samples;
  auto count = imu_count(stream_id);
  if (count.ok()) samples.reserve(static_cast<std::size_t>(*count));
  auto status = for_each_imu(stream_id, kTimeMin, kTimeMax, [&](const ImuSample& s) {
    samples.push_back(s);
    return true;
  });
  if (!status.ok()) return status.error();
  return samples;
}

}  // namespace imucal::log
