// SPDX-License-Identifier: BSD-3-Clause
// EuRoC/ASL dataset folders, both ways. Layout (per sensor folder under mav0/):
//   imuN/data.csv    #timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]
//   camN/data.csv    #timestamp [ns],filename       camN/data/<filename> (PNG)
//   */sensor.yaml    sensor_type, T_BS, rate_hz, resolution (cameras), ...
// Import keeps the original sensor.yaml text in the log metadata so that an export writes it
// back unchanged; logs recorded on a rig get a generated one.

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <set>

#include "log/dataset_io.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"

namespace imucal::log {
namespace fs = std::filesystem;

namespace {

constexpr const char* kImuHeader =
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
    "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";
constexpr const char* kCameraHeader = "#timestamp [ns],filename";

std::string sensor_yaml_key(const std::string& stream) { return "euroc." + stream + ".sensor_yaml"; }

struct SensorYaml {
  std::string text;  // empty when there is no sensor.yaml
  double rate_hz = 0.0;
  int width = 0;
  int height = 0;
};

/// The highest rate a sensor.yaml may give (above it, no IMU or camera: a damaged or foreign file).
constexpr double kMaxSensorRateHz = 100'000.0;

Result<SensorYaml> read_sensor_yaml(const fs::path& folder) {
  SensorYaml s;
  const fs::path path = folder / "sensor.yaml";
  std::error_code ec;
  if (!fs::exists(path, ec)) return s;
  auto text = read_text_file(path.string());
  if (!text.ok()) return text.error();
  s.text = *text;
  YAML::Node root;
  try {
    root = YAML::Load(s.text);
  } catch (const YAML::ParserException& e) {
    return make_error(Errc::kCorrupt,
                      path.string() + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
  }
  if (!root.IsMap()) return s;
  try {
    if (root["rate_hz"]) s.rate_hz = root["rate_hz"].as<double>();
    if (const YAML::Node r = root["resolution"]) {
      if (!r.IsSequence() || r.size() != 2) throw YAML::Exception(r.Mark(), "resolution");
      s.width = r[0].as<int>();
      s.height = r[1].as<int>();
    }
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, path.string() + ":" + std::to_string(e.mark.line + 1) +
                                          ": rate_hz must be a number and resolution [width, height]");
  }
  if (!(s.rate_hz >= 0.0) || s.width < 0 || s.height < 0) {
    return make_error(Errc::kCorrupt, path.string() + ": rate_hz and resolution must not be negative");
  }
  if (s.rate_hz > kMaxSensorRateHz) {
    return make_error(
        Errc::kCorrupt,
        path.string() + ": rate_hz " + format_double(s.rate_hz) +
            " Hz is above 100 kHz, the rate of no IMU or camera: fix or remove rate_hz (the rate "
            "is then taken from the timestamps)");
  }
  return s;
}

/// Sensor folders named <prefix><number>, sorted by number. A number too large for an index
/// is an error: such a folder would otherwise be left out without a word.
Result<std::vector<std::pair<int, fs::path>>> sensor_folders(const fs::path& root,
                                                             const std::string& prefix) {
  std::vector<std::pair<int, fs::path>> out;
  const std::regex pattern(prefix + "([0-9]+)");
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(root, ec)) {
    std::smatch m;
    const std::string name = entry.path().filename().string();
    if (!entry.is_directory(ec) || !std::regex_match(name, m, pattern)) continue;
    const std::string digits = m[1].str();
    int index = 0;
    const auto [ptr, err] = std::from_chars(digits.data(), digits.data() + digits.size(), index);
    if (err != std::errc() || ptr != digits.data() + digits.size()) {
      return make_error(Errc::kCorrupt, (root / name).string() + ": the sensor number " + printable(digits) +
                                            " is too large for a EuRoC sensor folder (rename it, e.g. " +
                                            prefix + "1)");
    }
    out.emplace_back(index, entry.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

/// The size of a PNG from its header (log/frame_codec.hpp), false when it is not a PNG.
bool png_size(const std::vector<std::uint8_t>& data, int& width, int& height) {
  auto size = png_dimensions(data);
  if (!size.ok()) return false;
  width = size->width;
  height = size->height;
  return true;
}

/// The largest image file read (a 16-bit 8192 x 8192 PNG is 128 MiB uncompressed).
constexpr std::size_t kMaxImageBytes = std::size_t{256} << 20;
/// The largest image side accepted: no camera comes near it, and decoding it would not fit.
constexpr int kMaxImageSide = 32768;

Result<std::vector<std::uint8_t>> read_binary(const fs::path& path) {
  // Regular files only (a folder or a FIFO is refused), read errors reported, size bounded.
  auto text = read_text_file(path.string(), kMaxImageBytes);
  if (!text.ok()) return text.error();
  return std::vector<std::uint8_t>(text->begin(), text->end());
}

/// PNG bytes of a stored frame: PNG as is, other encodings decoded and encoded losslessly.
Result<std::vector<std::uint8_t>> frame_png(const CameraFrame& frame) {
  if (frame.encoding == "png") return frame.data;
  auto image = frame_image(frame);
  if (!image.ok()) return image.error();
  return encode_png(*image);
}

struct ImuFolder {
  std::string name;
  std::string csv;  // imuN/data.csv
  std::int64_t count = 0;
  TimeNs first_ns = 0, last_ns = 0;
  double median_rate_hz = 0.0;
  std::optional<std::vector<ImuSample>> samples;  // held when the inputs are small
  SensorYaml sensor;
};

struct CameraFolder {
  std::string name;
  fs::path data_dir;
  std::vector<EurocImageRow> rows;
  SensorYaml sensor;
};

Result<fs::path> euroc_root(const std::string& dir) {
  std::error_code ec;
  const fs::path p(dir);
  if (!fs::is_directory(p, ec)) {
    return make_error(Errc::kNotFound,
                      dir + " is not a folder (expected an EuRoC dataset folder or its mav0/)");
  }
  if (fs::is_directory(p / "mav0", ec)) return p / "mav0";
  auto imus = sensor_folders(p, "imu");
  if (!imus.ok()) return imus.error();
  auto cams = sensor_folders(p, "cam");
  if (!cams.ok()) return cams.error();
  if (!imus->empty() || !cams->empty()) return p;
  return make_error(Errc::kNotFound, dir +
                                         " is not an EuRoC dataset: it has neither mav0/ nor imuN/ or camN/ "
                                         "folders (give the dataset folder or its mav0/)");
}

double median_rate_hz(const std::vector<TimeNs>& t) {
  const TimeNs period_ns = median_interval_ns(t);
  return period_ns > 0 ? 1e9 / static_cast<double>(period_ns) : 0.0;
}

}  // namespace

namespace {

/// Every imuN/ folder's data.csv and sensor.yaml, read and checked before anything is written so
/// that a malformed file fails fast. The samples are held when all the data.csv files together
/// are at most `in_memory_bytes`; else they are read again while written.
Result<std::vector<ImuFolder>> read_imu_folders(const fs::path& root, std::uint64_t in_memory_bytes) {
  std::vector<ImuFolder> imus;
  auto folders = sensor_folders(root, "imu");
  if (!folders.ok()) return folders.error();
  std::vector<std::string> files;
  for (const auto& [index, folder] : *folders) files.push_back((folder / "data.csv").string());
  const bool hold = inputs_fit_in_memory(files, in_memory_bytes);
  for (const auto& [index, folder] : *folders) {
    ImuFolder f;
    f.name = folder.filename().string();
    f.csv = (folder / "data.csv").string();
    if (hold) f.samples.emplace();
    IntervalMedian intervals;
    IMUCAL_TRY(for_each_euroc_imu_sample(f.csv, [&](const ImuSample& s) {
      if (f.count++ == 0) f.first_ns = s.t_ns;
      f.last_ns = s.t_ns;
      intervals.add(s.t_ns);
      if (f.samples) f.samples->push_back(s);
      return Status{};
    }));
    if (f.count == 0) return make_error(Errc::kCorrupt, f.csv + ": no data rows");
    const TimeNs period_ns = intervals.median();
    f.median_rate_hz = period_ns > 0 ? 1e9 / static_cast<double>(period_ns) : 0.0;
    auto sensor = read_sensor_yaml(folder);
    if (!sensor.ok()) return sensor.error();
    f.sensor = std::move(*sensor);
    imus.push_back(std::move(f));
  }
  return imus;
}

/// Every camN/ folder's image list and sensor.yaml (the images are read while writing).
Result<std::vector<CameraFolder>> read_camera_folders(const fs::path& root) {
  std::vector<CameraFolder> cams;
  auto folders = sensor_folders(root, "cam");
  if (!folders.ok()) return folders.error();
  for (const auto& [index, folder] : *folders) {
    CameraFolder f;
    f.name = folder.filename().string();
    f.data_dir = folder / "data";
    const std::string csv = (folder / "data.csv").string();
    auto text = read_text_file(csv);
    if (!text.ok()) return text.error();
    auto rows = parse_euroc_camera_csv(*text, csv);
    if (!rows.ok()) return rows.error();
    f.rows = std::move(*rows);
    auto sensor = read_sensor_yaml(folder);
    if (!sensor.ok()) return sensor.error();
    f.sensor = std::move(*sensor);
    cams.push_back(std::move(f));
  }
  return cams;
}

/// Progress in work units: one per IMU sample, kPerImage per image.
class WorkProgress {
 public:
  static constexpr double kPerImage = 50.0;
  WorkProgress(double total, const ProgressFn& report) : report_(report), total_(total) {}
  void advance(double amount) {
    done_ += amount;
    report_progress(report_, done_, total_);
  }

 private:
  const ProgressFn& report_;
  double total_ = 0.0;
  double done_ = 0.0;
};

double import_work(const std::vector<ImuFolder>& imus, const std::vector<CameraFolder>& cams) {
  double total = 0.0;
  for (const auto& f : imus) total += static_cast<double>(f.count);
  for (const auto& f : cams) total += WorkProgress::kPerImage * static_cast<double>(f.rows.size());
  return total;
}

Status write_imu_folder(SessionLogWriter& w, const ImuFolder& f, ImportSummary& summary,
                        WorkProgress& progress) {
  ImuStreamInfo info;
  info.name = f.name;
  info.units = ImuUnits::kSi;
  info.rate_hz = f.sensor.rate_hz > 0 ? f.sensor.rate_hz : f.median_rate_hz;
  info.device = "euroc:" + f.name;
  if (!f.sensor.text.empty()) IMUCAL_TRY(w.set_metadata(sensor_yaml_key(f.name), f.sensor.text));
  auto id = w.add_imu_stream(info);
  if (!id.ok()) return id.error();
  ImuBatchWriter batches(w, *id, [&progress](std::size_t n) { progress.advance(static_cast<double>(n)); });
  if (f.samples) {
    for (const auto& s : *f.samples) IMUCAL_TRY(batches.add(s));
  } else {
    IMUCAL_TRY(for_each_euroc_imu_sample(f.csv, [&batches](const ImuSample& s) { return batches.add(s); }));
  }
  IMUCAL_TRY(batches.flush());
  if (batches.count() != f.count) return changed_while_imported(f.csv, f.count, batches.count());
  summary.imu_samples += f.count;
  if (summary.imu_streams++ == 0) {
    summary.rate_hz = info.rate_hz;
    summary.t_first_ns = f.first_ns;
    summary.t_last_ns = f.last_ns;
  }
  return {};
}

/// One image file as a stored frame: a PNG as it is, a WebP decoded and stored as lossless PNG
/// (*converted set). EuRoC folders hold PNG; other formats are refused with the file named.
Result<CameraFrame> image_frame(const CameraFolder& f, const EurocImageRow& row, bool* converted) {
  const fs::path image_path = f.data_dir / row.filename;
  const std::string where = (f.data_dir.parent_path() / "data.csv").string() + ":" + std::to_string(row.line);
  auto data = read_binary(image_path);
  if (!data.ok())
    return make_error(data.error().code, where + ": image missing or unreadable: " + data.error().message);
  CameraFrame frame;
  frame.t_ns = row.t_ns;
  frame.encoding = "png";
  *converted = false;
  if (png_size(*data, frame.width, frame.height)) {
    if (frame.width > kMaxImageSide || frame.height > kMaxImageSide) {
      return make_error(Errc::kCorrupt,
                        where + ": " + image_path.string() + " claims " + std::to_string(frame.width) + "x" +
                            std::to_string(frame.height) + " pixels, more than any camera (" +
                            std::to_string(kMaxImageSide) + " a side): a damaged or foreign file");
    }
    // Stored as it is, so decoded once here: a PNG cut short or damaged would otherwise enter
    // the log with a checksum of its damaged bytes, and every later reader take it as sound.
    if (auto decoded = decode_png(*data); !decoded.ok()) {
      return make_error(Errc::kCorrupt, where + ": " + image_path.string() + " is a damaged PNG (" +
                                            decoded.error().message + ")");
    }
    frame.data = std::move(*data);
    return frame;
  }
  auto image = decode_image(*data);
  if (!image.ok()) {
    return make_error(Errc::kCorrupt, where + ": " + image_path.string() +
                                          " is not a readable PNG or WebP image (" + image.error().message +
                                          ")");
  }
  auto png = encode_png(*image);
  if (!png.ok()) return png.error();
  frame.data = std::move(*png);
  frame.width = image->width;
  frame.height = image->height;
  *converted = true;
  return frame;
}

Status write_camera_folder(SessionLogWriter& w, const CameraFolder& f, ImportSummary& summary,
                           WorkProgress& progress) {
  CameraStreamInfo info;
  info.name = f.name;
  info.backend = "euroc";
  info.device = "euroc:" + f.name;
  info.timestamp_source = "dataset";
  std::vector<TimeNs> t(f.rows.size());
  for (std::size_t i = 0; i < t.size(); ++i) t[i] = f.rows[i].t_ns;
  info.rate_hz = f.sensor.rate_hz > 0 ? f.sensor.rate_hz : median_rate_hz(t);
  info.width = f.sensor.width;
  info.height = f.sensor.height;
  // Without a resolution in sensor.yaml, the first image gives it.
  if ((info.width == 0 || info.height == 0) && !f.rows.empty()) {
    auto data = read_binary(f.data_dir / f.rows.front().filename);
    if (data.ok()) png_size(*data, info.width, info.height);
  }
  if (!f.sensor.text.empty()) IMUCAL_TRY(w.set_metadata(sensor_yaml_key(f.name), f.sensor.text));
  auto id = w.add_camera_stream(info);
  if (!id.ok()) return id.error();
  int converted = 0, mismatched = 0;
  std::uint32_t sequence = 0;
  for (const auto& row : f.rows) {
    bool was_converted = false;
    auto frame = image_frame(f, row, &was_converted);
    if (!frame.ok()) return frame.error();
    frame->sequence = sequence++;
    converted += was_converted ? 1 : 0;
    if (frame->width != info.width || frame->height != info.height) ++mismatched;
    IMUCAL_TRY(w.append_frame(*id, *frame));
    progress.advance(WorkProgress::kPerImage);
  }
  summary.frames += static_cast<std::int64_t>(f.rows.size());
  ++summary.camera_streams;
  if (converted > 0) {
    summary.notes.push_back(f.name + ": " + std::to_string(converted) +
                            " images were not PNG and were stored as lossless PNG");
  }
  if (mismatched > 0) {
    summary.notes.push_back(f.name + ": " + std::to_string(mismatched) + " images differ in size from " +
                            std::to_string(info.width) + "x" + std::to_string(info.height) +
                            " (sensor.yaml resolution or first image)");
  }
  return {};
}

}  // namespace

Result<Image> frame_image(const CameraFrame& frame) {
  const std::size_t pixels = static_cast<std::size_t>(std::max(frame.width, 0)) * std::max(frame.height, 0);
  if (frame.encoding == "gray8" || frame.encoding == "GREY" || frame.encoding == "Y800") {
    if (frame.data.size() != pixels || pixels == 0) {
      return make_error(Errc::kCorrupt, "frame at t_ns " + std::to_string(frame.t_ns) + " holds " +
                                            std::to_string(frame.data.size()) + " bytes, expected " +
                                            std::to_string(pixels) + " for " + frame.encoding);
    }
    return Image{frame.width, frame.height, 1, 8, frame.data};
  }
  if (frame.encoding == "Y16 " || frame.encoding == "gray16") {
    if (frame.data.size() != 2 * pixels || pixels == 0) {
      return make_error(Errc::kCorrupt, "frame at t_ns " + std::to_string(frame.t_ns) +
                                            " has the wrong size for " + frame.encoding);
    }
    return Image{frame.width, frame.height, 1, 16, frame.data};  // little-endian host
  }
  auto decoded = decode_image(frame.data);
  if (!decoded.ok()) {
    return make_error(Errc::kUnsupported, "frame at t_ns " + std::to_string(frame.t_ns) + " has encoding '" +
                                              frame.encoding + "', which cannot be decoded (" +
                                              decoded.error().message + ")");
  }
  return std::move(*decoded);
}

Result<ImportSummary> import_euroc(const std::string& dir, const std::string& out_path,
                                   const OutputOptions& options) {
  auto out = PendingOutput::begin(out_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  auto root = euroc_root(dir);
  if (!root.ok()) return root.error();
  auto imus = read_imu_folders(*root, options.in_memory_bytes);
  if (!imus.ok()) return imus.error();
  auto cams = read_camera_folders(*root);
  if (!cams.ok()) return cams.error();
  if (imus->empty() && cams->empty()) {
    return make_error(Errc::kInsufficientData, root->string() + " has no imuN/ or camN/ folders");
  }

  ImportSummary summary;
  WorkProgress progress(import_work(*imus, *cams), options.progress);
  {
    SessionLogWriterOptions staged;
    staged.staged = true;
    staged.commit_data_interval_ns = 0;  // nothing reads it before close()
    auto writer = SessionLogWriter::create(out->temp_path(), staged);
    if (!writer.ok()) return writer.error().context("cannot create the session log");
    SessionLogWriter& w = **writer;
    nlohmann::json source = {{"format", "euroc"}, {"path", fs::absolute(*root).string()}};
    IMUCAL_TRY(
        w.set_metadata("import", source.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
    for (const auto& f : *imus) IMUCAL_TRY(write_imu_folder(w, f, summary, progress));
    for (const auto& f : *cams) IMUCAL_TRY(write_camera_folder(w, f, summary, progress));
    IMUCAL_TRY(w.close());
  }
  IMUCAL_TRY(out->commit());
  return summary;
}

namespace {

std::string identity_t_bs() {
  return "T_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0, 0.0,\n         0.0, 1.0, 0.0, 0.0,\n"
         "         0.0, 0.0, 1.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\n";
}

std::string imu_sensor_yaml(const ImuStreamInfo& info, const std::string& log_path) {
  std::string s = "# Written by imucal from " + log_path + ".\n";
  s += "# T_BS is unknown here and written as identity. Noise densities and random walks are not\n";
  s += "# known from a recording alone: estimate them with 'imucal allan'.\n";
  s += "sensor_type: imu\n";
  s += "comment: \"" + info.name + " (" + (info.device.empty() ? "unknown device" : info.device) + ")\"\n";
  s += identity_t_bs();
  s += "rate_hz: " + format_double(info.rate_hz) + "\n";
  return s;
}

std::string camera_sensor_yaml(const CameraStreamInfo& info, const std::string& log_path) {
  std::string s = "# Written by imucal from " + log_path + ".\n";
  s += "# T_BS is unknown here and written as identity. Intrinsics are not part of a recording:\n";
  s += "# calibrate them with 'imucal calibrate camera'.\n";
  s += "sensor_type: camera\n";
  s += "comment: \"" + info.name + " (" + info.backend + (info.device.empty() ? "" : " " + info.device) +
       ")\"\n";
  s += identity_t_bs();
  s += "rate_hz: " + format_double(info.rate_hz) + "\n";
  s += "resolution: [" + std::to_string(info.width) + ", " + std::to_string(info.height) + "]\n";
  return s;
}

Status write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  out.close();
  if (!out) return make_error(Errc::kIo, "cannot write " + path.string());
  return {};
}

/// Folder names for streams: the stream's own name when it is <prefix>N and unique, else <prefix><index>.
template <class Info>
std::map<int, std::string> folder_names(const std::map<int, Info>& streams, const std::string& prefix) {
  std::map<int, std::string> names;
  std::set<std::string> used;
  const std::regex pattern(prefix + "[0-9]+");
  for (const auto& [id, info] : streams) {
    if (std::regex_match(info.name, pattern) && used.insert(info.name).second) names[id] = info.name;
  }
  int next = 0;
  for (const auto& [id, info] : streams) {
    if (names.count(id)) continue;
    while (used.count(prefix + std::to_string(next))) ++next;
    names[id] = prefix + std::to_string(next);
    used.insert(names[id]);
  }
  return names;
}

}  // namespace

namespace {

/// The file an export writes beside mav0/, by which --force knows a folder it may replace.
constexpr const char* kExportMarker = "imucal-export.txt";

/// Refuses what must not be exported or replaced, before anything is written.
Status check_export(const SessionLogReader& r, const std::string& log_path, const std::string& dir,
                    const OutputOptions& options, bool allow_damaged) {
  if (r.health().damaged && !allow_damaged) {
    return make_error(Errc::kCorrupt, log_path + " is damaged (" + r.health().damage_message +
                                          "); only what is readable can be exported")
        .with_remedy("allow_damaged");
  }
  std::error_code ec;
  // Never into the folder that holds the log (replacing it would delete the log).
  const fs::path log_abs = fs::weakly_canonical(log_path, ec);
  const fs::path dir_abs = fs::weakly_canonical(dir, ec);
  for (fs::path p = log_abs.parent_path(); !p.empty(); p = p.parent_path()) {
    if (p == dir_abs) {
      return make_error(Errc::kInvalidArgument,
                        dir + " holds the log being exported (" + log_path + "); export to another folder");
    }
    if (p == p.root_path()) break;
  }
  // --force replaces only an earlier export (it carries kExportMarker): a folder from anywhere
  // else (a downloaded dataset with its ground truth, whatever its layout) is never deleted.
  if (options.force && fs::is_directory(dir, ec) && !fs::is_empty(dir, ec) &&
      !fs::exists(fs::path(dir) / kExportMarker, ec)) {
    return make_error(
        Errc::kInvalidArgument,
        dir + " is not an earlier imucal export (it has no " + std::string(kExportMarker) +
            "); it is not replaced, --force or not: delete it yourself or export to another folder");
  }
  if (r.imu_streams().empty() && r.camera_streams().empty()) {
    return make_error(Errc::kInsufficientData, log_path + " has no IMU or camera streams to export");
  }
  return {};
}

double export_work(const SessionLogReader& r) {
  double total = 0;
  for (const auto& [id, info] : r.imu_streams()) {
    auto n = r.imu_count(id);
    if (n.ok()) total += static_cast<double>(*n);
  }
  for (const auto& [id, info] : r.camera_streams()) {
    auto n = r.frame_count(id);
    if (n.ok()) total += WorkProgress::kPerImage * static_cast<double>(*n);
  }
  return total;
}

/// imuN/data.csv (SI, as EuRoC wants) and sensor.yaml of one stream.
Status export_imu_stream(const SessionLogReader& r, int id, const ImuStreamInfo& info, const fs::path& folder,
                         const std::string& log_path, ExportSummary& summary, WorkProgress& progress) {
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) return make_error(Errc::kIo, "cannot create " + folder.string() + ": " + ec.message());
  std::ofstream csv(folder / "data.csv", std::ios::binary);
  csv << kImuHeader << "\n";
  const bool raw = info.units == ImuUnits::kRaw;
  std::string line;
  std::int64_t count = 0;
  Status visit = r.for_each_imu(id, kTimeMin, kTimeMax, [&](const ImuSample& s) {
    const Eigen::Vector3d a = raw ? info.accel.to_si(s.accel) : s.accel;
    const Eigen::Vector3d w = raw ? info.gyro.to_si(s.gyro) : s.gyro;
    line = std::to_string(s.t_ns);
    for (double v : {w.x(), w.y(), w.z(), a.x(), a.y(), a.z()}) {
      line += ',';
      line += format_double(v);
    }
    line += '\n';
    csv << line;
    ++count;
    progress.advance(1.0);
    return static_cast<bool>(csv);
  });
  csv.close();
  if (!csv) return make_error(Errc::kIo, "cannot write " + (folder / "data.csv").string());
  if (!visit.ok()) return visit.error().context("reading " + info.name + " from " + log_path);
  const auto& metadata = r.metadata();
  const auto meta = metadata.find(sensor_yaml_key(info.name));
  IMUCAL_TRY(write_text(folder / "sensor.yaml",
                        meta != metadata.end() ? meta->second : imu_sensor_yaml(info, log_path)));
  summary.imu_samples += count;
  if (raw) {
    summary.notes.push_back(info.name +
                            " holds raw counts: exported in SI (rad/s, m/s^2) with the stream's "
                            "nominal conversion si = scale * (raw - offset); temperature is not "
                            "part of the EuRoC format");
  }
  return {};
}

/// camN/data.csv, one PNG per frame named by its time, and sensor.yaml of one stream.
Status export_camera_stream(const SessionLogReader& r, int id, const CameraStreamInfo& info,
                            const fs::path& folder, const std::string& log_path, ExportSummary& summary,
                            WorkProgress& progress) {
  std::error_code ec;
  fs::create_directories(folder / "data", ec);
  if (ec) return make_error(Errc::kIo, "cannot create " + folder.string() + ": " + ec.message());
  std::ofstream csv(folder / "data.csv", std::ios::binary);
  csv << kCameraHeader << "\n";
  std::int64_t count = 0, converted = 0;
  std::optional<Error> failure;
  Status visit = r.for_each_frame(id, kTimeMin, kTimeMax, [&](const CameraFrame& frame) {
    const std::string name = std::to_string(frame.t_ns) + ".png";
    const fs::path path = folder / "data" / name;
    if (fs::exists(path)) {
      failure =
          make_error(Errc::kCorrupt, info.name + ": two frames share the timestamp " +
                                         std::to_string(frame.t_ns) + " ns; EuRoC names images by time");
      return false;
    }
    auto png = frame_png(frame);
    if (!png.ok()) {
      failure = png.error();
      return false;
    }
    if (frame.encoding != "png") ++converted;
    std::ofstream image(path, std::ios::binary);
    image.write(reinterpret_cast<const char*>(png->data()), static_cast<std::streamsize>(png->size()));
    image.close();
    if (!image) {
      failure = make_error(Errc::kIo, "cannot write " + path.string());
      return false;
    }
    csv << frame.t_ns << ',' << name << '\n';
    ++count;
    progress.advance(WorkProgress::kPerImage);
    return true;
  });
  csv.close();
  if (failure) return *failure;
  if (!csv) return make_error(Errc::kIo, "cannot write " + (folder / "data.csv").string());
  if (!visit.ok()) return visit.error().context("reading " + info.name + " from " + log_path);
  const auto& metadata = r.metadata();
  const auto meta = metadata.find(sensor_yaml_key(info.name));
  IMUCAL_TRY(write_text(folder / "sensor.yaml",
                        meta != metadata.end() ? meta->second : camera_sensor_yaml(info, log_path)));
  summary.frames += count;
  if (converted > 0) {
    summary.notes.push_back(info.name + ": " + std::to_string(converted) +
                            " frames were stored in other encodings and were written as lossless PNG");
  }
  return {};
}

}  // namespace

Result<ExportSummary> export_euroc(const std::string& log_path, const std::string& dir,
                                   const OutputOptions& options, bool allow_damaged) {
  auto reader = SessionLogReader::open(log_path);
  if (!reader.ok()) return reader.error();
  const SessionLogReader& r = **reader;
  IMUCAL_TRY(check_export(r, log_path, dir, options, allow_damaged));
  auto out = PendingOutput::begin(dir, PendingOutput::Kind::kDirectory, options.force);
  if (!out.ok()) return out.error();
  const fs::path mav0 = fs::path(out->temp_path()) / "mav0";
  ExportSummary summary;
  if (!r.health().complete) {
    summary.notes.push_back(log_path + " was not closed cleanly; exported what it holds");
  }
  const bool damaged_at_open = r.health().damaged;
  if (damaged_at_open) summary.notes.push_back("log damaged: " + r.health().damage_message);

  WorkProgress progress(export_work(r), options.progress);
  const auto imu_names = folder_names(r.imu_streams(), "imu");
  for (const auto& [id, info] : r.imu_streams()) {
    IMUCAL_TRY(export_imu_stream(r, id, info, mav0 / imu_names.at(id), log_path, summary, progress));
  }
  const auto cam_names = folder_names(r.camera_streams(), "cam");
  for (const auto& [id, info] : r.camera_streams()) {
    IMUCAL_TRY(export_camera_stream(r, id, info, mav0 / cam_names.at(id), log_path, summary, progress));
  }
  IMUCAL_TRY(
      write_text(mav0 / "body.yaml", "comment: 'Body frame: identity with every sensor (unknown here)'\n"));
  IMUCAL_TRY(write_text(fs::path(out->temp_path()) / kExportMarker,
                        "Written by imucal export euroc from " + log_path +
                            ". imucal export --force replaces a folder only when it holds this file.\n"));
  // Damage the open did not see shows while reading (a frame's image failing its CRC is
  // skipped): the export would hold less than the log lists.
  if (r.health().damaged && !damaged_at_open) {
    if (!allow_damaged) {
      return make_error(Errc::kCorrupt, log_path + " is damaged (" + r.health().damage_message +
                                            "); nothing was exported, as the export would miss what is lost")
          .with_remedy("allow_damaged");
    }
    summary.notes.push_back("log damaged: " + r.health().damage_message);
  }
  IMUCAL_TRY(out->commit());
  return summary;
}

}  // namespace imucal::log
