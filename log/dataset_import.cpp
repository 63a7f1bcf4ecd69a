// Imports of plain-text accelerometer/gyroscope files and generic CSV into session logs.

#include <algorithm>
#include <cmath>
#include <future>
#include <nlohmann/json.hpp>
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

/// Writes one IMU stream to `out` (a PendingOutput file) and renames it into place.
Status write_imu_log(PendingOutput& out, const ImuStreamInfo& info, const std::vector<ImuSample>& samples,
                     const nlohmann::json& source, const ProgressFn& progress) {
  SessionLogWriterOptions staged;
  staged.staged = true;
  auto writer = SessionLogWriter::create(out.temp_path(), staged);
  if (!writer.ok()) return writer.error().context("cannot create the session log");
  SessionLogWriter& w = **writer;
  IMUCAL_TRY(w.set_metadata("import", source.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
  auto id = w.add_imu_stream(info);
  if (!id.ok()) return id.error();
  constexpr std::size_t kBatch = 8192;
  for (std::size_t i = 0; i < samples.size(); i += kBatch) {
    const std::size_t n = std::min(kBatch, samples.size() - i);
    IMUCAL_TRY(w.append_imu(*id, std::span<const ImuSample>(samples.data() + i, n)));
    report_progress(progress, static_cast<double>(i + n), static_cast<double>(samples.size()));
  }
  IMUCAL_TRY(w.close());
  writer->reset();
  return out.commit();
}

ImportSummary summarize(const ImuStreamInfo& info, const std::vector<ImuSample>& samples) {
  ImportSummary s;
  s.imu_samples = static_cast<std::int64_t>(samples.size());
  s.imu_streams = 1;
  s.rate_hz = info.rate_hz;
  if (!samples.empty()) {
    s.t_first_ns = samples.front().t_ns;
    s.t_last_ns = samples.back().t_ns;
  }
  return s;
}

/// Progress over the three phases of an import: parse, check, write.
ProgressFn phase(const ProgressFn& progress, double start, double share) {
  if (!progress) return {};
  return [progress, start, share](double fraction) { progress(start + share * fraction); };
}

}  // namespace

Result<ImportSummary> import_ascii(const AsciiImport& in, const std::string& out_path,
                                   const OutputOptions& options) {
  auto out = PendingOutput::begin(out_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  // The files are independent: the gyroscope's is parsed on a second thread meanwhile (the
  // accelerometer's progress stands for both).
  auto gyro_parse = std::async(std::launch::async, [&in] { return parse_triad_file(in.gyro_path, {}); });
  auto accel = parse_triad_file(in.accel_path, phase(options.progress, 0.0, 0.6));
  auto gyro = gyro_parse.get();
  if (!accel.ok()) return accel.error();
  if (!gyro.ok()) return gyro.error();

  auto period =
      sample_period_ns(accel->t_ns, in.rate_hz, in.accel_path, "that the time column is in seconds");
  if (!period.ok()) return period.error();
  PairingStats stats;
  auto samples = pair_accel_gyro(*accel, *gyro, *period, &stats);
  if (!samples.ok()) return samples.error();
  if (samples->size() < 2) {
    return make_error(Errc::kInsufficientData, in.accel_path + " and " + in.gyro_path +
                                                   ": fewer than 2 paired samples; nothing to import");
  }
  if (in.unit_check) IMUCAL_TRY(check_units(*samples, in.units, in.accel_path));

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
  IMUCAL_TRY(write_imu_log(*out, info, *samples, source, phase(options.progress, 0.6, 0.4)));

  ImportSummary summary = summarize(info, *samples);
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
  if (in.units == ImuUnits::kRaw) {
    summary.notes.push_back("raw counts kept; nominal accelerometer conversion " + describe(in.accel) +
                            ", gyroscope " + describe(in.gyro));
  }
  return summary;
}

Result<ImportSummary> import_csv(const CsvImport& in, const std::string& out_path,
                                 const OutputOptions& options) {
  auto out = PendingOutput::begin(out_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  auto samples = parse_imu_csv_file(in.path, in.format, phase(options.progress, 0.0, 0.5));
  if (!samples.ok()) return samples.error();
  if (samples->size() < 2) {
    return make_error(Errc::kInsufficientData, in.path + ": fewer than 2 samples; nothing to import");
  }
  std::vector<TimeNs> t(samples->size());
  for (std::size_t i = 0; i < t.size(); ++i) t[i] = (*samples)[i].t_ns;
  auto period = sample_period_ns(
      t, in.rate_hz, in.path, std::string("the time unit (now ") + time_unit_name(in.format.time_unit) + ")");
  if (!period.ok()) {
    return period.error().code == Errc::kCorrupt ? period.error().with_remedy("time_unit") : period.error();
  }
  if (in.unit_check) IMUCAL_TRY(check_units(*samples, in.units, in.path));

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
  IMUCAL_TRY(write_imu_log(*out, info, *samples, source, phase(options.progress, 0.5, 0.5)));
  ImportSummary summary = summarize(info, *samples);
  if (in.units == ImuUnits::kRaw) {
    summary.notes.push_back("raw counts kept; nominal accelerometer conversion " + describe(in.accel) +
                            ", gyroscope " + describe(in.gyro));
  }
  return summary;
}

}  // namespace imucal::log
