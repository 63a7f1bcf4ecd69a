// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/imu_acquisition.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <ctime>
#include <span>
#include <sstream>

#include "acquisition/recorder.hpp"

namespace imucal::acq {

namespace mpu = drivers::mpu6000;

void MonotonicClock::sleep_until(TimeNs t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / kNsPerSecond);
  ts.tv_nsec = static_cast<long>(t_ns % kNsPerSecond);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

FifoBatchTiming batch_timing(const mpu::FifoBatch& batch) {
  FifoBatchTiming t;
  t.has_edge = batch.edge.has_value();
  if (batch.edge) {
    t.edge_t_ns = batch.edge->t_ns;
    t.edge_sequence = batch.edge->sequence;
    t.has_edge_sequence = true;
  }
  t.read_t_ns = batch.read_t_ns;
  t.sample_count = static_cast<std::uint32_t>(batch.samples.size());
  t.samples_left = batch.frames_left;
  t.fifo_overflow = (batch.flags & kImuFlagGapBefore) != 0 || batch.frames_discarded > 0;
  t.device_reset = (batch.flags & kImuFlagDeviceReset) != 0;
  return t;
}

ImuAcquisition::ImuAcquisition(mpu::Mpu6000& driver, drivers::DataReadyLine* line, AcquisitionClock& clock,
                               MountingMap mounting, AcquisitionOptions options)
    : driver_(driver),
      line_(line),
      clock_(clock),
      mounting_(std::move(mounting)),
      options_([&] {
        options.timestamps.nominal_rate_hz = driver.settings().sample_rate_hz();
        return options;
      }()),
      timestamper_(options_.timestamps) {
  edges_per_read_ =
      options_.edges_per_read > 0
          ? options_.edges_per_read
          : std::max(1, static_cast<int>(std::lround(options_.timestamps.nominal_rate_hz / 1000.0)));
  next_poll_ns_ = clock_.now_ns();
}

std::string ImuAcquisition::timing_metadata(double measured_rate_hz) const {
  RecordSummary summary;
  summary.rate_hz = measured_rate_hz;
  summary.period_error_ppm = period_error_ppm();
  summary.timing = timestamper_.stats();
  summary.acquisition = stats_;
  return timing_metadata_json(summary, timestamper_.options());
}

std::string ImuAcquisition::driver_metadata() const { return driver_metadata_json(driver_); }

Status ImuAcquisition::discard_pending_edges() {
  if (line_ == nullptr) return {};
  for (;;) {
    auto e = line_->wait(0);
    if (!e.ok()) return e.error().context("data-ready line");
    if (!e->has_value()) return {};
    ++stats_.edges;
  }
}

Status ImuAcquisition::step(std::vector<ImuSample>& out) {
  out.clear();
  std::optional<drivers::DataReadyEdge> edge;
  if (driver_.state() != mpu::State::kStream) {
    // Configuring: edges from before streaming must not anchor the timestamps.
    IMUCAL_TRY(discard_pending_edges());
    clock_.sleep_until(next_poll_ns_);
  } else if (line_ != nullptr) {
    for (int i = 0; i < edges_per_read_; ++i) {
      const TimeNs timeout = std::clamp<TimeNs>(next_poll_ns_ - clock_.now_ns(), 0, options_.edge_timeout_ns);
      auto e = line_->wait(timeout);
      if (!e.ok()) return e.error().context("data-ready line");
      if (!e->has_value()) {
        ++stats_.edge_timeouts;
        break;
      }
      ++stats_.edges;
      if (edge) driver_.on_edge(*edge);
      edge = **e;
    }
    // With a backlog (the host was late) the FIFO is read now, so the newest edge is the one
    // that belongs to its newest sample; the older ones are only counted.
    while (edge) {
      auto e = line_->wait(0);
      if (!e.ok()) return e.error().context("data-ready line");
      if (!e->has_value()) break;
      ++stats_.edges;
      driver_.on_edge(*edge);
      edge = **e;
    }
  } else {
    clock_.sleep_until(next_poll_ns_);
  }
  return poll_driver(clock_.now_ns(), edge, out);
}

Status ImuAcquisition::service(std::vector<ImuSample>& out) {
  out.clear();
  if (driver_.state() != mpu::State::kStream) {
    IMUCAL_TRY(discard_pending_edges());
    pending_edges_ = 0;
    pending_edge_.reset();
    const TimeNs now_ns = clock_.now_ns();
    if (now_ns < next_poll_ns_) return {};
    return poll_driver(now_ns, std::nullopt, out);
  }
  if (line_ != nullptr) {
    // As in step(): with a backlog the newest edge belongs to the newest sample in the FIFO;
    // the older ones are only counted.
    for (;;) {
      auto e = line_->wait(0);
      if (!e.ok()) return e.error().context("data-ready line");
      if (!e->has_value()) break;
      ++stats_.edges;
      if (pending_edge_) driver_.on_edge(*pending_edge_);
      pending_edge_ = **e;
      ++pending_edges_;
    }
  }
  const TimeNs now_ns = clock_.now_ns();
  if (pending_edges_ < edges_per_read_ && now_ns < next_poll_ns_) return {};
  if (line_ != nullptr && pending_edges_ < edges_per_read_) ++stats_.edge_timeouts;
  const std::optional<drivers::DataReadyEdge> edge = pending_edge_;
  pending_edges_ = 0;
  pending_edge_.reset();
  return poll_driver(now_ns, edge, out);
}

Status ImuAcquisition::poll_driver(TimeNs now_ns, std::optional<drivers::DataReadyEdge> edge,
                                   std::vector<ImuSample>& out) {
  auto polled = driver_.poll(now_ns, edge);
  if (!polled.ok()) return polled.error();
  ++stats_.polls;
  next_poll_ns_ = polled->next_poll_ns;
  if (!polled->batch) return {};
  const mpu::FifoBatch& batch = *polled->batch;
  if (batch.samples.empty() && batch.flags == kImuFlagNone) return {};

  const FifoBatchTiming timing = batch_timing(batch);
  const std::size_t n = batch.samples.size();
  t_buf_.assign(n, 0);
  flag_buf_.assign(n, 0);
  IMUCAL_TRY(timestamper_.process(timing, t_buf_, flag_buf_));
  ++stats_.batches;
  if (!timing.has_edge) ++stats_.batches_without_edge;
  stats_.samples += n;

  out.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const mpu::RawSample& r = batch.samples[i];
    ImuSample& s = out[i];
    s.t_ns = t_buf_[i];
    s.accel = Eigen::Vector3d(r.accel[0], r.accel[1], r.accel[2]);
    s.gyro = Eigen::Vector3d(r.gyro[0], r.gyro[1], r.gyro[2]);
    s.temperature = static_cast<double>(r.temp);
    s.flags = r.flags | flag_buf_[i];
    if (i == 0) s.flags |= batch.flags;
    if (mounting_.exact_on_raw()) mounting_.remap_raw_sample(s);
  }
  return {};
}

}  // namespace imucal::acq
