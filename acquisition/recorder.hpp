#pragma once
// The IMU acquisition loop and the recording session around it.
//
// ImuAcquisition turns the MPU-6000 driver's FIFO batches into timestamped samples: it waits
// for data-ready edges (or, without a line, for the driver's next poll time), polls the driver,
// reconstructs per-sample times (timestamp.hpp), remaps axes exactly when the mounting allows
// it (mounting.hpp) and hands the samples to an ImuStream. It works the same on a rig (real
// clock, spidev/i2c-dev, libgpiod) and in simulation (the emulator's clock, which runs as fast
// as the host can compute).
//
// record_imu_session() creates the session log, writes the metadata (rig configuration,
// driver settings, mounting, timing), records for a given duration of sample time and closes
// the log with the counters of every stage.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

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
  /// Longest wait for a data-ready edge before polling anyway.
  TimeNs edge_timeout_ns = 20'000'000;
};

struct AcquisitionStats {
  std::uint64_t polls = 0;
  std::uint64_t batches = 0;
  std::uint64_t samples = 0;
  std::uint64_t edge_timeouts = 0;  // waits that ended without an edge
  std::uint64_t batches_without_edge = 0;
};

class ImuAcquisition {
 public:
  /// Everything is borrowed. `line` may be null (no data-ready interrupt: poll the FIFO).
  ImuAcquisition(drivers::mpu6000::Mpu6000& driver, drivers::DataReadyLine* line, AcquisitionClock& clock,
                 MountingMap mounting, AcquisitionOptions options);

  /// Waits for the next edge (or poll time), polls the driver and appends the samples of the
  /// batch, if any, to `out` (cleared first). Errors are the driver's unrecoverable ones.
  [[nodiscard]] Status step(std::vector<ImuSample>& out);

  const SampleTimestamper& timestamper() const { return timestamper_; }
  const AcquisitionStats& stats() const { return stats_; }
  const MountingMap& mounting() const { return mounting_; }
  /// True when samples are remapped to rig axes (exact mounting), false when they stay in the
  /// IMU's axes (general mounting: applied in SI after calibration).
  bool samples_in_rig_frame() const { return mounting_.exact_on_raw(); }

 private:
  drivers::mpu6000::Mpu6000& driver_;
  drivers::DataReadyLine* line_;
  AcquisitionClock& clock_;
  MountingMap mounting_;
  AcquisitionOptions options_;
  SampleTimestamper timestamper_;
  int edges_per_read_ = 1;
  TimeNs next_poll_ns_ = 0;
  std::vector<TimeNs> t_buf_;
  std::vector<std::uint32_t> flag_buf_;
  AcquisitionStats stats_;
};

struct RecordOptions {
  std::string log_path;
  bool overwrite = false;
  double duration_s = 10.0;   // of sample time
  ImuStreamInfo stream_info;  // name, units, conversion, device settings
  /// Metadata written before recording (e.g. "rig_config" as JSON, "source": "sim").
  std::vector<std::pair<std::string, std::string>> metadata;
  ImuStreamOptions stream;
  /// Receives the recorded fraction in [0, 1] (may be empty).
  std::function<void(double)> progress;
};

struct RecordSummary {
  std::uint64_t samples = 0;
  double duration_s = 0.0;        // first to last sample time
  double rate_hz = 0.0;           // measured
  double period_error_ppm = 0.0;  // the chip's rate against nominal, as estimated
  TimestamperStats timing;
  ImuStreamStats stream;
  AcquisitionStats acquisition;
};

/// Records `options.duration_s` of samples through `acquisition` into a new session log.
/// Driver counters and the timing/stream counters are stored in the log's metadata.
[[nodiscard]] Result<RecordSummary> record_imu_session(ImuAcquisition& acquisition,
                                                       const drivers::mpu6000::Mpu6000& driver,
                                                       const RecordOptions& options);

/// Session-log metadata written by record_imu_session(), for other writers of IMU sessions:
/// "imu.timing" (timestamper counters), "imu.driver" (settings and failure counters per
/// cause), "imu.mounting".
std::string timing_metadata_json(const RecordSummary& summary, const TimestamperOptions& options);
std::string driver_metadata_json(const drivers::mpu6000::Mpu6000& driver);
std::string mounting_metadata_json(const MountingMap& mounting);

}  // namespace imucal::acq
