// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/iio_acquisition.hpp"

#include <poll.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <sstream>

namespace imucal::acq {

namespace {

constexpr double kGapPeriods = 1.5;      // an interval this many periods long holds lost samples
constexpr double kPeriodWindow = 0.10;   // intervals within this of nominal feed the period
constexpr double kPeriodMemory = 256.0;  // the running mean's memory, in intervals
constexpr int kMaxRestartsInARow = 3;
// The kernel's stamp is its period estimate's time for the scan, which can lead the clock a
// little (1.3 ms was seen under QEMU); another clock (realtime) is decades off.
constexpr TimeNs kAheadTolerance = 250'000'000;
constexpr TimeNs kBehindTolerance = 3600 * kNsPerSecond;  // an hour

bool saturated(const std::array<std::int16_t, 3>& v) {
  return std::any_of(v.begin(), v.end(), [](std::int16_t c) { return c == 32767 || c == -32768; });
}

}  // namespace

IioAcquisition::IioAcquisition(drivers::iio::IioImu& imu, AcquisitionClock& clock, MountingMap mounting)
    : imu_(imu),
      clock_(clock),
      mounting_(std::move(mounting)),
      nominal_period_ns_(1e9 / imu.rate_hz()),
      period_ns_(nominal_period_ns_),
      silence_ns_(std::max<TimeNs>(kNsPerSecond / 2, static_cast<TimeNs>(20.0 * nominal_period_ns_))) {
  last_data_ns_ = clock_.now_ns();
  next_poll_ns_ = last_data_ns_ + silence_ns_;
}

double IioAcquisition::period_error_ppm() const { return (period_ns_ / nominal_period_ns_ - 1.0) * 1e6; }

Status IioAcquisition::step(std::vector<ImuSample>& out) {
  const TimeNs wait_ns = std::max<TimeNs>(0, next_poll_ns_ - clock_.now_ns());
  pollfd p{imu_.fd(), POLLIN, 0};
  const int ms = static_cast<int>(std::min<TimeNs>(wait_ns / 1'000'000 + 1, 1000));
  if (::poll(&p, 1, ms) < 0 && errno != EINTR) {
    return make_error(Errc::kIo, "waiting on " + imu_.node() + ": " + std::strerror(errno));
  }
  return service(out);
}

Status IioAcquisition::service(std::vector<ImuSample>& out) {
  out.clear();
  scans_.clear();
  IMUCAL_TRY(imu_.read(scans_));
  ++stats_.polls;
  const TimeNs now_ns = clock_.now_ns();
  if (!scans_.empty()) {
    IMUCAL_TRY(check_clock(scans_.back().t_ns, now_ns));
    convert(scans_, out);
    last_data_ns_ = now_ns;
    restarts_in_a_row_ = 0;
  } else if (now_ns - last_data_ns_ >= silence_ns_) {
    if (restarts_in_a_row_ >= kMaxRestartsInARow) {
      std::ostringstream os;
      os << "no samples from " << imu_.describe() << " for " << kMaxRestartsInARow + 1 << " x "
         << static_cast<double>(silence_ns_) / 1e9
         << " s, buffer restarted in between: the chip's data-ready interrupt no longer reaches the kernel "
            "(check its INT wiring and the device tree's interrupts), or the chip is gone; if interrupts do "
            "come "
            "(/proc/interrupts), the kernel's driver may be dropping them: Debian's 6.1 inv-mpu6050 reads an "
            "MPU-6000/6050's interrupt status from register 0x00 (docs/mpu6000.md)";
      return make_error(Errc::kDevice, os.str());
    }
    IMUCAL_TRY(imu_.restart());
    ++restarts_in_a_row_;
    ++iio_.silences;
    last_data_ns_ = now_ns;
  }
  next_poll_ns_ = last_data_ns_ + silence_ns_;
  return {};
}

Status IioAcquisition::check_clock(TimeNs t_ns, TimeNs now_ns) const {
  if (t_ns <= now_ns + kAheadTolerance && t_ns >= now_ns - kBehindTolerance) return {};
  std::ostringstream os;
  os << "the kernel's timestamps on " << imu_.node() << " are not on CLOCK_MONOTONIC (a scan stamped "
     << static_cast<double>(t_ns - now_ns) / 1e9
     << " s from the host's clock): its current_timestamp_clock must read monotonic (another program may "
        "have "
        "changed it)";
  return make_error(Errc::kDevice, os.str());
}

void IioAcquisition::convert(const std::vector<drivers::iio::IioScan>& scans, std::vector<ImuSample>& out) {
  out.resize(scans.size());
  ++stats_.batches;
  ++timing_.batches;
  stats_.samples += scans.size();
  timing_.samples += scans.size();
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const drivers::iio::IioScan& r = scans[i];
    ImuSample& s = out[i];
    s.flags = kImuFlagNone;
    TimeNs t = r.t_ns;
    if (have_last_) {
      const TimeNs dt = t - last_t_ns_;
      if (dt <= 0) {
        t = last_t_ns_ + static_cast<TimeNs>(0.5 * period_ns_);
        ++timing_.monotonic_clamps;
      } else if (static_cast<double>(dt) > kGapPeriods * period_ns_) {
        const auto lost = std::max<std::int64_t>(1, std::llround(static_cast<double>(dt) / period_ns_) - 1);
        timing_.samples_lost += static_cast<std::uint64_t>(lost);
        ++timing_.gaps;
        s.flags |= kImuFlagGapBefore;
      } else if (std::abs(static_cast<double>(dt) / nominal_period_ns_ - 1.0) < kPeriodWindow) {
        const double n = static_cast<double>(++iio_.interval_count);
        period_ns_ += (static_cast<double>(dt) - period_ns_) / std::min(n, kPeriodMemory);
        const double d = static_cast<double>(dt) - nominal_period_ns_;
        iio_.interval_sum_dev_ns += d;
        iio_.interval_sum_sq_dev += d * d;
        iio_.interval_min_ns = iio_.interval_count == 1 ? dt : std::min(iio_.interval_min_ns, dt);
        iio_.interval_max_ns = std::max(iio_.interval_max_ns, dt);
      }
    }
    have_last_ = true;
    last_t_ns_ = t;
    s.t_ns = t;
    s.accel = Eigen::Vector3d(r.accel[0], r.accel[1], r.accel[2]);
    s.gyro = Eigen::Vector3d(r.gyro[0], r.gyro[1], r.gyro[2]);
    s.temperature = static_cast<double>(r.temp);
    if (saturated(r.accel)) s.flags |= kImuFlagAccelSaturated;
    if (saturated(r.gyro)) s.flags |= kImuFlagGyroSaturated;
    if (mounting_.exact_on_raw()) mounting_.remap_raw_sample(s);
  }
}

