#include "acquisition/recorder.hpp"

#include <algorithm>
#include <boost/asio/io_context.hpp>
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
  return j.dump();
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
  return j.dump();
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
  return j.dump();
}

std::string mounting_metadata_json(const MountingMap& m) {
  nlohmann::json j;
  j["kind"] = mounting_kind_name(m.kind());
  j["description"] = m.describe();
  j["samples_frame"] = m.exact_on_raw() ? "rig" : "imu";
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({m.R_rig_imu()(r, 0), m.R_rig_imu()(r, 1), m.R_rig_imu()(r, 2)});
  j["R_rig_imu"] = rows;
  return j.dump();
}

namespace {

/// What record_imu_session() does with each batch, in either loop: keeps exactly the requested
/// span of sample time, publishes, posts a fault event per new gap and reports progress.
class SessionSamples {
 public:
  SessionSamples(ImuAcquisition& acquisition, ImuStream& stream, const RecordOptions& options)
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
    const auto gaps = acquisition_.timestamper().stats().gaps;
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

 private:
  ImuAcquisition& acquisition_;
  ImuStream& stream_;
  const RecordOptions& options_;
  TimeNs duration_ns_;
  TimeNs first_t_ns_ = 0, last_t_ns_ = 0;
  bool have_first_ = false;
  std::uint64_t count_ = 0;
  std::uint64_t last_gaps_ = 0;
};

}  // namespace

Result<RecordSummary> record_imu_session(ImuAcquisition& acquisition, const mpu::Mpu6000& driver,
                                         const RecordOptions& options) {
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

  log::SessionLogWriterOptions wo;
  wo.overwrite = options.overwrite;
  auto writer_r = log::SessionLogWriter::create(options.log_path, wo);
  if (!writer_r.ok()) return writer_r.error().context("creating the session log " + options.log_path);
  auto writer = std::move(writer_r).value();

  for (const auto& [key, value] : options.metadata) IMUCAL_TRY(writer->set_metadata(key, value));
  IMUCAL_TRY(writer->set_metadata("imu.mounting", mounting_metadata_json(acquisition.mounting())));
  auto stream_id = writer->add_imu_stream(options.stream_info);
  if (!stream_id.ok()) return stream_id.error().context("declaring the IMU stream");

  ImuStream stream(options.stream);
  IMUCAL_TRY(stream.start_log(*writer, *stream_id));

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
      if (!session.take(samples)) break;
    }
  } else {
    AsioAcquisition runner(io, acquisition, [&](std::span<const ImuSample> s) { return session.take(s); });
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
  auto stop_status = stream.stop();

  summary.samples = session.count();
  summary.timing = acquisition.timestamper().stats();
  summary.acquisition = acquisition.stats();
  summary.stream = stream.stats();
  summary.duration_s = session.span_s();
  summary.rate_hz = summary.samples > 1 && summary.duration_s > 0
                        ? static_cast<double>(summary.samples - 1) / summary.duration_s
                        : 0.0;
  summary.period_error_ppm = acquisition.timestamper().period_error_ppm();

  // Counters go into the log even when recording stopped early.
  (void)writer->set_metadata("imu.timing",
                             timing_metadata_json(summary, acquisition.timestamper().options()));
  (void)writer->set_metadata("imu.stream", stream_json(summary.stream));
  (void)writer->set_metadata("imu.driver", driver_metadata_json(driver));
  if (!stop_status.ok()) return stop_status.error();
  if (!failure.ok()) {
    (void)writer->close();
    return failure.error().context("recording stopped after " + std::to_string(summary.samples) + " samples");
  }
  IMUCAL_TRY(writer->close());
  return summary;
}

}  // namespace imucal::acq
