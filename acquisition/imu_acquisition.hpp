// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The IMU acquisition loop.
//
// ImuAcquisition turns the MPU-6000 driver's FIFO batches into timestamped samples: it takes
// data-ready edges (or, without a line, waits for the driver's next poll time), polls the
// driver, reconstructs per-sample times (timestamp.hpp), remaps axes exactly when the mounting
// allows it (mounting.hpp) and hands the samples to an ImuStream. Two forms of the same loop:
// step() blocks in the line's wait() or the clock's sleep_until() (the simulated rig, whose
// clock only moves when asked, runs on it deterministically); service() never blocks and is
// called by an event loop whenever the line's file descriptor is readable or the poll time
// has come (asio_acquisition.hpp, the form a rig runs).

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "acquisition/imu_source.hpp"
#include "acquisition/imu_stream.hpp"
#include "acquisition/mounting.hpp"
#include "acquisition/timestamp.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/gpio/data_ready_line.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

namespace imucal::acq {

/// The host clock as the acquisition loop sees it.
class AcquisitionClock {
 public:
  virtual ~AcquisitionClock() = default;
  virtual TimeNs now_ns() = 0;
  /// Returns at `t_ns` or later (sleeps on a rig; advances simulated time).
  virtual void sleep_until(TimeNs t_ns) = 0;
};

/// CLOCK_MONOTONIC and clock_nanosleep.
class MonotonicClock final : public AcquisitionClock {
 public:
  TimeNs now_ns() override { return monotonic_now_ns(); }
  void sleep_until(TimeNs t_ns) override;
};

/// The timing the timestamper needs from one driver batch.
FifoBatchTiming batch_timing(const drivers::mpu6000::FifoBatch& batch);

struct AcquisitionOptions {
  TimestamperOptions timestamps;  // nominal_rate_hz is taken from the driver settings
  /// Edges per FIFO read: the loop collects this many data-ready edges before it polls
  /// (0: chosen from the rate so that reads happen at about 1 kHz or slower).
  int edges_per_read = 0;
  /// Longest wait for a data-ready edge before polling anyway (step(); service() polls at the
  /// driver's next poll time at the latest).
  TimeNs edge_timeout_ns = 20'000'000;
};

class ImuAcquisition final : public ImuSource {
 public:
  /// Everything is borrowed. `line` may be null (no data-ready interrupt: poll the FIFO).
  ImuAcquisition(drivers::mpu6000::Mpu6000& driver, drivers::DataReadyLine* line, AcquisitionClock& clock,
                 MountingMap mounting, AcquisitionOptions options);

  /// Waits for the next edge (or poll time), polls the driver and appends the samples of the
  /// batch, if any, to `out` (cleared first). Errors are the driver's unrecoverable ones.
  [[nodiscard]] Status step(std::vector<ImuSample>& out) override;

  /// The event-loop form of step(); never blocks. Takes the edges already pending on the line
  /// (each older one is reported to the driver with on_edge()) and polls the driver when
  /// `edges_per_read` edges have come since the last poll or next_poll_ns() has come, appending
  /// the samples of the batch, if any, to `out` (cleared first). Call it when the line's fd()
  /// is readable and at next_poll_ns(). Use either step() or service() on one acquisition.
  [[nodiscard]] Status service(std::vector<ImuSample>& out) override;

  /// When service() polls the driver at the latest (the clock's time base; CLOCK_MONOTONIC on
  /// a rig), unless edges come first.
  TimeNs next_poll_ns() const override { return next_poll_ns_; }

  int wake_fd() const override { return line_ != nullptr ? line_->fd() : -1; }
  std::string wake_name() const override {
    return line_ != nullptr ? "data-ready line " + line_->name() : "";
  }
  std::uint64_t wake_progress() const override { return stats_.edges; }
  TimestamperStats timing_stats() const override { return timestamper_.stats(); }
  AcquisitionStats acquisition_stats() const override { return stats_; }
  double period_error_ppm() const override { return timestamper_.period_error_ppm(); }
  std::string timing_metadata(double measured_rate_hz) const override;
  std::string driver_metadata() const override;

  /// The data-ready line, or null (FIFO polling).
  drivers::DataReadyLine* line() const { return line_; }

  const SampleTimestamper& timestamper() const { return timestamper_; }
  const AcquisitionStats& stats() const { return stats_; }
  const MountingMap& mounting() const override { return mounting_; }
  /// True when samples are remapped to rig axes (exact mounting), false when they stay in the
  /// IMU's axes (general mounting: applied in SI after calibration).
  bool samples_in_rig_frame() const { return mounting_.exact_on_raw(); }

 private:
  /// Polls the driver at `now_ns` with the newest edge and converts the batch, if any, into
  /// timestamped, remapped samples in `out`.
  [[nodiscard]] Status poll_driver(TimeNs now_ns, std::optional<drivers::DataReadyEdge> edge,
                                   std::vector<ImuSample>& out);
  /// Takes and drops every pending edge (before streaming they must not anchor the timestamps).
  [[nodiscard]] Status discard_pending_edges();

  drivers::mpu6000::Mpu6000& driver_;
  drivers::DataReadyLine* line_;
  AcquisitionClock& clock_;
  MountingMap mounting_;
  AcquisitionOptions options_;
  SampleTimestamper timestamper_;
  int edges_per_read_ = 1;
  TimeNs next_poll_ns_ = 0;
  // service(): edges taken since the last poll and the newest of them.
  int pending_edges_ = 0;
  std::optional<drivers::DataReadyEdge> pending_edge_;
  std::vector<TimeNs> t_buf_;
  std::vector<std::uint32_t> flag_buf_;
  AcquisitionStats stats_;
};

}  // namespace imucal::acq
