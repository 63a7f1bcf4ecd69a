// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Test helpers for the simulated IMU path: a smooth sensor source, and the accounting of
// delivered samples against the frames the emulated MPU-6000 wrote into its FIFO (matched by
// their exact counts), used by the acquisition tests.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "core/imu.hpp"
#include "core/time.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/registers.hpp"

namespace imucal::emutest {

/// A few sines on every axis, fast enough that consecutive frames differ in their counts even
/// at 8 kHz.
inline fake::SensorReading wobble(TimeNs t_ns) {
  const double t = ns_to_s(t_ns), two_pi = 2.0 * std::numbers::pi;
  fake::SensorReading r;
  r.specific_force = {3.0 * std::sin(two_pi * 3.1 * t), 2.5 * std::cos(two_pi * 1.7 * t),
                      9.81 + std::sin(two_pi * 0.37 * t)};
  r.angular_rate = {1.1 * std::sin(two_pi * 5.3 * t), 0.9 * std::cos(two_pi * 2.9 * t),
                    0.7 * std::sin(two_pi * 7.7 * t + 0.3)};
  r.temperature_c = 31.0;
  return r;
}

/// Delivered samples against the frames the chip wrote into its FIFO.
struct Accounting {
  std::size_t delivered = 0;
  std::size_t produced = 0;          // frames written from the first delivered one on
  std::size_t mismatched = 0;        // delivered samples that are no later frame written
  std::size_t lost = 0;              // frames after the first delivered one that were skipped
  std::size_t unflagged_losses = 0;  // skips without kImuFlagGapBefore on the next sample
  std::size_t still_in_fifo = 0;
  std::size_t gap_flags = 0;
  double rms_time_error_ns = 0.0;  // after settle_ns from the first delivered frame
  double max_time_error_ns = 0.0;
};

inline Accounting account(const std::vector<ImuSample>& all, const fake::Mpu6000Emulator& emulator,
                          TimeNs settle_ns = kNsPerSecond / 2) {
  Accounting r;
  std::vector<const fake::TruthSample*> fifo;
  for (const auto& t : emulator.truth()) {
    if (t.to_fifo) fifo.push_back(&t);
  }
  auto same = [](const ImuSample& a, const fake::TruthSample& b) {
    return a.accel == Eigen::Vector3d(b.accel[0], b.accel[1], b.accel[2]) &&
           a.gyro == Eigen::Vector3d(b.gyro[0], b.gyro[1], b.gyro[2]) && a.temperature == b.temp;
  };
  // The first delivered sample: the first frame from which the next 16 delivered ones follow.
  std::size_t j0 = 0;
  auto run_matches = [&](std::size_t j) {
    for (std::size_t i = 0; i < 16 && i < all.size(); ++i) {
      if (j + i >= fifo.size() || !same(all[i], *fifo[j + i])) return false;
    }
    return true;
  };
  while (j0 < fifo.size() && !run_matches(j0)) ++j0;
  EXPECT_LT(j0, fifo.size());
  r.delivered = all.size();
  r.produced = fifo.size() - std::min(j0, fifo.size());
  r.still_in_fifo = emulator.fifo_bytes() / drivers::mpu6000::FIFO::kFrameBytes;
  double sum2 = 0.0;
  std::size_t n = 0;
  std::size_t j = j0;  // the next frame expected
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (all[i].flags & kImuFlagGapBefore) ++r.gap_flags;
    std::size_t k = j;
    while (k < fifo.size() && !same(all[i], *fifo[k])) ++k;
    if (k == fifo.size()) {
      ++r.mismatched;
      continue;
    }
    if (k > j) {
      r.lost += k - j;
      if (!(all[i].flags & kImuFlagGapBefore)) ++r.unflagged_losses;
    }
    j = k + 1;
    const fake::TruthSample& t = *fifo[k];
    if (t.t_ns - fifo[j0]->t_ns < settle_ns) continue;
    const double e = static_cast<double>(all[i].t_ns - t.t_ns);
    sum2 += e * e;
    r.max_time_error_ns = std::max(r.max_time_error_ns, std::abs(e));
    ++n;
  }
  if (n > 0) r.rms_time_error_ns = std::sqrt(sum2 / static_cast<double>(n));
  return r;
}

}  // namespace imucal::emutest
