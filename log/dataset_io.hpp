// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Import and export of dataset formats (docs/datasets.md):
//   - EuRoC/ASL folders (mav0/imuN/data.csv, mav0/camN/data.csv + data/<t_ns>.png, sensor.yaml),
//     both ways, exact: timestamps are integer nanoseconds, values are written in the shortest
//     form that reads back to the same double, PNG bytes are copied unchanged;
//   - plain-text accelerometer and gyroscope files ("t x y z" rows, t in seconds), as imu_tk
//     and many IMU tools write them, in raw counts or SI;
//   - generic CSV with a column mapping;
//   - ROS 1 bags (sensor_msgs/Imu, Image, CompressedImage topics; log/rosbag.hpp), both ways.
// Every import writes a session log through a temporary file next to the output, renamed into
// place only when complete; a failure removes it. An existing output is replaced only with
// `force`. Parse errors name the file, the line (and column) and what is wrong.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/frame.hpp"
#include "core/imu.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "core/text_file.hpp"
#include "core/time.hpp"
#include "log/frame_codec.hpp"

namespace imucal::log {

struct OutputOptions {
  bool force = false;   // replace an existing output
  ProgressFn progress;  // may be empty
  /// Imports whose input files together are at most this large are parsed once and held in
  /// memory; larger ones are read twice (checked, then written as they are read again), so that
  /// memory does not grow with the input. The log written is the same either way.
  std::uint64_t in_memory_bytes = std::uint64_t{64} << 20;
};

/// An output file or folder written under a temporary name next to its final path
/// ("<path>.partial-<pid>") and renamed into place by commit(). Destroyed without commit, it
/// removes what was written, so a failed import or export never leaves a partial output that
/// looks complete.
class PendingOutput {
 public:
  enum class Kind { kFile, kDirectory };

  /// Checks that `final_path` can be written (its folder exists; it does not exist, or `force`).
  /// For a folder, the temporary folder is created; for a file, only the name is chosen.
  [[nodiscard]] static Result<PendingOutput> begin(const std::string& final_path, Kind kind, bool force);

  PendingOutput(PendingOutput&& other) noexcept;
  PendingOutput& operator=(PendingOutput&&) = delete;
  PendingOutput(const PendingOutput&) = delete;
  PendingOutput& operator=(const PendingOutput&) = delete;
  ~PendingOutput();

  const std::string& temp_path() const { return temp_path_; }
  const std::string& final_path() const { return final_path_; }

  /// Renames the temporary output into place, replacing an existing one (only with `force`).
  [[nodiscard]] Status commit();

 private:
  PendingOutput(std::string final_path, std::string temp_path, Kind kind, bool force);
  void discard();

  std::string final_path_;
  std::string temp_path_;
  Kind kind_;
  bool force_;
  bool done_ = false;
};

/// Refuses an output path that exists and is not a regular file (a device, a FIFO, a socket, a
/// folder; a symbolic link is judged by what it points to): such a path is never replaced, with
/// --force or not (kInvalidArgument). A log another process is writing (a recording: its writer
/// holds a flock on it) is refused too (kIo, naming the process). A missing path is fine.
[[nodiscard]] Status check_replaceable(const std::string& path);

/// Removes what writers killed before their rename left beside `final_path`:
/// "<path>.partial-<pid>-<n>" (an import or export, with its -wal, -shm and -journal) and
/// "<path>.tmp-<pid>" (a result file), once no process <pid> runs. A running process's
/// temporaries and every other name are left alone. PendingOutput::begin and the result writers
/// call it before they write.
void remove_stale_temporaries(const std::string& final_path);

/// Renames `from` to `to`; unless `replace`, fails with kAlreadyExists when `to` exists, atomically
/// (renameat2 RENAME_NOREPLACE, or link + unlink where the filesystem lacks it), so of two
/// processes writing one output the second is refused instead of replacing the first's.
[[nodiscard]] Status rename_into_place(const std::string& from, const std::string& to, bool replace);

/// Reads a whole file; the error names the path (core/text_file.hpp).
using imucal::read_text_file;

// ---------------------------------------------------------------------------------------------
// Text primitives (exposed for tests and other readers).

enum class TimeUnit { kS, kMs, kUs, kNs };
/// "s", "ms", "us", "ns".
[[nodiscard]] Result<TimeUnit> parse_time_unit(const std::string& name);
const char* time_unit_name(TimeUnit unit);

/// A decimal time value in `unit` to integer nanoseconds. Plain decimals ("1403636579.763555527")
/// convert exactly; exponent notation is accepted; the result is rounded to the nearest ns.
[[nodiscard]] Result<TimeNs> parse_time_ns(std::string_view text, TimeUnit unit);

/// A finite double; accepts a leading '+'. Reads exactly what format_double writes.
[[nodiscard]] Result<double> parse_double(std::string_view text);

/// Shortest decimal text that reads back to exactly `value` (std::to_chars).
std::string format_double(double value);

// ---------------------------------------------------------------------------------------------
// Plain-text triads and generic CSV.

/// Timed 3-vectors from one file, with the line each came from.
struct TriadSeries {
  std::string source;
  std::vector<TimeNs> t_ns;
  std::vector<Eigen::Vector3d> xyz;
  std::vector<int> line;
};

/// Parses whitespace-separated "t x y z" rows (t in seconds); '#' comments and blank lines are
/// skipped. Timestamps must increase strictly.
[[nodiscard]] Result<TriadSeries> parse_triad_text(std::string_view text, const std::string& source,
                                                   const ProgressFn& progress = {});

/// One "t x y z" row and the line it came from.
struct TriadRow {
  TimeNs t_ns = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  int line = 0;
};

/// Rows in time order, one at a time.
class TriadSource {
 public:
  virtual ~TriadSource() = default;
  /// The next row (true) or the end (false); an error when the rows cannot be read.
  [[nodiscard]] virtual Result<bool> next(TriadRow& row) = 0;
};

/// The rows of a "t x y z" file (or text), read line by line with the checks of
/// parse_triad_text: a malformed line, times that do not increase, a read error, or no row at
/// all are errors.
class TriadRowReader final : public TriadSource {
 public:
  [[nodiscard]] static Result<std::unique_ptr<TriadRowReader>> open(const std::string& path,
                                                                    const ProgressFn& progress = {});
  TriadRowReader(std::string_view text, const std::string& source, const ProgressFn& progress = {});
  ~TriadRowReader() override;
  TriadRowReader(const TriadRowReader&) = delete;
  TriadRowReader& operator=(const TriadRowReader&) = delete;
  [[nodiscard]] Result<bool> next(TriadRow& row) override;

