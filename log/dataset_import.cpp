// SPDX-License-Identifier: BSD-3-Clause
// Imports of plain-text accelerometer/gyroscope files and generic CSV into session logs.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <future>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "log/dataset_io.hpp"
#include "log/session_log.hpp"

namespace imucal::log {

AxisConversion default_raw_accel_conversion() {
  AxisConversion c;
  c.scale = Eigen::Vector3d::Constant(kStandardGravity / 16384.0);  // MPU-6000 +-2 g: 16384 LSB/g
  return c;
}

AxisConversion default_raw_gyro_conversion() {
  AxisConversion c;
  c.scale = Eigen::Vector3d::Constant(M_PI / 180.0 / 131.0);  // MPU-6000 +-250 deg/s: 131 LSB/(deg/s)
  return c;
}

namespace {

std::string describe(const AxisConversion& c) {
  std::ostringstream s;
  s.precision(9);
  s << "scale [" << c.scale.x() << ", " << c.scale.y() << ", " << c.scale.z() << "], offset [" << c.offset.x()
    << ", " << c.offset.y() << ", " << c.offset.z() << "]";
  return s.str();
}

/// One IMU stream written to a staged session log at `out`'s temporary path as the samples come.
class ImuLogSink {
 public:
  static Result<std::unique_ptr<ImuLogSink>> create(const PendingOutput& out, const ImuStreamInfo& info,
                                                    const nlohmann::json& source, double expected,
                                                    ProgressFn progress) {
    SessionLogWriterOptions staged;
    staged.staged = true;
    staged.commit_data_interval_ns = 0;  // nothing reads it before close()
    auto writer = SessionLogWriter::create(out.temp_path(), staged);
    if (!writer.ok()) return writer.error().context("cannot create the session log");
    IMUCAL_TRY((*writer)->set_metadata(
        "import", source.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
    auto id = (*writer)->add_imu_stream(info);
    if (!id.ok()) return id.error();
    return std::unique_ptr<ImuLogSink>(
        new ImuLogSink(std::move(*writer), *id, expected, std::move(progress)));
  }

  Status add(const ImuSample& sample) { return batches_.add(sample); }

  /// Writes what is left and closes the log (not yet renamed into place).
  Status close() {
    IMUCAL_TRY(batches_.flush());
    IMUCAL_TRY(writer_->close());
    writer_.reset();
    report_progress(progress_, 1.0, 1.0);
    return {};
  }

  const ImuBatchWriter& samples() const { return batches_; }

 private:
  ImuLogSink(std::unique_ptr<SessionLogWriter> writer, int id, double expected, ProgressFn progress)
      : writer_(std::move(writer)),
        progress_(std::move(progress)),
        batches_(*writer_, id, [this, expected](std::size_t) {
          const auto done = static_cast<double>(batches_.count());
          report_progress(progress_, done, std::max(expected, done));
        }) {}

  std::unique_ptr<SessionLogWriter> writer_;
  ProgressFn progress_;
  ImuBatchWriter batches_;
};

/// Progress over the phases of an import: parse (and check), then write.
ProgressFn phase(const ProgressFn& progress, double start, double share) {
  if (!progress) return {};
  return [progress, start, share](double fraction) { progress(start + share * fraction); };
}

/// What a first reading of a "t x y z" file found: how many rows and their span, the intervals
/// and the unit check (of the accelerometer's file) and, when the inputs are small, the rows.
struct TriadScan {
  TriadSpan span;
  IntervalMedian intervals;
  UnitCheck units;
  std::optional<TriadSeries> rows;
};

Result<TriadScan> scan_triad_file(const std::string& path, bool hold, bool checks,
                                  const ProgressFn& progress) {
  auto reader = TriadRowReader::open(path, progress);
  if (!reader.ok()) return reader.error();
  TriadScan scan;
  scan.span.source = path;
  if (hold) {
    scan.rows.emplace();
    scan.rows->source = path;
    // Room for the rows of lines of 32 bytes or more (a "t x y z" line is longer): the vectors
    // are filled without being moved as they grow, and what is not filled is never touched.
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(path, ec);
    if (!ec) {
      const auto rows = static_cast<std::size_t>(bytes / 32);
      scan.rows->t_ns.reserve(rows);
      scan.rows->xyz.reserve(rows);
      scan.rows->line.reserve(rows);
    }
  }
  TriadRow row;
  while (true) {
    auto more = (*reader)->next(row);
    if (!more.ok()) return more.error();
    if (!*more) break;
    if (scan.span.rows++ == 0) scan.span.first_ns = row.t_ns;
    scan.span.last_ns = row.t_ns;
    if (checks) {
      scan.intervals.add(row.t_ns);
      scan.units.add(row.xyz);
    }
    if (hold) {
      scan.rows->t_ns.push_back(row.t_ns);
      scan.rows->xyz.push_back(row.xyz);
      scan.rows->line.push_back(row.line);
    }
  }
  return scan;
}

/// The rows of a scanned file for the second reading: from memory, or the file read again.
Result<std::unique_ptr<TriadSource>> reread(const TriadScan& scan) {
  if (scan.rows) return std::unique_ptr<TriadSource>(std::make_unique<TriadSeriesSource>(*scan.rows));
  auto reader = TriadRowReader::open(scan.span.source);
  if (!reader.ok()) return reader.error();
  return std::unique_ptr<TriadSource>(std::move(*reader));
}

/// Passes rows on and counts them; finish() reads what is left, so that a file that changed
/// between the two readings is found.
class CountingSource final : public TriadSource {
 public:
  explicit CountingSource(TriadSource& inner) : inner_(inner) {}
  Result<bool> next(TriadRow& row) override {
    auto more = inner_.next(row);
    if (more.ok() && *more) ++rows_;
    return more;
  }
  /// Reads the rest of the rows; an error when there are not as many as the first reading found.
  Status finish(const TriadSpan& span) {
    TriadRow row;
    while (true) {
      auto more = next(row);
      if (!more.ok()) return more.error();
      if (!*more) break;
    }
    if (rows_ == span.rows) return {};
    return changed_while_imported(span.source, span.rows, rows_);
  }

 private:
  TriadSource& inner_;
  std::int64_t rows_ = 0;
};

void add_raw_note(const ImuStreamInfo& info, ImportSummary* summary) {
  if (info.units != ImuUnits::kRaw) return;
  summary->notes.push_back("raw counts kept; nominal accelerometer conversion " + describe(info.accel) +
                           ", gyroscope " + describe(info.gyro));
}

ImportSummary summarize(const ImuStreamInfo& info, const ImuLogSink& sink) {
  ImportSummary s;
  s.imu_samples = sink.samples().count();
  s.imu_streams = 1;
  s.rate_hz = info.rate_hz;
  s.t_first_ns = sink.samples().first_ns();
  s.t_last_ns = sink.samples().last_ns();
  return s;
}

}  // namespace

bool inputs_fit_in_memory(const std::vector<std::string>& paths, std::uint64_t in_memory_bytes) {
  std::uint64_t total = 0;
  for (const auto& path : paths) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    if (!ec) total += size;
  }
  return total <= in_memory_bytes;
}

Error changed_while_imported(const std::string& source, std::int64_t first, std::int64_t then) {
  return make_error(Errc::kCorrupt, source + " changed while it was imported (" + std::to_string(first) +
                                        " rows, then " + std::to_string(then) + "): import it again");
}

ImuBatchWriter::ImuBatchWriter(SessionLogWriter& writer, int stream_id,
                               std::function<void(std::size_t)> on_flush)
    : writer_(writer), stream_id_(stream_id), on_flush_(std::move(on_flush)) {
  batch_.reserve(kBatch);
}

Status ImuBatchWriter::add(const ImuSample& sample) {
  if (count_++ == 0) first_ns_ = sample.t_ns;
  last_ns_ = sample.t_ns;
  batch_.push_back(sample);
  return batch_.size() == kBatch ? flush() : Status{};
}

Status ImuBatchWriter::flush() {
  if (batch_.empty()) return {};
  IMUCAL_TRY(writer_.append_imu(stream_id_, batch_));
  const std::size_t n = batch_.size();
  batch_.clear();
  if (on_flush_) on_flush_(n);
  return {};
}

Result<ImportSummary> import_ascii(const AsciiImport& in, const std::string& out_path,
                                   const OutputOptions& options) {
  auto out = PendingOutput::begin(out_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  const bool hold = inputs_fit_in_memory({in.accel_path, in.gyro_path}, options.in_memory_bytes);
  // First reading, which checks every line: the files are independent, so the gyroscope's is read
  // on a second thread meanwhile (the accelerometer's progress stands for both).
  auto gyro_scan =
      std::async(std::launch::async, [&in, hold] { return scan_triad_file(in.gyro_path, hold, false, {}); });
  auto accel = scan_triad_file(in.accel_path, hold, true, phase(options.progress, 0.0, hold ? 0.6 : 0.5));
  auto gyro = gyro_scan.get();
  if (!accel.ok()) return accel.error();
  if (!gyro.ok()) return gyro.error();

  auto period =
      sample_period_ns(accel->intervals, in.rate_hz, in.accel_path, "that the time column is in seconds");
  if (!period.ok()) return period.error();
  if (in.unit_check) IMUCAL_TRY(accel->units.check(in.units, in.accel_path));

  ImuStreamInfo info;
  info.name = "imu0";
  info.units = in.units;
  info.rate_hz = 1e9 / static_cast<double>(*period);
  if (in.rate_hz > 0) info.rate_hz = in.rate_hz;
  if (in.units == ImuUnits::kRaw) {
    info.accel = in.accel;
    info.gyro = in.gyro;
  }
  info.device = "ascii:" + in.accel_path;
  nlohmann::json source = {{"format", "ascii"},
                           {"accel", in.accel_path},
                           {"gyro", in.gyro_path},
                           {"units", imu_units_name(in.units)}};

  // Second reading: pair the rows and write the samples as they are paired.
  auto accel_rows = reread(*accel);
  if (!accel_rows.ok()) return accel_rows.error();
  auto gyro_rows = reread(*gyro);
  if (!gyro_rows.ok()) return gyro_rows.error();
  CountingSource accel_counted(**accel_rows), gyro_counted(**gyro_rows);
  TriadPairer pairer(accel_counted, accel->span, gyro_counted, gyro->span, *period);
  auto sink = ImuLogSink::create(*out, info, source, static_cast<double>(accel->span.rows),
                                 phase(options.progress, hold ? 0.6 : 0.5, hold ? 0.4 : 0.5));
  if (!sink.ok()) return sink.error();
  ImuSample sample;
  while (true) {
    auto more = pairer.next(sample);
    if (!more.ok()) return more.error();
    if (!*more) break;
    IMUCAL_TRY((*sink)->add(sample));
  }
  IMUCAL_TRY(accel_counted.finish(accel->span));
  IMUCAL_TRY(gyro_counted.finish(gyro->span));
  if ((*sink)->samples().count() < 2) {
    return make_error(Errc::kInsufficientData, in.accel_path + " and " + in.gyro_path +
                                                   ": fewer than 2 paired samples; nothing to import");
  }
  IMUCAL_TRY((*sink)->close());
  IMUCAL_TRY(out->commit());

  ImportSummary summary = summarize(info, **sink);
  const PairingStats& stats = pairer.stats();
  if (stats.nearest > 0) {
    summary.notes.push_back(
        std::to_string(stats.nearest) +
        " rows paired with the nearest gyroscope row (timestamps differ by less than half a "
        "sample period); samples carry the accelerometer's time");
  }
  if (stats.dropped_accel > 0 || stats.dropped_gyro > 0) {
    summary.notes.push_back("dropped " + std::to_string(stats.dropped_accel) + " accelerometer and " +
                            std::to_string(stats.dropped_gyro) +
                            " gyroscope rows outside the time span both files cover");
  }
  add_raw_note(info, &summary);
  return summary;
}

Result<ImportSummary> import_csv(const CsvImport& in, const std::string& out_path,
                                 const OutputOptions& options) {
  auto out = PendingOutput::begin(out_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  const bool hold = inputs_fit_in_memory({in.path}, options.in_memory_bytes);
  // First reading: every line checked; the intervals and the unit check gathered.
  std::vector<ImuSample> held;
  IntervalMedian intervals;
  UnitCheck units;
  IMUCAL_TRY(for_each_csv_sample(
      in.path, in.format,
      [&](const ImuSample& s) {
        intervals.add(s.t_ns);
        units.add(s.accel);
        if (hold) held.push_back(s);
        return Status{};
      },
      phase(options.progress, 0.0, 0.5)));
  if (intervals.times() < 2) {
    return make_error(Errc::kInsufficientData, in.path + ": fewer than 2 samples; nothing to import");
  }
  auto period =
      sample_period_ns(intervals, in.rate_hz, in.path,
                       std::string("the time unit (now ") + time_unit_name(in.format.time_unit) + ")");
  if (!period.ok()) {
    return period.error().code == Errc::kCorrupt ? period.error().with_remedy("time_unit") : period.error();
  }
  if (in.unit_check) IMUCAL_TRY(units.check(in.units, in.path));

  ImuStreamInfo info;
  info.name = "imu0";
  info.units = in.units;
  info.rate_hz = in.rate_hz > 0 ? in.rate_hz : 1e9 / static_cast<double>(*period);
  if (in.units == ImuUnits::kRaw) {
    info.accel = in.accel;
    info.gyro = in.gyro;
  }
  info.temperature_scale = in.temperature_scale;
  info.temperature_offset = in.temperature_offset;
  info.device = "csv:" + in.path;
  nlohmann::json source = {{"format", "csv"},
                           {"path", in.path},
                           {"time_unit", time_unit_name(in.format.time_unit)},
                           {"units", imu_units_name(in.units)}};
  // Second reading (or the held samples): written as they come.
  auto sink = ImuLogSink::create(*out, info, source, static_cast<double>(intervals.times()),
                                 phase(options.progress, 0.5, 0.5));
  if (!sink.ok()) return sink.error();
  if (hold) {
    for (const auto& s : held) IMUCAL_TRY((*sink)->add(s));
  } else {
    IMUCAL_TRY(
        for_each_csv_sample(in.path, in.format, [&sink](const ImuSample& s) { return (*sink)->add(s); }));
  }
  if ((*sink)->samples().count() != intervals.times()) {
    return changed_while_imported(in.path, intervals.times(), (*sink)->samples().count());
  }
  IMUCAL_TRY((*sink)->close());
  IMUCAL_TRY(out->commit());
  ImportSummary summary = summarize(info, **sink);
  add_raw_note(info, &summary);
  return summary;
}

}  // namespace imucal::log
