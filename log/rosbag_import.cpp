// SPDX-License-Identifier: BSD-3-Clause
// ROS 1 bags into session logs and back (log/dataset_io.hpp: import_bag, export_bag).

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>

#include "log/dataset_io.hpp"
#include "log/rosbag.hpp"
#include "log/rosbag2.hpp"
#include "log/session_log.hpp"

namespace imucal::log {
namespace fs = std::filesystem;
using rosbag::BagDamage;
using rosbag::Connection;
using rosbag::MessageView;

namespace {

/// A ROS 1 bag or a rosbag2, read alike: their connections, their messages in storage order and
/// the decoders of their serialization (ROS 1's, or CDR).
struct Source {
  std::string format;  // "rosbag" or "rosbag2"
  std::function<Result<std::vector<Connection>>()> connections;
  std::function<Status(const std::function<Status(const MessageView&)>&, BagDamage&,
                       const std::function<void(double)>&)>
      for_each;
  std::function<Result<TimeNs>(std::span<const std::uint8_t>)> stamp;
  std::function<Result<rosbag::ImuMessage>(std::span<const std::uint8_t>)> imu;
  std::function<Result<rosbag::ImageMessage>(std::span<const std::uint8_t>)> image;
  std::function<Result<rosbag::CompressedImageMessage>(std::span<const std::uint8_t>)> compressed;
};

Result<Source> open_source(const std::string& path) {
  Source src;
  if (rosbag2::is_rosbag2(path)) {
    auto reader = rosbag2::Bag2Reader::open(path);
    if (!reader.ok()) return reader.error();
    std::shared_ptr<rosbag2::Bag2Reader> r = std::move(*reader);
    src.format = "rosbag2";
    src.connections = [r] { return r->connections(); };
    src.for_each = [r](const auto& visit, BagDamage& damage, const auto& progress) {
      return r->for_each_message(visit, damage, progress);
    };
    src.stamp = rosbag2::header_stamp_cdr;
    src.imu = rosbag2::decode_imu_cdr;
    src.image = rosbag2::decode_image_cdr;
    src.compressed = rosbag2::decode_compressed_image_cdr;
    return src;
  }
  auto reader = rosbag::BagReader::open(path);
  if (!reader.ok()) return reader.error();
  std::shared_ptr<rosbag::BagReader> r = std::move(*reader);
  src.format = "rosbag";
  src.connections = [r] { return r->connections(); };
  src.for_each = [r](const auto& visit, BagDamage& damage, const auto& progress) {
    return r->for_each_message(visit, damage, progress);
  };
  src.stamp = rosbag::header_stamp;
  src.imu = rosbag::decode_imu;
  src.image = rosbag::decode_image;
  src.compressed = rosbag::decode_compressed_image;
  return src;
}

/// One topic imported: the stream it becomes and what the first reading found.
struct Topic {
  std::string name;    // the bag's topic
  std::string type;    // one of the three types read
  std::string stream;  // imu0, cam0, ...
  std::set<std::uint32_t> connections;
  std::int64_t messages = 0;
  std::vector<TimeNs> stamps;  // the times used, in bag order
  std::vector<TimeNs> receive_minus_header;
  std::vector<ImuSample> samples;  // Imu topics
  std::set<std::int64_t> dropped;  // camera messages left out (their stamp was seen before), by ordinal
  int width = 0, height = 0;       // camera topics: the first frame's
  std::int64_t zero_stamps = 0;
  bool imu() const { return type == rosbag::kImuType; }
};

bool is_camera_type(const std::string& type) {
  return type == rosbag::kImageType || type == rosbag::kCompressedImageType;
}

std::string topic_list(const std::vector<Connection>& connections) {
  std::map<std::string, std::string> topics;
  for (const auto& c : connections) topics.emplace(c.topic, c.type);
  std::string out;
  for (const auto& [topic, type] : topics) out += (out.empty() ? "" : ", ") + topic + " (" + type + ")";
  return out.empty() ? "none" : out;
}

/// The topics to import, in stream order, with their streams named.
Result<std::vector<Topic>> choose_topics(const std::vector<Connection>& connections, const BagImport& in) {
  std::map<std::string, Topic> by_name;
  for (const auto& c : connections) {
    Topic& t = by_name[c.topic];
    t.name = c.topic;
    t.type = c.type;
    t.connections.insert(c.id);
  }
  std::vector<std::string> names = in.topics;
  if (names.empty()) {
    for (const auto& [name, t] : by_name) {
      if (t.imu() || is_camera_type(t.type)) names.push_back(name);
    }
  }
  std::vector<Topic> out;
  int imus = 0, cameras = 0;
  for (const auto& name : names) {
    auto it = by_name.find(name);
    if (it == by_name.end()) {
      return make_error(Errc::kInvalidArgument,
                        in.path + " has no topic " + name + "; its topics: " + topic_list(connections));
    }
    if (std::any_of(out.begin(), out.end(), [&](const Topic& t) { return t.name == name; })) {
      return make_error(Errc::kInvalidArgument, "the topic " + name + " is named twice");
    }
    Topic t = it->second;
    if (t.imu()) {
      t.stream = "imu" + std::to_string(imus++);
    } else if (is_camera_type(t.type)) {
      t.stream = "cam" + std::to_string(cameras++);
    } else {
      return make_error(Errc::kUnsupported, "the topic " + name + " carries " + t.type +
                                                "; imucal reads sensor_msgs/Imu, Image and CompressedImage");
    }
    out.push_back(std::move(t));
  }
  if (out.empty()) {
    return make_error(Errc::kInsufficientData, in.path +
                                                   " has no sensor_msgs/Imu, Image or CompressedImage topic; "
                                                   "its topics: " +
                                                   topic_list(connections));
  }
  return out;
}

Topic* topic_of(std::vector<Topic>& topics, const MessageView& m) {
  for (auto& t : topics) {
    if (t.connections.count(m.connection->id) != 0) return &t;
  }
  return nullptr;
}

/// Where a message is, for an error: its topic, its ordinal and when the bag received it.
std::string where(const Topic& t, const MessageView& m) {
  return t.name + ", message " + std::to_string(t.messages + 1) + " (received at " +
         format_double(ns_to_s(m.receive_ns)) + " s)";
}

/// A camera message as a stored frame: raw pixels encoded as PNG, a PNG as it is (checked), a
/// WebP decoded and stored as PNG.
Result<CameraFrame> bag_frame(const Source& src, const Topic& t, const MessageView& m, TimeNs stamp) {
  CameraFrame frame;
  frame.t_ns = stamp;
  frame.encoding = "png";
  if (t.type == rosbag::kImageType) {
    auto image = src.image(m.data);
    if (!image.ok()) return image.error();
    auto png = encode_png(image->image);
    if (!png.ok()) return png.error();
    frame.width = image->image.width;
    frame.height = image->image.height;
    frame.data = std::move(*png);
    return frame;
  }
  auto compressed = src.compressed(m.data);
  if (!compressed.ok()) return compressed.error();
  const ImageFormat kind = sniff_format(compressed->data);
  if (kind == ImageFormat::kUnknown) {
    const bool jpeg =
        compressed->data.size() > 2 && compressed->data[0] == 0xff && compressed->data[1] == 0xd8;
    return make_error(Errc::kUnsupported,
                      std::string("a compressed image in ") +
                          (jpeg ? "JPEG" : "format '" + compressed->format + "'") +
                          "; imucal reads PNG and WebP ones, and raw sensor_msgs/Image (JPEG loses the "
                          "corners' detail a calibration needs): record the raw image topic");
  }
  auto image = decode_image(compressed->data);
  if (!image.ok()) return make_error(Errc::kCorrupt, "a damaged compressed image: " + image.error().message);
  frame.width = image->width;
  frame.height = image->height;
  if (kind == ImageFormat::kPng) {
    frame.data = std::move(compressed->data);
  } else {
    auto png = encode_png(*image);
    if (!png.ok()) return png.error();
    frame.data = std::move(*png);
  }
  return frame;
}

/// The first reading: every Imu message decoded and kept, every image's stamp, the first
/// image's size.
Status scan(const Source& src, std::vector<Topic>& topics, const BagImport& in, BagDamage& damage,
            const ProgressFn& progress) {
  std::map<std::string, std::set<TimeNs>> seen;
  return src.for_each(
      [&](const MessageView& m) -> Status {
        Topic* t = topic_of(topics, m);
        if (t == nullptr) return {};
        auto header = src.stamp(m.data);
        if (!header.ok()) return header.error().context(where(*t, m));
        const TimeNs stamp = in.receive_time ? m.receive_ns : *header;
        if (*header == 0) ++t->zero_stamps;
        t->receive_minus_header.push_back(m.receive_ns - *header);
        if (t->imu()) {
          auto imu = src.imu(m.data);
          if (!imu.ok()) return imu.error().context(where(*t, m));
          ImuSample sample;
          sample.t_ns = stamp;
          sample.accel = imu->accel;
          sample.gyro = imu->gyro;
          t->samples.push_back(sample);
        } else if (!seen[t->name].insert(stamp).second) {
          t->dropped.insert(t->messages);
        } else if (t->width == 0) {
          auto frame = bag_frame(src, *t, m, stamp);
          if (!frame.ok()) return frame.error().context(where(*t, m));
          t->width = frame->width;
          t->height = frame->height;
        }
        t->stamps.push_back(stamp);
        ++t->messages;
        return {};
      },
      damage, [&](double f) { report_progress(progress, 0.3 * f, 1.0); });
}

TimeNs median(std::vector<TimeNs> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TimeNs median_interval(std::vector<TimeNs> t) {
  std::sort(t.begin(), t.end());
  std::vector<TimeNs> d;
  for (std::size_t i = 1; i < t.size(); ++i) {
    if (t[i] > t[i - 1]) d.push_back(t[i] - t[i - 1]);
  }
  return median(std::move(d));
}

/// A duration for a note: in ms below a second, in s below a day, else in days.
std::string duration_text(TimeNs ns) {
  const double s = std::abs(static_cast<double>(ns)) * 1e-9;
  if (s < 1.0) return format_double(std::round(s * 1e5) / 100.0) + " ms";
  if (s < 86400.0) return format_double(std::round(s * 1e3) / 1e3) + " s";
  return format_double(std::round(s / 8640.0) / 10.0) + " days";
}

/// Checks what the first reading found and puts the IMU samples in time order; notes what a
/// user should know.
Status check_topics(std::vector<Topic>& topics, const BagImport& in, ImportSummary& summary) {
  TimeNs frame_period = 0;
  for (const auto& t : topics) {
    if (t.imu()) continue;
    const TimeNs p = median_interval(t.stamps);
    if (p > 0 && (frame_period == 0 || p < frame_period)) frame_period = p;
  }
  for (auto& t : topics) {
    if (t.messages == 0) {
      return make_error(Errc::kInsufficientData, in.path + ": the topic " + t.name + " has no message");
    }
    if (!in.receive_time && t.zero_stamps == t.messages) {
      return make_error(Errc::kInsufficientData,
                        in.path + ": the messages of " + t.name +
                            " carry no header stamp (all 0); the bag's receive times "
                            "can stamp them instead")
          .with_remedy("receive_time");
    }
    summary.notes.push_back(t.stream + ": " + t.name + " (" + t.type + ", " + std::to_string(t.messages) +
                            " messages)");
    const TimeNs lag = median(t.receive_minus_header);
    const TimeNs limit = frame_period > 0 ? frame_period : median_interval(t.stamps);
    if (limit > 0 && std::llabs(lag) > limit) {
      summary.notes.push_back(
          t.name + ": the bag received its messages " + duration_text(lag) + " (median) " +
          (lag > 0 ? "after" : "before") + " their header stamps, more than " +
          (frame_period > 0 ? "a frame (" : "a sample (") + duration_text(limit) + "): the stamps used are " +
          (in.receive_time ? "the receive times, which carry that delay" : "the headers'"));
    }
    if (t.imu()) {
      const bool sorted =
          std::is_sorted(t.samples.begin(), t.samples.end(),
                         [](const ImuSample& a, const ImuSample& b) { return a.t_ns < b.t_ns; });
      std::stable_sort(t.samples.begin(), t.samples.end(),
                       [](const ImuSample& a, const ImuSample& b) { return a.t_ns < b.t_ns; });
      const auto last = std::unique(t.samples.begin(), t.samples.end(),
                                    [](const ImuSample& a, const ImuSample& b) { return a.t_ns == b.t_ns; });
      const auto repeated = std::distance(last, t.samples.end());
      t.samples.erase(last, t.samples.end());
      if (!sorted) summary.notes.push_back(t.name + ": messages out of time order were put in order");
      if (repeated > 0) {
        summary.notes.push_back(t.name + ": " + std::to_string(repeated) +
                                " messages repeat an earlier stamp and were left out");
      }
    } else if (!t.dropped.empty()) {
      summary.notes.push_back(t.name + ": " + std::to_string(t.dropped.size()) +
                              " frames repeat an earlier stamp and were left out");
    }
  }
  return {};
}

Status write_imu_topic(SessionLogWriter& w, const Topic& t, ImportSummary& summary) {
  ImuStreamInfo info;
  info.name = t.stream;
  info.units = ImuUnits::kSi;
  const TimeNs period = median_interval(t.stamps);
  info.rate_hz = period > 0 ? 1e9 / static_cast<double>(period) : 0.0;
  info.device = "rosbag:" + t.name;
  auto id = w.add_imu_stream(info);
  if (!id.ok()) return id.error();
  ImuBatchWriter batches(w, *id);
  for (const auto& s : t.samples) IMUCAL_TRY(batches.add(s));
  IMUCAL_TRY(batches.flush());
  summary.imu_samples += batches.count();
  if (summary.imu_streams++ == 0) {
    summary.rate_hz = info.rate_hz;
    summary.t_first_ns = batches.first_ns();
    summary.t_last_ns = batches.last_ns();
  }
  return {};
}

/// The second reading: every frame of the camera topics into its stream.
Status write_frames(const Source& src, std::vector<Topic>& topics, SessionLogWriter& w,
                    const std::map<std::string, int>& stream_ids, ImportSummary& summary,
                    const ProgressFn& progress) {
  std::map<std::string, std::int64_t> ordinal;
  std::map<std::string, std::uint32_t> sequence;
  BagDamage damage;
  IMUCAL_TRY(src.for_each(
      [&](const MessageView& m) -> Status {
        Topic* t = topic_of(topics, m);
        if (t == nullptr || t->imu()) return {};
        const std::int64_t n = ordinal[t->name]++;
        if (n >= t->messages) return {};  // past what the first reading found (a bag growing)
        if (t->dropped.count(n) != 0) return {};
        auto frame = bag_frame(src, *t, m, t->stamps[static_cast<std::size_t>(n)]);
        if (!frame.ok()) {
          return frame.error().context(t->name + ", message " + std::to_string(n + 1) + " (received at " +
                                       format_double(ns_to_s(m.receive_ns)) + " s)");
        }
        frame->sequence = sequence[t->name]++;
        IMUCAL_TRY(w.append_frame(stream_ids.at(t->name), *frame));
        ++summary.frames;
        return {};
      },
      damage, [&](double f) { report_progress(progress, 0.3 + 0.7 * f, 1.0); }));
  return {};
}

Status declare_cameras(SessionLogWriter& w, const std::vector<Topic>& topics, std::map<std::string, int>& ids,
                       ImportSummary& summary) {
  for (const auto& t : topics) {
    if (t.imu()) continue;
    CameraStreamInfo info;
    info.name = t.stream;
    info.backend = "rosbag";
    info.device = "rosbag:" + t.name;
    info.timestamp_source = "dataset";
    info.width = t.width;
    info.height = t.height;
    const TimeNs period = median_interval(t.stamps);
    info.rate_hz = period > 0 ? 1e9 / static_cast<double>(period) : 0.0;
    auto id = w.add_camera_stream(info);
    if (!id.ok()) return id.error();
    ids[t.name] = *id;
    ++summary.camera_streams;
  }
  return {};
}

std::string damage_text(const BagDamage& d) {
  return d.message + " (byte " + std::to_string(d.offset) + " of " + std::to_string(d.size) + ", after " +
         std::to_string(d.chunks_read) + " whole chunks)";
}

Result<ImportSummary> import_bag_as_read(const BagImport& in, const std::string& out_path,
                                         const OutputOptions& options) {
  auto out = PendingOutput::begin(out_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  auto src = open_source(in.path);
  if (!src.ok()) return src.error();
  auto connections = src->connections();
  if (!connections.ok()) return connections.error().context(in.path);
  auto topics = choose_topics(*connections, in);
  if (!topics.ok()) return topics.error();
  BagDamage damage;
  IMUCAL_TRY(scan(*src, *topics, in, damage, options.progress));
  ImportSummary summary;
  if (damage.damaged) {
    if (!in.allow_damaged) {
      return make_error(Errc::kCorrupt, in.path + " is damaged: " + damage_text(damage) +
                                            "; nothing was imported; the whole chunks before it can be")
          .with_remedy("allow_damaged");
    }
    summary.notes.push_back(in.path + " is damaged: " + damage_text(damage) +
                            "; imported what comes before it");
  }
  IMUCAL_TRY(check_topics(*topics, in, summary));
  {
    SessionLogWriterOptions staged;
    staged.staged = true;
    staged.commit_data_interval_ns = 0;
    auto writer = SessionLogWriter::create(out->temp_path(), staged);
    if (!writer.ok()) return writer.error().context("cannot create the session log");
    SessionLogWriter& w = **writer;
    nlohmann::json source = {{"format", src->format},
                             {"path", fs::absolute(in.path).string()},
                             {"stamps", in.receive_time ? "receive" : "header"}};
    for (const auto& t : *topics) source["topics"][t.stream] = t.name;
    if (damage.damaged) source["damage"] = damage_text(damage);
    IMUCAL_TRY(
        w.set_metadata("import", source.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
    for (const auto& t : *topics) {
      if (t.imu()) IMUCAL_TRY(write_imu_topic(w, t, summary));
    }
    std::map<std::string, int> ids;
    IMUCAL_TRY(declare_cameras(w, *topics, ids, summary));
    if (!ids.empty()) IMUCAL_TRY(write_frames(*src, *topics, w, ids, summary, options.progress));
    IMUCAL_TRY(w.close());
  }
  if (summary.imu_streams == 0) {
    summary.notes.push_back("no sensor_msgs/Imu topic was imported (the bag's topics: " +
                            topic_list(*connections) + "): the log holds cameras only");
  }
  IMUCAL_TRY(out->commit());
  report_progress(options.progress, 1.0, 1.0);
  return summary;
}

}  // namespace

Result<ImportSummary> import_bag(const BagImport& in, const std::string& out_path,
                                 const OutputOptions& options) {
  auto summary = import_bag_as_read(in, out_path, options);
  // A bag in a form imucal does not read is an input it cannot use, as a malformed one is.
  if (!summary.ok() && summary.error().code == Errc::kUnsupported) {
    Error e = summary.error();
    e.code = Errc::kCorrupt;
    return e;
  }
  return summary;
}

// ---------------------------------------------------------------------------------------------

namespace {

rosbag::ChunkCompression chunk_compression(BagCompression c) {
  switch (c) {
    case BagCompression::kBz2:
      return rosbag::ChunkCompression::kBz2;
    case BagCompression::kLz4:
      return rosbag::ChunkCompression::kLz4;
    case BagCompression::kNone:
      break;
  }
  return rosbag::ChunkCompression::kNone;
}

// One message of the bag being written, held until its window is written in time order.
struct OutMessage {
  TimeNs t_ns = 0;
  std::uint32_t connection = 0;
  std::vector<std::uint8_t> data;
};

// What export writes of one stream: its connection, the next sequence number, and for a camera
// its frames' times (to find the next frame past a gap without reading images).
struct ExportStream {
  int id = 0;
  bool camera = false;
  std::string name;
  const ImuStreamInfo* imu = nullptr;  // an IMU stream's
  std::uint32_t connection = 0;
  std::uint32_t seq = 0;
  std::vector<TimeNs> frame_times;
};

// Messages are written in windows of this much time, each sorted by time across streams, as
// rosbag record interleaves them; it bounds the images held at once.
constexpr TimeNs kExportWindowNs = 250'000'000;

// The first message time of a stream at or after t_ns, if any.
Result<std::optional<TimeNs>> next_time(const SessionLogReader& r, const ExportStream& s, TimeNs t_ns) {
  if (s.camera) {
    const auto it = std::lower_bound(s.frame_times.begin(), s.frame_times.end(), t_ns);
    if (it == s.frame_times.end()) return std::optional<TimeNs>{};
    return std::optional<TimeNs>{*it};
  }
  std::optional<TimeNs> first;
  IMUCAL_TRY(r.for_each_imu(s.id, t_ns, kTimeMax, [&](const ImuSample& sample) {
    first = sample.t_ns;
    return false;
  }));
  return first;
}

Status collect_imu(const SessionLogReader& r, ExportStream& s, TimeNs t0, TimeNs t1,
                   std::vector<OutMessage>& out) {
  return r.for_each_imu(s.id, t0, t1, [&](const ImuSample& sample) {
    rosbag::ImuMessage m;
    m.stamp_ns = sample.t_ns;
    m.frame_id = s.name;
    const bool raw = s.imu->units == ImuUnits::kRaw;
    m.accel = raw ? s.imu->accel.to_si(sample.accel) : sample.accel;
    m.gyro = raw ? s.imu->gyro.to_si(sample.gyro) : sample.gyro;
    out.push_back({sample.t_ns, s.connection, rosbag::encode_imu(m, s.seq++)});
    return true;
  });
}

Status collect_frames(const SessionLogReader& r, ExportStream& s, TimeNs t0, TimeNs t1,
                      std::vector<OutMessage>& out) {
  std::optional<Error> failure;
  IMUCAL_TRY(r.for_each_frame(s.id, t0, t1, [&](const CameraFrame& frame) {
    auto image = frame_image(frame);
    if (!image.ok()) {
      failure = image.error().context(s.name);
      return false;
    }
    rosbag::ImageMessage m;
    m.stamp_ns = frame.t_ns;
    m.frame_id = s.name;
    m.image = std::move(*image);
    out.push_back({frame.t_ns, s.connection, rosbag::encode_image(m, s.seq++)});
    return true;
  }));
  if (failure) return *failure;
  return {};
}

Result<std::vector<ExportStream>> export_streams(const SessionLogReader& r, rosbag::BagWriter& bag,
                                                 ExportSummary& summary) {
  std::vector<ExportStream> streams;
  for (const auto& [id, info] : r.imu_streams()) {
    auto conn = bag.add_connection("/" + info.name, rosbag::kImuType);
    if (!conn.ok()) return conn.error();
    ExportStream s;
    s.id = id;
    s.name = info.name;
    s.imu = &info;
    s.connection = *conn;
    streams.push_back(std::move(s));
    if (info.units == ImuUnits::kRaw) {
      summary.notes.push_back(info.name +
                              " holds raw counts: exported in SI (rad/s, m/s^2) with the stream's nominal "
                              "conversion si = scale * (raw - offset)");
    }
  }
  for (const auto& [id, info] : r.camera_streams()) {
    auto conn = bag.add_connection("/" + info.name + "/image_raw", rosbag::kImageType);
    if (!conn.ok()) return conn.error();
    auto times = r.frame_times(id);
    if (!times.ok()) return times.error();
    ExportStream s;
    s.id = id;
    s.camera = true;
    s.name = info.name;
    s.frame_times = std::move(*times);
    std::sort(s.frame_times.begin(), s.frame_times.end());
    s.connection = *conn;
    streams.push_back(std::move(s));
  }
  return streams;
}

// Every stream's messages, window by window in time order; a gap with no message is skipped.
Status export_messages(const SessionLogReader& r, rosbag::BagWriter& bag, ExportSummary& summary,
                       const ProgressFn& progress) {
  auto streams = export_streams(r, bag, summary);
  if (!streams.ok()) return streams.error();
  std::int64_t total = 0;
  for (const auto& s : *streams) {
    auto n = s.camera ? r.frame_count(s.id) : r.imu_count(s.id);
    if (!n.ok()) return n.error();
    total += *n;
  }
  std::int64_t written = 0;
  TimeNs t0 = kTimeMin;
  std::vector<OutMessage> window;
  while (true) {
    std::optional<TimeNs> start;
    for (const auto& s : *streams) {
      auto t = next_time(r, s, t0);
      if (!t.ok()) return t.error();
      if (*t && (!start || **t < *start)) start = *t;
    }
    if (!start) break;
    const TimeNs t1 = *start > kTimeMax - kExportWindowNs ? kTimeMax : *start + kExportWindowNs;
    window.clear();
    for (auto& s : *streams) {
      IMUCAL_TRY(s.camera ? collect_frames(r, s, *start, t1, window) : collect_imu(r, s, *start, t1, window));
    }
    std::stable_sort(window.begin(), window.end(),
                     [](const OutMessage& a, const OutMessage& b) { return a.t_ns < b.t_ns; });
    for (const auto& m : window) IMUCAL_TRY(bag.write(m.connection, m.t_ns, m.data));
    written += static_cast<std::int64_t>(window.size());
    report_progress(progress, static_cast<double>(written),
                    static_cast<double>(std::max<std::int64_t>(total, 1)));
    if (t1 == kTimeMax) break;
    t0 = t1;
  }
  for (const auto& s : *streams) (s.camera ? summary.frames : summary.imu_samples) += s.seq;
  return {};
}

}  // namespace

Result<ExportSummary> export_bag(const std::string& log_path, const std::string& bag_path,
                                 const OutputOptions& options, bool allow_damaged,
                                 BagCompression compression) {
  auto reader = SessionLogReader::open(log_path);
  if (!reader.ok()) return reader.error();
  const SessionLogReader& r = **reader;
  if (r.health().damaged && !allow_damaged) {
    return make_error(Errc::kCorrupt, log_path + " is damaged (" + r.health().damage_message +
                                          "); only what is readable can be exported")
        .with_remedy("allow_damaged");
  }
  if (r.imu_streams().empty() && r.camera_streams().empty()) {
    return make_error(Errc::kInsufficientData, log_path + " has no IMU or camera streams to export");
  }
  auto out = PendingOutput::begin(bag_path, PendingOutput::Kind::kFile, options.force);
  if (!out.ok()) return out.error();
  ExportSummary summary;
  {
    auto bag = rosbag::BagWriter::create(out->temp_path(), chunk_compression(compression));
    if (!bag.ok()) return bag.error();
    IMUCAL_TRY(export_messages(r, **bag, summary, options.progress));
    IMUCAL_TRY((*bag)->close());
  }
  if (r.health().damaged) summary.notes.push_back("log damaged: " + r.health().damage_message);
  IMUCAL_TRY(out->commit());
  return summary;
}

}  // namespace imucal::log
