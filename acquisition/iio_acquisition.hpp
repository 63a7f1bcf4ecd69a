// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The acquisition loop over the kernel's inv-mpu6050 driver (drivers/iio/iio_imu.hpp): the IIO
// buffer's scans become samples in counts with the kernel's timestamps, checked the way the
// direct path checks its own.
//
// Times. The kernel stamps each scan (the data-ready interrupt's time, the chip's period
// estimated from the interrupt intervals, inv_sensors_timestamp.c). They are used as they are,
// after three checks: on CLOCK_MONOTONIC (a scan stamped more than 250 ms ahead of the host's
// clock, or more than an hour behind, is an error: the device's current_timestamp_clock is not
// monotonic; the kernel's estimate itself may lead the clock by a little), strictly increasing (a stamp at or
// before its predecessor is moved to half a period after it and counted in monotonic_clamps), and without
// holes: an interval of more than 1.5 periods means samples were lost (the kernel reset the chip's FIFO on an
// overflow, or the buffer was full). They are counted from the interval, round(dt / P) - 1 with P the period
// the stamps themselves show (a running mean of the intervals within 10 % of nominal), into samples_lost and
// gaps, and the first sample after the hole carries kImuFlagGapBefore.
//
// Silence. No scan for max(0.5 s, 20 periods) restarts the buffer (the kernel resets the chip's
// FIFO); three restarts in a row without a scan are an error (kDevice: the chip's interrupt
// no longer comes).

#include <cstdint>
#include <string>
#include <vector>

#include "acquisition/imu_acquisition.hpp"
#include "acquisition/imu_source.hpp"
#include "acquisition/mounting.hpp"
#include "acquisition/timestamp.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "drivers/iio/iio_imu.hpp"

namespace imucal::acq {

struct IioAcquisitionStats {
  std::uint64_t interval_count = 0;  // intervals between consecutive scans that fed the period
  TimeNs interval_min_ns = 0;
  TimeNs interval_max_ns = 0;
  double interval_sum_dev_ns = 0.0;  // sum of (interval - nominal period)
  double interval_sum_sq_dev = 0.0;  // sum of (interval - nominal period)^2
  std::uint64_t silences = 0;        // buffer restarts after no scan for too long
};

class IioAcquisition final : public ImuSource {
 public:
  /// `imu` and `clock` are borrowed.
  IioAcquisition(drivers::iio::IioImu& imu, AcquisitionClock& clock, MountingMap mounting);

  [[nodiscard]] Status step(std::vector<ImuSample>& out) override;
  [[nodiscard]] Status service(std::vector<ImuSample>& out) override;
  TimeNs next_poll_ns() const override { return next_poll_ns_; }
  int wake_fd() const override { return imu_.fd(); }
  std::string wake_name() const override { return "IIO buffer " + imu_.node(); }
  std::uint64_t wake_progress() const override { return imu_.stats().reads; }
  const MountingMap& mounting() const override { return mounting_; }
  TimestamperStats timing_stats() const override { return timing_; }
  AcquisitionStats acquisition_stats() const override { return stats_; }
  double period_error_ppm() const override;
  std::string timing_metadata(double measured_rate_hz) const override;
  std::string driver_metadata() const override;

  /// The period the kernel's stamps show (nominal until the first intervals), ns.
  double period_ns() const { return period_ns_; }
  const IioAcquisitionStats& iio_stats() const { return iio_; }

 private:
  void convert(const std::vector<drivers::iio::IioScan>& scans, std::vector<ImuSample>& out);
  [[nodiscard]] Status check_clock(TimeNs t_ns, TimeNs now_ns) const;

  drivers::iio::IioImu& imu_;
  AcquisitionClock& clock_;
  MountingMap mounting_;
  double nominal_period_ns_;
  double period_ns_;
  TimeNs silence_ns_;
  TimeNs next_poll_ns_ = 0;
  TimeNs last_data_ns_ = 0;  // host time of the last read that gave scans (or of the start)
  int restarts_in_a_row_ = 0;
  bool have_last_ = false;
  TimeNs last_t_ns_ = 0;
  std::vector<drivers::iio::IioScan> scans_;
  TimestamperStats timing_;
  AcquisitionStats stats_;
  IioAcquisitionStats iio_;
};

}  // namespace imucal::acq