 private:
  struct State;
  explicit TriadRowReader(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

/// The rows of a TriadSeries held in memory.
class TriadSeriesSource final : public TriadSource {
 public:
  explicit TriadSeriesSource(const TriadSeries& series) : series_(series) {}
  [[nodiscard]] Result<bool> next(TriadRow& row) override;

 private:
  const TriadSeries& series_;
  std::size_t next_ = 0;
};

/// The exact median interval between consecutive times (median_interval_ns), fed one time at a
/// time. Memory: one counter per distinct interval, few for a sampled signal.
class IntervalMedian {
 public:
  void add(TimeNs t_ns);
  /// Times added.
  std::int64_t times() const { return times_; }
  /// The upper median interval; 0 with fewer than two times.
  TimeNs median() const;

 private:
  // Equal intervals in a row are counted here before they go into the map (most of a sampled
  // signal's are equal).
  std::map<TimeNs, std::int64_t> counts_;
  TimeNs run_interval_ = 0;
  std::int64_t run_length_ = 0;
  TimeNs last_ = 0;
  std::int64_t times_ = 0;
};

/// Sample period used to pair accelerometer and gyroscope rows: from rate_hz if > 0, else the
/// median interval of `t_ns`. Fails when the median interval is not plausible: the message says
/// to check `time_hint` (e.g. "the time unit (now ms)").
[[nodiscard]] Result<TimeNs> sample_period_ns(const std::vector<TimeNs>& t_ns, double rate_hz,
                                              const std::string& source, const std::string& time_hint);
/// The same from intervals counted as the times were read.
[[nodiscard]] Result<TimeNs> sample_period_ns(const IntervalMedian& intervals, double rate_hz,
                                              const std::string& source, const std::string& time_hint);

struct PairingStats {
  int exact = 0;          // rows whose timestamps matched exactly
  int nearest = 0;        // rows paired with the nearest row within half a period
  int dropped_accel = 0;  // accelerometer rows outside the gyroscope's time span
  int dropped_gyro = 0;   // gyroscope rows outside the accelerometer's time span
};

/// Pairs accelerometer and gyroscope rows into samples stamped with the accelerometer's time.
/// Rows outside the common time span are dropped (and counted); inside it, every row must
/// have a partner within half a sample period, else the error names both files and lines.
[[nodiscard]] Result<std::vector<ImuSample>> pair_accel_gyro(const TriadSeries& accel,
                                                             const TriadSeries& gyro, TimeNs period_ns,
                                                             PairingStats* stats = nullptr);

/// How many rows a file has and the times of its first and last (from a first reading).
struct TriadSpan {
  std::string source;
  std::int64_t rows = 0;
  TimeNs first_ns = 0;
  TimeNs last_ns = 0;
};

/// pair_accel_gyro one sample at a time, from rows as they are read: the same samples, stats and
/// errors, without holding the rows. The spans are those of the whole files.
class TriadPairer {
 public:
  TriadPairer(TriadSource& accel, TriadSpan accel_span, TriadSource& gyro, TriadSpan gyro_span,
              TimeNs period_ns);
  /// The next sample (true) or the end (false); pairing errors as pair_accel_gyro's.
  [[nodiscard]] Result<bool> next(ImuSample& sample);
  /// Complete once next() returned false.
  const PairingStats& stats() const { return stats_; }

 private:
  Result<bool> next_kept(TriadSource& source, const TriadSpan& other, std::int64_t* kept, TriadRow& row);
  Error no_overlap() const;

  TriadSource& accel_;
  TriadSource& gyro_;
  TriadSpan accel_span_, gyro_span_;
  TimeNs half_ = 0;
  std::int64_t accel_kept_ = 0, gyro_kept_ = 0;
  std::optional<TriadRow> gyro_row_;  // the next kept gyroscope row, read ahead
  bool gyro_done_ = false;
  bool done_ = false;
  PairingStats stats_;
};

/// Column indexes (0-based) of a generic CSV; -1 = absent.
struct CsvColumns {
  int t = -1, ax = -1, ay = -1, az = -1, gx = -1, gy = -1, gz = -1, temp = -1;
};
/// Parses "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6[,temp=7]".
[[nodiscard]] Result<CsvColumns> parse_csv_columns(const std::string& spec);

struct CsvFormat {
  CsvColumns columns;
  TimeUnit time_unit = TimeUnit::kS;
  char delimiter = ',';  // ' ' means any run of spaces or tabs
  int skip_header = 0;   // lines skipped before parsing (headers)
};
/// Parses a CSV into samples (temperature NaN when there is no temp column).
[[nodiscard]] Result<std::vector<ImuSample>> parse_imu_csv(std::string_view text, const std::string& source,
                                                           const CsvFormat& format,
                                                           const ProgressFn& progress = {});
/// Reads the CSV at `path` line by line (never whole; read errors are errors) and gives each
/// sample to `visit` (the checks of parse_imu_csv); an error from `visit` ends the reading with it.
[[nodiscard]] Status for_each_csv_sample(const std::string& path, const CsvFormat& format,
                                         const std::function<Status(const ImuSample&)>& visit,
                                         const ProgressFn& progress = {});

/// Unit sanity check: SI data whose accelerometer magnitude is far above 100 look like raw
/// counts; raw data with a magnitude near 9.8 and non-integral values look like SI. The error
/// names the flag to use.
[[nodiscard]] Status check_units(const std::vector<ImuSample>& samples, ImuUnits units,
                                 const std::string& source);

/// check_units fed one accelerometer sample at a time: it keeps an evenly spaced subset of
/// 20000 to 40000 of them (every 2^k-th).
class UnitCheck {
 public:
  void add(const Eigen::Vector3d& accel);
  [[nodiscard]] Status check(ImuUnits units, const std::string& source) const;

 private:
  std::vector<Eigen::Vector3d> kept_;
  std::int64_t stride_ = 1;
  std::int64_t seen_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Imports and exports.

/// Whether input files of these sizes together are at most `in_memory_bytes`
/// (OutputOptions::in_memory_bytes): then they are parsed once and held.
[[nodiscard]] bool inputs_fit_in_memory(const std::vector<std::string>& paths, std::uint64_t in_memory_bytes);

/// The refusal of an input whose second reading found `then` rows (or samples) where the first
/// found `first`.
[[nodiscard]] Error changed_while_imported(const std::string& source, std::int64_t first, std::int64_t then);

class SessionLogWriter;

/// Appends one IMU stream's samples to a session log in batches of 8192 as they come, counting
/// them and their time span; `on_flush(n)` follows every batch written.
class ImuBatchWriter {
 public:
  ImuBatchWriter(SessionLogWriter& writer, int stream_id, std::function<void(std::size_t)> on_flush = {});
  [[nodiscard]] Status add(const ImuSample& sample);
  /// Writes what is left of the last batch.
  [[nodiscard]] Status flush();
  std::int64_t count() const { return count_; }
  TimeNs first_ns() const { return first_ns_; }
  TimeNs last_ns() const { return last_ns_; }

 private:
  static constexpr std::size_t kBatch = 8192;
  SessionLogWriter& writer_;
  int stream_id_;
  std::function<void(std::size_t)> on_flush_;
  std::vector<ImuSample> batch_;
  std::int64_t count_ = 0;
  TimeNs first_ns_ = 0, last_ns_ = 0;
};

struct ImportSummary {
  std::int64_t imu_samples = 0;
  std::int64_t frames = 0;
  int imu_streams = 0;
  int camera_streams = 0;
  double rate_hz = 0.0;  // first IMU stream
  TimeNs t_first_ns = 0;
  TimeNs t_last_ns = 0;
  std::vector<std::string> notes;  // things the user should know (dropped rows, conversions)
};

/// Nominal raw->SI conversions used when a raw import gives none: the MPU-6000 power-on ranges,
/// +-2 g (16384 LSB/g) and +-250 deg/s (131 LSB/(deg/s)).
AxisConversion default_raw_accel_conversion();
AxisConversion default_raw_gyro_conversion();

struct AsciiImport {
  std::string accel_path;
  std::string gyro_path;
  ImuUnits units = ImuUnits::kSi;
  double rate_hz = 0.0;                                   // 0: estimate from the timestamps
  AxisConversion accel = default_raw_accel_conversion();  // raw only
  AxisConversion gyro = default_raw_gyro_conversion();    // raw only
  bool unit_check = true;
};
[[nodiscard]] Result<ImportSummary> import_ascii(const AsciiImport& in, const std::string& out_path,
                                                 const OutputOptions& options);

struct CsvImport {
  std::string path;
  CsvFormat format;
  ImuUnits units = ImuUnits::kSi;
  double rate_hz = 0.0;
  AxisConversion accel = default_raw_accel_conversion();
  AxisConversion gyro = default_raw_gyro_conversion();
  bool unit_check = true;
  double temperature_scale = 1.0;  // deg C = scale * value + offset (raw streams)
  double temperature_offset = 0.0;
};
[[nodiscard]] Result<ImportSummary> import_csv(const CsvImport& in, const std::string& out_path,
                                               const OutputOptions& options);

/// EuRoC/ASL folder: `dir` may be the dataset folder or its mav0/.
[[nodiscard]] Result<ImportSummary> import_euroc(const std::string& dir, const std::string& out_path,
                                                 const OutputOptions& options);

struct ExportSummary {
  std::int64_t imu_samples = 0;
  std::int64_t frames = 0;
  std::vector<std::string> notes;
};

/// Writes a session log as an EuRoC/ASL folder `dir`/mav0/. Raw-count streams are converted to
/// SI with the stream's nominal conversion (and a note says so). A damaged or incomplete log is
/// refused unless `allow_damaged`.
[[nodiscard]] Result<ExportSummary> export_euroc(const std::string& log_path, const std::string& dir,
                                                 const OutputOptions& options, bool allow_damaged = false);

/// The pixels of a stored frame: PNG and WebP decoded, raw gray8 and gray16 as they are.
[[nodiscard]] Result<Image> frame_image(const CameraFrame& frame);

/// A ROS 1 bag import (log/rosbag.hpp, docs/datasets.md).
struct BagImport {
  std::string path;
  /// The topics to import, in stream order (sensor_msgs/Imu topics become imu0, imu1, ...; image
  /// topics cam0, cam1, ...). Empty: every Imu, Image and CompressedImage topic, by name.
  std::vector<std::string> topics;
  /// Stamp with the time the bag received each message instead of its header.stamp.
  bool receive_time = false;
  /// Import the whole chunks of a bag that is cut short or damaged (a note says where it ends).
  bool allow_damaged = false;
};
/// Imports a ROS 1 bag or a ROS 2 bag (folder, .db3 or .mcap) into a session log. A bag cut short
/// or damaged, and one in a form imucal does not read (ROS 1 format 1.2, JPEG images, Bayer
/// encodings), is Errc::kCorrupt with what is wrong named.
[[nodiscard]] Result<ImportSummary> import_bag(const BagImport& in, const std::string& out_path,
                                               const OutputOptions& options);

enum class BagCompression { kNone, kBz2, kLz4 };
/// Writes a session log as a ROS 1 bag that Kalibr and rosbag read: each IMU stream as
/// sensor_msgs/Imu on /imuN (SI), each camera as sensor_msgs/Image on /camN/image_raw (mono8,
/// mono16 or bgr8), stamped (header and receive time) with the log's times.
[[nodiscard]] Result<ExportSummary> export_bag(const std::string& log_path, const std::string& bag_path,
                                               const OutputOptions& options, bool allow_damaged = false,
                                               BagCompression compression = BagCompression::kNone);

// EuRoC pieces, exposed for tests.
struct EurocImageRow {
  TimeNs t_ns = 0;
  std::string filename;
  int line = 0;
};
[[nodiscard]] Result<std::vector<ImuSample>> parse_euroc_imu_csv(std::string_view text,
                                                                 const std::string& source);
/// Reads an EuRoC imuN/data.csv line by line and gives each sample to `visit` (the checks of
/// parse_euroc_imu_csv); an error from `visit` ends the reading with it.
[[nodiscard]] Status for_each_euroc_imu_sample(const std::string& path,
                                               const std::function<Status(const ImuSample&)>& visit);
[[nodiscard]] Result<std::vector<EurocImageRow>> parse_euroc_camera_csv(std::string_view text,
                                                                        const std::string& source);

}  // namespace imucal::log
