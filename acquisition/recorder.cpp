// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/recorder.hpp"

#include <fcntl.h>

#include <algorithm>
#include <boost/asio/io_context.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/signal_set.hpp>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <ctime>
#include <functional>
#include <nlohmann/json.hpp>
#include <span>
#include <sstream>

#include "acquisition/asio_acquisition.hpp"

namespace imucal::acq {

namespace mpu = drivers::mpu6000;

std::string timing_metadata_json(const RecordSummary& s, const TimestamperOptions& o) {
  nlohmann::json j;
  j["nominal_rate_hz"] = o.nominal_rate_hz;
  j["measured_rate_hz"] = s.rate_hz;
  j["period_error_ppm"] = s.period_error_ppm;
  j["edge_latency_ns"] = o.edge_latency_ns;
  j["edge_jitter_ns"] = o.edge_jitter_ns;
  j["batches"] = s.timing.batches;
  j["edges_accepted"] = s.timing.edges_accepted;
  j["edges_rejected"] = s.timing.edges_rejected;
  j["gaps"] = s.timing.gaps;
  j["resets"] = s.timing.resets;
  j["overflows"] = s.timing.overflows;
  j["reanchors"] = s.timing.reanchors;
  j["samples_lost"] = s.timing.samples_lost;
  j["monotonic_clamps"] = s.timing.monotonic_clamps;
  j["batches_without_edge"] = s.acquisition.batches_without_edge;
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

namespace {

std::string stream_json(const ImuStreamStats& s) {
  nlohmann::json j;
  j["published"] = s.published;
  j["log_written"] = s.log_written;
  j["log_dropped"] = s.log_dropped;
  j["log_batches"] = s.log_batches;
  j["log_queue_high_water"] = s.log_queue_high_water;
  j["events_dropped"] = s.events_dropped;
  for (const auto& c : s.consumers)
    j["consumers"][c.name] = {{"delivered", c.delivered}, {"dropped", c.dropped}};
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace

std::string driver_metadata_json(const mpu::Mpu6000& d) {
  const auto& c = d.counters();
  const auto& st = d.settings();
  nlohmann::json j;
  j["settings"] = {{"bus", st.bus == mpu::BusKind::kSpi ? "spi" : "i2c"},
                   {"accel_full_scale_g", mpu::accel_full_scale_g(st.accel_range)},
                   {"gyro_full_scale_dps", mpu::gyro_full_scale_dps(st.gyro_range)},
                   {"dlpf_cfg", st.dlpf_cfg},
                   {"smplrt_div", st.smplrt_div},
                   {"sample_rate_hz", st.sample_rate_hz()},
                   {"read_interval_ns", st.read_interval_ns}};
  j["counters"] = {{"bad_transfers", c.bad_transfers},
                   {"fifo_overflows", c.fifo_overflows},
                   {"fifo_resets", c.fifo_resets},
                   {"bad_fifo_counts", c.bad_fifo_counts},
                   {"implausible_data", c.implausible_data},
                   {"config_mismatches", c.config_mismatches},
                   {"resets", c.resets},
                   {"missed_data_ready", c.missed_data_ready},
                   {"no_data_timeouts", c.no_data_timeouts},
                   {"samples", c.samples},
                   {"frames_discarded", c.frames_discarded}};
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

std::string camera_metadata_json(const CameraAcquisitionStats& s) {
  nlohmann::json j;
  j["frames_published"] = s.stream.published;
  j["frames_written"] = s.stream.written;
  j["queue_dropped"] = s.stream.queue_dropped;
  j["device_dropped"] = s.stream.device_dropped + s.device.dropped;
  j["wrong_size"] = s.stream.wrong_size;
  j["encoded_bytes"] = s.stream.encoded_bytes;
  j["queue_high_water"] = s.stream.queue_high_water;
  j["device"] = {{"frames", s.device.frames},
                 {"dropped", s.device.dropped},
                 {"incomplete", s.device.incomplete},
                 {"packets_lost", s.device.packets_lost},
                 {"errors", s.device.errors}};
  j["stalls"] = s.stalls;
  j["failed"] = s.failed;
  if (s.failed) j["failure"] = s.failure;
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

std::string mounting_metadata_json(const MountingMap& m) {
  nlohmann::json j;
  j["kind"] = mounting_kind_name(m.kind());
  j["description"] = m.describe();
  j["samples_frame"] = m.exact_on_raw() ? "rig" : "imu";
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({m.R_rig_imu()(r, 0), m.R_rig_imu()(r, 1), m.R_rig_imu()(r, 2)});
  j["R_rig_imu"] = rows;
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

namespace {

/// What record_imu_session() does with each batch, in either loop: keeps exactly the requested
/// span of sample time, publishes, posts a fault event per new gap and reports progress.
class SessionSamples {
 public:
  SessionSamples(const ImuSource& acquisition, ImuStream& stream, const RecordOptions& options)
      : acquisition_(acquisition),
        stream_(stream),
        options_(options),
        duration_ns_(s_to_ns(options.duration_s)) {}

  /// False once the duration is recorded or the log failed.
  bool take(std::span<const ImuSample> samples) {
    if (samples.empty()) return true;
    if (!have_first_) {
      first_t_ns_ = samples.front().t_ns;
      have_first_ = true;
    }
    std::size_t keep = samples.size();
    while (keep > 0 && samples[keep - 1].t_ns - first_t_ns_ >= duration_ns_) --keep;
    stream_.publish(samples.first(keep));
    count_ += keep;
    if (keep > 0) last_t_ns_ = samples[keep - 1].t_ns;
    const auto gaps = acquisition_.timing_stats().gaps;
    if (gaps != last_gaps_) {
      log::Event e;
      e.t_ns = samples.front().t_ns;
      e.kind = "fault";
      e.message = "IMU sample gap (FIFO reset, overflow or lost samples); see imu.timing";
      stream_.post_event(std::move(e));
      last_gaps_ = gaps;
    }
    if (options_.progress) {
      options_.progress(std::min(1.0, ns_to_s(last_t_ns_ - first_t_ns_) / options_.duration_s));
    }
    return keep == samples.size() && !stream_.log_failed();
  }

  std::uint64_t count() const { return count_; }
  double span_s() const { return ns_to_s(last_t_ns_ - first_t_ns_); }
  TimeNs last_t_ns() const { return last_t_ns_; }

 private:
  const ImuSource& acquisition_;
  ImuStream& stream_;
  const RecordOptions& options_;
  TimeNs duration_ns_;
  TimeNs first_t_ns_ = 0, last_t_ns_ = 0;
  bool have_first_ = false;
  std::uint64_t count_ = 0;
  std::uint64_t last_gaps_ = 0;
};

/// The cameras of a recording: their streams into the log, serviced from the acquisition thread
/// after every IMU batch and, on the event loop, whenever a camera's descriptor turns readable.
class CameraSet {
 public:
  /// Declares each camera's stream, starts its encoder and the camera. Nothing has been recorded
  /// yet when this fails.
  Status open(const RecordOptions& options, log::SessionLogWriter& writer, ImuStream& events) {
    for (const RecordCamera& rc : options.cameras) {
      if (rc.camera == nullptr)
        return make_error(Errc::kInvalidArgument, "record: a camera entry without a camera");
      drivers::camera::Camera& cam = *rc.camera;
      const drivers::camera::FrameFormat format = cam.format();
      CameraStreamOptions so = rc.stream;
      // The step loop runs on a simulated clock, which stands still while the encoder catches
      // up: waiting loses nothing there, where dropping would lose frames a real-time rig keeps.
      if (options.loop == RecordLoop::kStep) so.block_when_full = true;
      auto stream = CameraStream::create(format, cam.timestamp_meaning(), so);
      if (!stream.ok()) return stream.error().context("camera " + rc.info.name);
      CameraStreamInfo info = rc.info;
      info.width = format.width;
      info.height = format.height;
      info.rate_hz = format.rate_hz;
      info.timestamp_source = (*stream)->timestamp_source();
      auto id = writer.add_camera_stream(info);
      if (!id.ok()) return id.error().context("declaring camera stream " + info.name);
      IMUCAL_TRY((*stream)->start_log(writer, *id));
      cameras_.push_back(std::make_unique<CameraAcquisition>(
          cam, info.name, std::move(*stream), [&events](log::Event e) { events.post_event(std::move(e)); },
          options.camera_stall_timeout_ns));
      auto st = cam.start();
      if (!st.ok()) return st.error().context("starting camera " + info.name);
    }
    return {};
  }

  void service(TimeNs now_ns) {
    for (auto& c : cameras_) c->service(now_ns);
  }

  /// Event loop: waits on each camera's descriptor (a duplicate of it) and services the camera
  /// when it turns readable. Cameras without one are serviced after every IMU batch only.
  void arm(boost::asio::io_context& io, const std::function<TimeNs()>& now) {
    for (auto& c : cameras_) {
      const int fd = c->camera().fd();
      if (fd < 0) continue;
      const int dup_fd = ::fcntl(fd, F_DUPFD_CLOEXEC, 0);
      if (dup_fd < 0) continue;
      descriptors_.push_back(std::make_unique<boost::asio::posix::stream_descriptor>(io, dup_fd));
      wait(*descriptors_.back(), *c, now);
    }
  }

  /// Stops the cameras, then writes what their encoders still hold. Returns the first error.
  Status close() {
    for (auto& d : descriptors_) d->cancel();
    Status first;
    for (auto& c : cameras_) {
      auto st = c->camera().stop();
      if (!st.ok() && first.ok()) first = st;
    }
    for (auto& c : cameras_) {
      auto st = c->stream().stop();
      if (!st.ok() && first.ok()) first = st.error().context("camera " + c->name());
    }
    return first;
  }

  void summarize(RecordSummary& summary, log::SessionLogWriter& writer) const {
    for (const auto& c : cameras_) {
      summary.cameras.push_back({c->name(), c->stats()});
      (void)writer.set_metadata("camera." + c->name(), camera_metadata_json(summary.cameras.back().stats));
    }
  }

 private:
  void wait(boost::asio::posix::stream_descriptor& d, CameraAcquisition& c,
            const std::function<TimeNs()>& now) {
    d.async_wait(boost::asio::posix::stream_descriptor::wait_read,
                 [this, &d, &c, now](const boost::system::error_code& ec) {
                   if (ec) return;
                   if (c.service(now())) wait(d, c, now);
                 });
  }

  std::vector<std::unique_ptr<CameraAcquisition>> cameras_;
  std::vector<std::unique_ptr<boost::asio::posix::stream_descriptor>> descriptors_;
};

/// Creates the log with the options' metadata, the mounting and the IMU stream.
Result<std::unique_ptr<log::SessionLogWriter>> create_session_log(const RecordOptions& options,
                                                                  const ImuSource& acquisition,
                                                                  int* stream_id) {
  log::SessionLogWriterOptions wo;
  wo.overwrite = options.overwrite;
  // On simulated time the samples come faster than the wall clock: bound each commit by sample
  // time as well, so a failure (a full disk) loses at most half a second of the recording.
  wo.commit_data_interval_ns = wo.commit_interval_ns;
  auto writer = log::SessionLogWriter::create(options.log_path, wo);
  if (!writer.ok()) return writer.error().context("creating the session log " + options.log_path);
  for (const auto& [key, value] : options.metadata) IMUCAL_TRY((*writer)->set_metadata(key, value));
  IMUCAL_TRY((*writer)->set_metadata("imu.mounting", mounting_metadata_json(acquisition.mounting())));
  auto id = (*writer)->add_imu_stream(options.stream_info);
  if (!id.ok()) return id.error().context("declaring the IMU stream");
  *stream_id = *id;
  return writer;
}

/// Fills the summary from every stage's counters and stores them in the log; this happens even
/// when recording stopped early.
void summarize(const ImuSource& acquisition, const SessionSamples& session, const ImuStream& stream,
               const CameraSet& cameras, log::SessionLogWriter& writer, RecordSummary& summary) {
  summary.samples = session.count();
  summary.timing = acquisition.timing_stats();
  summary.acquisition = acquisition.acquisition_stats();
  summary.stream = stream.stats();
  summary.duration_s = session.span_s();
  summary.rate_hz = summary.samples > 1 && summary.duration_s > 0
                        ? static_cast<double>(summary.samples - 1) / summary.duration_s
                        : 0.0;
  summary.period_error_ppm = acquisition.period_error_ppm();
  (void)writer.set_metadata("imu.timing", acquisition.timing_metadata(summary.rate_hz));
  (void)writer.set_metadata("imu.stream", stream_json(summary.stream));
  (void)writer.set_metadata("imu.driver", acquisition.driver_metadata());
  cameras.summarize(summary, writer);
}

}  // namespace

Result<RecordSummary> record_imu_session(ImuSource& acquisition, const RecordOptions& options) {
  if (!(options.duration_s > 0.0) || !std::isfinite(options.duration_s)) {
    return make_error(Errc::kInvalidArgument, "record: the duration must be a positive number of seconds");
  }
  RecordSummary summary;
  // The event loop and its signal handlers exist before the log does, so that a signal that
  // comes once the log exists always closes it cleanly; they go after the log is closed.
  boost::asio::io_context io;
  std::optional<boost::asio::signal_set> signals;
  // SIGHUP (the terminal or an ssh session went away) and SIGQUIT end a recording as cleanly as
  // SIGINT and SIGTERM; later signals while it is closing are ignored rather than killing it.
  if (options.loop == RecordLoop::kEventLoop && options.stop_on_signals) {
    signals.emplace(io, SIGINT, SIGTERM, SIGHUP);
    signals->add(SIGQUIT);
  }

  int stream_id = -1;
  auto writer_r = create_session_log(options, acquisition, &stream_id);
  if (!writer_r.ok()) return writer_r.error();
  auto writer = std::move(writer_r).value();

  // The IMU stream's writer thread and each camera's encoder share the log.
  auto shared_writer = log::synchronized_writer(*writer);
  ImuStream stream(options.stream);
  IMUCAL_TRY(stream.start_log(*shared_writer, stream_id));
  CameraSet cameras;
  if (auto st = cameras.open(options, *shared_writer, stream); !st.ok()) {
    (void)cameras.close();
    (void)stream.stop();
    (void)writer->close();
    return st.error();
  }

  SessionSamples session(acquisition, stream, options);
  Status failure;
  if (options.loop == RecordLoop::kStep) {
    std::vector<ImuSample> samples;
    while (true) {
      auto st = acquisition.step(samples);
      if (!st.ok()) {
        failure = st.error();
        break;
      }
      const bool more = session.take(samples);
      if (!samples.empty()) cameras.service(samples.back().t_ns);
      if (!more) break;
    }
  } else {
    AsioAcquisition runner(io, acquisition, [&](std::span<const ImuSample> s) {
      const bool more = session.take(s);
      cameras.service(s.back().t_ns);
      return more;
    });
    cameras.arm(io, [&] { return session.last_t_ns(); });
    std::function<void(const boost::system::error_code&, int)> on_signal;
    on_signal = [&](const boost::system::error_code& ec, int signal) {
      if (ec) return;
      if (!summary.interrupted) {
        summary.interrupted = true;
        summary.signal = signal;
        runner.stop();
      }
      signals->async_wait(on_signal);  // stay armed: a second Ctrl-C must not kill the close
    };
    if (signals) signals->async_wait(on_signal);
    failure = runner.run();
  }
  auto camera_status = cameras.close();
  auto stop_status = stream.stop();

  summarize(acquisition, session, stream, cameras, *writer, summary);
  if (!stop_status.ok()) return stop_status.error();
  if (!camera_status.ok()) {
    (void)writer->close();
    return camera_status.error().context("writing camera frames");
  }
  if (!failure.ok()) {
    (void)writer->close();
    return failure.error().context("recording stopped after " + std::to_string(summary.samples) + " samples");
  }
  IMUCAL_TRY(writer->close());
  return summary;
}

}  // namespace imucal::acq