std::string IioAcquisition::timing_metadata(double measured_rate_hz) const {
  nlohmann::json j;
  j["source"] = "kernel: inv-mpu6050 IIO buffer timestamps";
  j["nominal_rate_hz"] = 1e9 / nominal_period_ns_;
  j["measured_rate_hz"] = measured_rate_hz;
  j["period_error_ppm"] = period_error_ppm();
  j["batches"] = timing_.batches;
  j["gaps"] = timing_.gaps;
  j["samples_lost"] = timing_.samples_lost;
  j["monotonic_clamps"] = timing_.monotonic_clamps;
  j["intervals"] = iio_.interval_count;
  if (iio_.interval_count > 1) {
    const double n = static_cast<double>(iio_.interval_count);
    const double mean = iio_.interval_sum_dev_ns / n;
    j["interval_mean_ns"] = nominal_period_ns_ + mean;
    j["interval_sd_ns"] = std::sqrt(std::max(0.0, (iio_.interval_sum_sq_dev - n * mean * mean) / (n - 1.0)));
    j["interval_min_ns"] = iio_.interval_min_ns;
    j["interval_max_ns"] = iio_.interval_max_ns;
  }
  j["buffer_restarts"] = iio_.silences;
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

std::string IioAcquisition::driver_metadata() const {
  const drivers::iio::IioStats& st = imu_.stats();
  nlohmann::json j;
  j["driver"] = "iio";
  j["device"] = imu_.describe();
  j["settings"] = {{"sample_rate_hz", imu_.rate_hz()},
                   {"accel_scale", imu_.accel_scale()},
                   {"anglvel_scale", imu_.gyro_scale()},
                   {"scan_bytes", imu_.scan_bytes()}};
  j["counters"] = {{"reads", st.reads},
                   {"scans", st.scans},
                   {"empty_reads", st.empty_reads},
                   {"partial_bytes", st.partial_bytes},
                   {"restarts", st.restarts}};
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace imucal::acq
