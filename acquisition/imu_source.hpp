// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the recorder, the event loop and the rig service need from an IMU acquisition, whatever
// reads the chip: ImuAcquisition (imucal's own MPU-6000 driver over spidev or i2c-dev, times
// reconstructed from the data-ready line) or IioAcquisition (the kernel's inv-mpu6050 driver,
// times from the IIO buffer). Both deliver timestamped samples in counts, in the same stream
// layout (ImuStreamInfo), flag gaps the same way (kImuFlagGapBefore on the first sample after
// lost ones) and keep the same counters.

#include <cstdint>
#include <string>
#include <vector>

#include "acquisition/mounting.hpp"
#include "acquisition/timestamp.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::acq {

struct AcquisitionStats {
  std::uint64_t polls = 0;
  std::uint64_t batches = 0;
  std::uint64_t samples = 0;
  std::uint64_t edge_timeouts = 0;  // waits (or service polls) that ended without enough edges
  std::uint64_t edges = 0;          // data-ready edges taken from the line
  std::uint64_t batches_without_edge = 0;
};

class ImuSource {
 public:
  virtual ~ImuSource() = default;

  /// Waits for the next data (or poll time) and appends the samples that came, if any, to
  /// `out` (cleared first). Errors are unrecoverable ones (the device gone or broken).
  [[nodiscard]] virtual Status step(std::vector<ImuSample>& out) = 0;
  /// The event-loop form of step(); never blocks. Call it when wake_fd() is readable and at
  /// next_poll_ns(). Use either step() or service() on one source.
  [[nodiscard]] virtual Status service(std::vector<ImuSample>& out) = 0;
  /// When service() wants to be called at the latest (CLOCK_MONOTONIC on a rig).
  virtual TimeNs next_poll_ns() const = 0;

  /// A descriptor that turns readable when service() has something to take, or -1 (the poll
  /// time is the only wake-up).
  virtual int wake_fd() const = 0;
  /// What that descriptor is, for messages: "data-ready line gpiochip0:3", "IIO buffer
  /// /dev/iio:device0".
  virtual std::string wake_name() const = 0;
  /// Grows whenever service() took something from the descriptor: a descriptor that keeps
  /// turning readable without it is broken.
  virtual std::uint64_t wake_progress() const = 0;

  virtual const MountingMap& mounting() const = 0;
  /// Counters of the sample times (gaps, samples lost, ...). A source whose times come from the
  /// kernel fills what applies to it.
  virtual TimestamperStats timing_stats() const = 0;
  virtual AcquisitionStats acquisition_stats() const = 0;
  /// The chip's rate against nominal as the times show it, ppm (+ = slower chip).
  virtual double period_error_ppm() const = 0;
  /// The recording's "imu.timing" metadata (JSON), given the measured rate.
  virtual std::string timing_metadata(double measured_rate_hz) const = 0;
  /// The recording's "imu.driver" metadata (JSON): which driver, its settings and counters.
  virtual std::string driver_metadata() const = 0;
};

}  // namespace imucal::acq
