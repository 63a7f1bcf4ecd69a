// SPDX-License-Identifier: BSD-3-Clause
// Camera calibration of a log's camera stream (app/camera_calibration.hpp): detection over the
// frames on worker threads, stored detections, the intrinsics solve. Compiled into the camera
// module libimucal_camera.so.

#include "app/camera_calibration.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <span>
#include <thread>
#include <utility>

#include "app/camera_self_check.hpp"
#include "app/camimu_inputs.hpp"
#include "app/results/camera_results.hpp"
#include "calib/observation_check.hpp"
#include "core/option_words.hpp"
#include "core/text_format.hpp"
#include "core/threads.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "log/target_detections.hpp"

namespace imucal::app {
namespace {

/// Consecutive frames of a stream with their indices: a worker searches them in order, so that
/// each frame's search can track the board from the frames before it.
using FrameBatch = std::vector<std::pair<std::size_t, CameraFrame>>;

/// Frames per batch: the first frame of a batch is searched without a history, the others are
/// tracked while the board stays in view. Fixed, so that what is found does not depend on the
/// number of workers.
constexpr std::size_t kFramesPerBatch = 16;

/// A queue of batches with a fixed capacity: the reader waits while the workers are behind, so
/// memory stays bounded whatever the length of the log.
class BatchQueue {
 public:
  explicit BatchQueue(std::size_t capacity) : capacity_(capacity) {}

  void push(FrameBatch batch) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return items_.size() < capacity_; });
    items_.push_back(std::move(batch));
    not_empty_.notify_one();
  }

  /// The next batch, or nullopt once the queue is closed and empty.
  std::optional<FrameBatch> pop() {
    std::unique_lock lock(mutex_);
    not_empty_.wait(lock, [&] { return !items_.empty() || closed_; });
    if (items_.empty()) return std::nullopt;
    FrameBatch batch = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_one();
    return batch;
  }

  void close() {
    const std::lock_guard lock(mutex_);
    closed_ = true;
    not_empty_.notify_all();
  }

 private:
  std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_full_, not_empty_;
  std::deque<FrameBatch> items_;
  bool closed_ = false;
};

/// One frame as 8-bit grey.
Result<log::Image> gray_of(const CameraFrame& frame) {
  if (frame.encoding == "gray8") {
    if (frame.width <= 0 || frame.height <= 0 ||
        frame.data.size() != static_cast<std::size_t>(frame.width) * static_cast<std::size_t>(frame.height)) {
      return make_error(Errc::kCorrupt, "a gray8 frame's data does not match its size");
    }
    log::Image image;
    image.width = frame.width;
    image.height = frame.height;
    image.data = frame.data;
    return image;
  }
  if (frame.encoding == "png" || frame.encoding == "webp")
    return log::decode_image(frame.data, log::ReadMode::kGray8);
  return make_error(Errc::kUnsupported, "frames encoded as '" + frame.encoding + "' cannot be decoded here");
}

/// Stops a search whose target file does not match the board in the frames. Of the first
/// kEarlyFrames frames, while none shows the target, every other one without it is shown to
/// TargetDetector::describe_other_target (at most kProbes); when kAgreeing of them, and more than
/// half of those asked, describe the same other target, the search stops and says so. A board the
/// description matches, or one found by the search, ends the check.
class WrongTargetCheck {
 public:
  static constexpr std::size_t kEarlyFrames = 40;
  static constexpr int kProbes = 8;
  static constexpr int kAgreeing = 4;

  /// Called after a frame's search: whether to describe it.
  bool wants_description(std::size_t index, bool found) {
    const std::lock_guard lock(mutex_);
    if (found && index < kEarlyFrames) done_ = true;
    if (done_ || found || index >= kEarlyFrames || index % 2 != 0 || asked_ >= kProbes) return false;
    ++asked_;
    return true;
  }

  /// What a described frame shows (empty: nothing, or the target itself); true when the
  /// search should stop.
  bool add_description(const std::string& what) {
    const std::lock_guard lock(mutex_);
    if (done_) return false;
    ++answered_;
    if (what.empty()) return false;
    const int agreeing = ++seen_[what];
    if (agreeing >= kAgreeing && 2 * agreeing > answered_) {
      verdict_ = what;
      done_ = true;
      return true;
    }
    return false;
  }

  std::optional<std::pair<std::string, int>> verdict() const {
    const std::lock_guard lock(mutex_);
    if (verdict_.empty()) return std::nullopt;
    return std::make_pair(verdict_, answered_);
  }

 private:
  mutable std::mutex mutex_;
  bool done_ = false;
  int asked_ = 0;
  int answered_ = 0;
  std::map<std::string, int> seen_;
  std::string verdict_;
};

std::string target_in_words(const TargetDescription& t) {
  if (t.type == TargetDescription::Type::kCheckerboard) {
    return "a checkerboard of " + std::to_string(std::max(t.cols, t.rows)) + " x " +
           std::to_string(std::min(t.cols, t.rows)) + " inner corners";
  }
  return "an AprilGrid of " + std::to_string(t.tag_cols) + " x " + std::to_string(t.tag_rows) +
         " tags (ids 0 to " + std::to_string(t.tag_cols * t.tag_rows - 1) + ")";
}

struct Detected {
  std::vector<calib::TargetObservation> observations;  // one per frame, in time order
  std::int64_t unreadable = 0;  // frames the reader skipped (data failing its checksum)
  TimeNs first_unreadable_t_ns = 0;
  int failed = 0;
  std::string first_failure;
};

/// Searches every frame of the stream on `threads` workers; frames are decoded in the workers.
/// Without `allow_damaged` the search stops at the first frame the reader skips.
Result<Detected> detect_frames(const log::SessionLogReader& reader, int stream_id,
                               const calib::TargetDetector& detector, int threads, bool allow_damaged,
                               const ProgressFn& progress) {
  auto times = reader.frame_times(stream_id);
  if (!times.ok()) return times.error();
  const std::size_t total = times->size();
  Detected out;
  out.observations.resize(total);
  std::mutex failure_mutex;
  std::atomic<std::size_t> done{0};
  BatchQueue queue(static_cast<std::size_t>(threads));
  WrongTargetCheck wrong_target;
  std::atomic<bool> stop{false};
  auto search = [&](std::size_t index, const CameraFrame& frame, calib::DetectionHistory history) {
    Result<calib::TargetObservation> found = make_error(Errc::kInternal, "");
    auto gray = gray_of(frame);
    if (gray.ok()) {
      const calib::GrayView view{gray->data.data(), gray->width, gray->height, 0};
      history.t_ns = frame.t_ns;
      found = detector.detect(view, history);
      if (found.ok() && wrong_target.wants_description(index, !found->empty()) &&
          wrong_target.add_description(detector.describe_other_target(view))) {
        stop = true;
      }
    } else {
      found = gray.error();
    }
    if (found.ok()) {
      found->t_ns = frame.t_ns;
      out.observations[index] = std::move(*found);
      return true;
    }
    const std::lock_guard lock(failure_mutex);
    if (out.failed++ == 0)
      out.first_failure = "t_ns " + std::to_string(frame.t_ns) + ": " + found.error().message;
    return false;
  };
  auto work = [&] {
    while (auto batch = queue.pop()) {
      // The history: the detections of the one or two frames just before, in this batch.
      const calib::TargetObservation* last = nullptr;
      const calib::TargetObservation* before_last = nullptr;
      std::size_t last_index = 0;
      for (auto& [index, frame] : *batch) {
        if (last != nullptr && index != last_index + 1) last = before_last = nullptr;
        const bool ok = search(index, frame, {0, last, before_last});
        const calib::TargetObservation* now =
            ok && !out.observations[index].empty() ? &out.observations[index] : nullptr;
        before_last = now != nullptr ? last : nullptr;
        last = now;
        last_index = index;
        done.fetch_add(1);
      }
    }
  };
  std::vector<std::thread> workers;
  for (int i = 0; i < threads; ++i) workers.emplace_back(work);
  std::size_t next = 0;
  bool ended_early = false;
  FrameBatch batch;
  auto status = reader.for_each_frame(stream_id, log::kTimeMin, log::kTimeMax, [&](const CameraFrame& frame) {
    // Frames whose data failed its check are skipped by the reader: their slots stay empty.
    while (next < total && (*times)[next] < frame.t_ns) {
      if (out.unreadable++ == 0) out.first_unreadable_t_ns = (*times)[next];
      ++next;
    }
    if (next >= total || stop || (out.unreadable > 0 && !allow_damaged)) {
      ended_early = true;
      return false;
    }
    // Batches start at fixed indices (multiples of kFramesPerBatch).
    if (!batch.empty() && next / kFramesPerBatch != batch.front().first / kFramesPerBatch) {
      queue.push(std::move(batch));
      batch.clear();
    }
    batch.emplace_back(next++, frame);
    report_progress(progress, static_cast<double>(done.load()), static_cast<double>(total));
    return true;
  });
  if (!batch.empty() && !ended_early) queue.push(std::move(batch));
  queue.close();
  for (auto& w : workers) w.join();
  if (!status.ok()) return status.error();
  if (auto verdict = wrong_target.verdict()) {
    return make_error(Errc::kInvalidArgument, "the target was not found in the first frames, which show " +
                                                  verdict->first + " (" + std::to_string(verdict->second) +
                                                  " frames looked at); the target file says " +
                                                  target_in_words(detector.target()) +
                                                  ": give the target file of the board that was recorded")
        .with_remedy("target");
  }
  // Frames skipped after the last one read (the loop above sees only those before a frame).
  if (!ended_early && next < total) {
    if (out.unreadable == 0) out.first_unreadable_t_ns = (*times)[next];
    out.unreadable += static_cast<std::int64_t>(total - next);
  }
  if (!ended_early) report_progress(progress, 1.0, 1.0);
  return out;
}

/// The observations of a stored set, when it is one for this many frames and every id is one of
/// the target's `target_points` points (a file may hold anything).
std::optional<std::vector<calib::TargetObservation>> decode_set(
    const Result<std::optional<log::DetectionSet>>& set, std::int64_t frames, int target_points,
    std::vector<std::string>* warnings) {
  if (!set.ok()) {
    warnings->push_back("stored detections not used: " + set.error().message);
    return std::nullopt;
  }
  if (!*set || (*set)->frames != frames) return std::nullopt;
  std::vector<calib::TargetObservation> obs;
  for (const auto& d : (*set)->detections) {
    auto o = decode_detection(d.data, d.t_ns);
    const Status usable = o.ok() ? calib::check_observation(*o, target_points) : Status(o.error());
    if (!usable.ok()) {
      warnings->push_back("stored detections not used (the frames are searched again): " +
                          usable.error().message);
      return std::nullopt;
    }
    obs.push_back(std::move(*o));
  }
  return obs;
}

log::DetectionSet make_set(const StreamDetectionRequest& q, const std::string& key, std::int64_t frames,
                           const std::vector<calib::TargetObservation>& obs) {
  log::DetectionSet set;
  set.target_key = key;
  set.description = target_to_yaml(q.target);
  set.frames = frames;
  for (const auto& o : obs) {
    if (!o.empty()) set.detections.push_back({o.t_ns, encode_detection(o)});
  }
  return set;
}

/// Stores the detections in the log when it is safe to write there; a warning says why not.
bool store_in_log(const StreamDetectionRequest& q, const log::SessionLogReader& reader, int stream_id,
                  const log::DetectionSet& set, std::vector<std::string>* warnings) {
  if (reader.health().damaged) {
    warnings->push_back("detections not stored in the log: it is damaged, and writing could lose more of it");
    return false;
  }
  if (!reader.health().complete) {
    warnings->push_back(
        "detections not stored in the log: it is not marked complete (still being recorded, or "
        "its writer stopped without closing it)");
    return false;
  }
  if (auto s = log::write_target_detections(q.log_path, stream_id, set); !s.ok()) {
    warnings->push_back("detections not stored in the log (the next run searches the frames again): " +
                        s.error().message);
    return false;
  }
  return true;
}

/// The cache file of a stream's content: the folder, then the fingerprint in hex.
std::string cache_path(const std::string& dir, std::uint64_t fingerprint) {
  char name[40];
  std::snprintf(name, sizeof name, "%016llx.sqlite", static_cast<unsigned long long>(fingerprint));
  return dir + "/" + name;
}

/// Opens the log, picks the stream (q.camera) and applies the damage policy.
Result<std::unique_ptr<log::SessionLogReader>> open_log(const CameraCalibrationRequest& q,
                                                        CameraCalibrationReport* report) {
  auto reader = log::SessionLogReader::open(q.log_path);
  if (!reader.ok()) return reader.error();
  const auto& health = (*reader)->health();
  if (health.damaged) {
    if (!q.allow_damaged) {
      return make_error(Errc::kCorrupt, q.shown_log() + " is damaged (" + health.damage_message +
                                            "); only its readable part can be used")
          .with_remedy("allow_damaged");
    }
    report->warnings.push_back(q.shown_log() + " is damaged (" + health.damage_message +
                               "): calibrated from its readable part only");
  }
  auto id = (*reader)->find_camera_stream(q.camera);
  if (!id.ok()) return id.error().with_remedy("camera");
  report->stream_id = *id;
  report->stream = (*reader)->camera_streams().at(*id);
  const auto& meta = (*reader)->metadata();
  if (auto it = meta.find("software_version"); it != meta.end()) report->software_version = it->second;
  return std::move(*reader);
}

}  // namespace

Result<StreamDetections> detect_target_in_stream(const log::SessionLogReader& reader, int stream_id,
                                                 const StreamDetectionRequest& q) {
  const auto& stream = reader.camera_streams().at(stream_id);
  StreamDetections out;
  auto count = reader.frame_count(stream_id);
  if (!count.ok()) return count.error();
  out.frames = *count;
  if (out.frames == 0) {
    return make_error(Errc::kInsufficientData,
                      "camera stream '" + stream.name + "' of " + q.log_path + " holds no frames");
  }
  out.key = detection_key(q.target, q.detection);
  // The cache is keyed by the stream's content; a damaged log's readable part is not cached.
  std::string cache;
  if (!q.cache_dir.empty() && !reader.health().damaged) {
    auto fingerprint = reader.frame_fingerprint(stream_id);
    if (fingerprint.ok()) {
      cache = cache_path(q.cache_dir, *fingerprint);
    } else {
      out.warnings.push_back("detection cache not used: " + fingerprint.error().message);
    }
  }
  std::optional<std::vector<calib::TargetObservation>> obs;
  if (q.reuse_detections) {
    const int points = q.target.point_count();
    obs = decode_set(log::read_target_detections(q.log_path, stream_id, out.key), out.frames, points,
                     &out.warnings);
    if (obs) out.reused_from = "the log";
    if (!obs && !cache.empty()) {
      obs = decode_set(log::read_detection_cache(cache, out.key), out.frames, points, &out.warnings);
      if (obs) out.reused_from = cache;
    }
  }
  if (!obs) {
    auto detector = calib::TargetDetector::create(q.target, q.detection);
    if (!detector.ok()) return detector.error();
    out.threads = threads_or_cores(q.threads);
    const auto start = std::chrono::steady_clock::now();
    auto found = detect_frames(reader, stream_id, **detector, out.threads, q.allow_damaged, q.progress);
    if (!found.ok()) return found.error();
    out.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    out.frames_failed = found->failed;
    if (found->unreadable > 0) {
      if (!q.allow_damaged) {
        return make_error(Errc::kCorrupt, "camera stream '" + stream.name + "' of " + q.log_path +
                                              " has damaged frames (the data of the frame at t_ns " +
                                              std::to_string(found->first_unreadable_t_ns) +
                                              " fails its checksum); only the readable frames can be used")
            .with_remedy("allow_damaged");
      }
      out.warnings.push_back(std::to_string(found->unreadable) + " of the " + std::to_string(out.frames) +
                             " frames of camera stream '" + stream.name + "' in " + q.log_path +
                             " are damaged (their data fails its checksum): calibrated from the readable "
                             "frames only");
      out.frames_failed += static_cast<int>(found->unreadable);
    }
    if (found->failed > 0) {
      out.warnings.push_back(std::to_string(found->failed) + " frames of camera stream '" + stream.name +
                             "' could not be searched (first: " + found->first_failure + ")");
    }
    obs = std::move(found->observations);
    const log::DetectionSet set = make_set(q, out.key, out.frames, *obs);
    if (q.store_detections) {
      if (store_in_log(q, reader, stream_id, set, &out.warnings)) out.stored_in = "the log";
    } else if (!cache.empty() && found->unreadable == 0) {
      if (auto s = log::write_detection_cache(cache, set); s.ok()) {
        out.stored_in = cache;
      } else {
        out.warnings.push_back("detections not cached (the next run searches the frames again): " +
                               s.error().message);
      }
    }
  }
  out.frames_with_target =
      static_cast<int>(std::count_if(obs->begin(), obs->end(), [](const auto& o) { return !o.empty(); }));
  out.observations = std::move(*obs);
  return out;
}

namespace {

/// The detection of one stream into `report` (its stream chosen by open_log): the figures, the
/// warnings and the observations.
Result<std::vector<calib::TargetObservation>> detect_for_report(const CameraCalibrationRequest& q,
                                                                const log::SessionLogReader& reader,
                                                                CameraCalibrationReport* report) {
  StreamDetectionRequest dq;
  dq.log_path = q.log_path;
  dq.target = q.target;
  dq.detection = q.detection;
  dq.threads = q.threads;
  dq.reuse_detections = q.reuse_detections;
  dq.store_detections = q.store_detections;
  dq.cache_dir = q.cache_dir;
  dq.allow_damaged = q.allow_damaged;
  dq.progress = q.detection_progress;
  auto found = detect_target_in_stream(reader, report->stream_id, dq);
  if (!found.ok()) return found.error();
  report->frames = found->frames;
  report->frames_with_target = found->frames_with_target;
  report->frames_failed = found->frames_failed;
  report->detection_key = found->key;
  report->detections_reused_from = found->reused_from;
  report->detections_stored_in = found->stored_in;
  report->detection_wall_s = found->wall_s;
  report->detection_threads = found->threads;
  report->warnings.insert(report->warnings.end(), found->warnings.begin(), found->warnings.end());
  return std::move(found->observations);
}

/// A report for the log and target of `q`, with its stream opened (q.camera).
Result<std::unique_ptr<log::SessionLogReader>> start_report(const CameraCalibrationRequest& q,
                                                            CameraCalibrationReport* report) {
  report->log_path = q.shown_log();
  report->target = q.target;
  report->target_source = q.target_source;
  return open_log(q, report);
}

}  // namespace

namespace {

/// The median interval between the views with the target, s (infinite with fewer than two).
double median_view_interval_s(std::span<const calib::TargetObservation> views) {
  std::vector<double> dt;
  for (std::size_t i = 1; i < views.size(); ++i)
    dt.push_back(1e-9 * static_cast<double>(views[i].t_ns - views[i - 1].t_ns));
  if (dt.empty()) return std::numeric_limits<double>::infinity();
  std::nth_element(dt.begin(), dt.begin() + static_cast<long>(dt.size() / 2), dt.end());
  return dt[dt.size() / 2];
}

/// The `count` consecutive views (of those with the target) over which the corners move the most
/// from view to view: where a rolling shutter shows most.
std::span<const calib::TargetObservation> fastest_views(std::span<const calib::TargetObservation> views,
                                                        std::size_t count) {
  if (views.size() <= count) return views;
  std::vector<double> motion(views.size(), 0.0);  // mean corner displacement from the view before, px
  for (std::size_t i = 1; i < views.size(); ++i) {
    const auto& a = views[i - 1];
    const auto& b = views[i];
    double sum = 0.0;
    int n = 0;
    for (std::size_t j = 0, k = 0; j < a.ids.size() && k < b.ids.size();) {
      if (a.ids[j] < b.ids[k]) {
        ++j;
      } else if (b.ids[k] < a.ids[j]) {
        ++k;
      } else {
        sum += (a.px[j] - b.px[k]).norm();
        ++n;
        ++j;
        ++k;
      }
    }
    motion[i] = n > 0 ? sum / n : 0.0;
  }
  double window = 0.0, best = -1.0;
  std::size_t first = 0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    window += motion[i];
    if (i >= count) window -= motion[i - count];
    if (i + 1 >= count && window > best) {
      best = window;
      first = i + 1 - count;
    }
  }
  return views.subspan(first, count);
}

/// The shutter of a single camera as the request asks (CameraCalibrationRequest::shutter): the
/// views also solved on a trajectory with the line delay, whose solution replaces the per-view
/// one when the camera is rolling. The evidence (kAuto) is taken on the kShutterTestViews
/// consecutive views that move the most; only a rolling camera is then solved on all of them.
Status solve_shutter(const CameraCalibrationRequest& q, std::span<const calib::TargetObservation> views,
                     CameraCalibrationReport* report) {
  using Mode = calib::ShutterSolveOptions::Mode;
  if (q.shutter.mode == Mode::kGlobal && !q.shutter.line_delay_s) return {};
  const bool automatic = q.shutter.mode == Mode::kAuto && !q.shutter.line_delay_s;
  // A rolling shutter shows only in motion, on views that a smooth trajectory joins: a video.
  constexpr double kMaxVideoIntervalS = 0.2;
  const double interval = median_view_interval_s(views);
  if (automatic && !(interval <= kMaxVideoIntervalS)) {
    report->shutter_choice = "global: the views are " + format_number("%.2f", interval) +
                             " s apart (not a video), so a rolling shutter cannot show; asking for one (" +
                             option_words(CalibOption::kShutter, "rolling") + ") tries anyway";
    return {};
  }
  calib::CameraChainOptions options;
  options.intrinsics = q.intrinsics;
  options.threads = q.threads;
  options.shutter = q.shutter;
  calib::CameraChainInput in;
  in.name = report->stream.name;
  in.model = q.intrinsics.model;
  in.shutter = q.known_shutter;
  const auto [note, warning] = stamp_row_from_stream(report->stream, q.known_stamp_row, in.name, &in.shutter);
  if (!warning.empty()) report->warnings.push_back(warning);
  // The test on the views that move the most (a few seconds of them, not the whole recording).
  constexpr std::size_t kShutterTestViews = 200;
  const bool subset = automatic && views.size() > kShutterTestViews;
  const auto tested = subset ? fastest_views(views, kShutterTestViews) : views;
  in.observations.assign(tested.begin(), tested.end());
  auto chain = calib::calibrate_camera_chain(q.target, std::span(&in, 1), options, {});
  if (chain.ok() && subset && chain->cameras.front().intrinsics.camera.shutter.rolling()) {
    // Rolling on the test's views: every view solved with the line delay (started from the test's).
    const std::string why = chain->cameras.front().shutter_choice + " (on the " +
                            std::to_string(kShutterTestViews) + " consecutive views that move the most)";
    options.shutter.mode = calib::ShutterSolveOptions::Mode::kRolling;
    in.shutter = chain->cameras.front().intrinsics.camera.shutter;
    in.observations.assign(views.begin(), views.end());
    chain = calib::calibrate_camera_chain(q.target, std::span(&in, 1), options, {});
    if (chain.ok()) chain->cameras.front().shutter_choice = why;
  }
  if (!chain.ok()) {
    if (!automatic) return chain.error().context("camera '" + report->stream.name + "' of " + q.shown_log());
    report->shutter_choice =
        "global: the rolling-shutter test on the trajectory failed (" + chain.error().message + ")";
    return {};
  }
  const calib::CameraChainCameraResult& c = chain->cameras.front();
  report->shutter_choice = c.shutter_choice;
  if (subset && !c.intrinsics.camera.shutter.rolling())
    report->shutter_choice +=
        " (on the " + std::to_string(kShutterTestViews) + " consecutive views that move the most)";
  if (!c.intrinsics.camera.shutter.rolling()) return {};
  if (!note.empty()) report->shutter_choice += "; " + note;
  // Rolling: the trajectory's solution replaces the per-view one (whose intrinsics the motion
  // during the readout biased); the views' figures stay those of the per-view start.
  report->intrinsics = c.intrinsics;
  report->line_delay_sigma_s = c.line_delay_sigma_s;
  report->warnings.insert(report->warnings.end(), chain->warnings.begin(), chain->warnings.end());
  return {};
}

/// The self-check's verdict and its scaling notes among the warnings, when the parts disagree or
/// their spread scaled a sigma.
void add_self_check_warnings(const SplitCheck* check, const std::vector<std::string>& notes,
                             std::vector<std::string>* warnings) {
  if (check->verdict == SplitCheck::Verdict::kDisagree)
    warnings->push_back("self-check: " + check->summary + "; " + check->advice);
  for (const auto& n : notes) warnings->push_back("self-check: " + n);
}

}  // namespace

Result<CameraChainReport> calibrate_camera_chain_log(const CameraChainRequest& q) {
  IMUCAL_TRY(q.base.intrinsics.validate());
  IMUCAL_TRY(q.base.target.validate());
  if (q.cameras.size() < 2 || q.models.size() != q.cameras.size()) {
    return make_error(Errc::kInvalidArgument,
                      "a camera chain needs two or more cameras, each with its model");
  }
  calib::CameraChainOptions options = q.chain;
  options.intrinsics = q.base.intrinsics;
  options.threads = q.chain.threads > 0 ? q.chain.threads : q.base.threads;
  IMUCAL_TRY(options.validate());
  CameraChainReport out;
  std::vector<calib::CameraChainInput> inputs;
  for (std::size_t c = 0; c < q.cameras.size(); ++c) {
    CameraCalibrationRequest one = q.base;
    one.camera = q.cameras[c];
    CameraCalibrationReport report;
    auto reader = start_report(one, &report);
    if (!reader.ok()) return reader.error();
    for (const auto& earlier : out.cameras) {
      if (earlier.stream_id == report.stream_id) {
        return make_error(Errc::kInvalidArgument, "camera stream '" + report.stream.name + "' is named twice")
            .with_remedy("camera");
      }
    }
    auto obs = detect_for_report(one, **reader, &report);
    if (!obs.ok()) return obs.error();
    calib::CameraChainInput in;
    in.name = "cam" + std::to_string(c);
    if (report.stream.name != in.name) in.name += " (" + report.stream.name + ")";
    in.model = q.models[c];
    if (!q.base.model_candidates.empty()) {
      // Each camera's model by the evidence of its own views (at most kChoiceViews of them,
      // spread over the recording, as the chain's start uses).
      constexpr std::size_t kChoiceViews = 100;
      std::vector<calib::TargetObservation> sample;
      const std::size_t step = std::max<std::size_t>(1, (obs->size() + kChoiceViews - 1) / kChoiceViews);
      for (std::size_t i = 0; i < obs->size(); i += step) sample.push_back((*obs)[i]);
      auto chosen =
          calib::choose_camera_model(q.base.target, sample, q.base.intrinsics, q.base.model_candidates);
      if (!chosen.ok()) return chosen.error().context(in.name + " of " + q.base.shown_log());
      in.model = chosen->choice.chosen;
      report.model_choice = std::move(chosen->choice);
    }
    in.observations = std::move(*obs);
    in.shutter = c < q.shutters.size() ? q.shutters[c] : q.base.known_shutter;
    const auto [note, warning] =
        stamp_row_from_stream(report.stream, q.base.known_stamp_row, in.name, &in.shutter);
    for (const std::string& text : {note, warning})
      if (!text.empty()) report.warnings.push_back(text);
    inputs.push_back(std::move(in));
    out.warnings.insert(out.warnings.end(), report.warnings.begin(), report.warnings.end());
    out.cameras.push_back(std::move(report));
  }
  auto chain = calib::calibrate_camera_chain(q.base.target, inputs, options, q.base.solve_progress);
  if (!chain.ok()) return chain.error().context(q.base.shown_log());
  for (std::size_t c = 0; c < out.cameras.size(); ++c) {
    out.cameras[c].intrinsics = chain->cameras[c].intrinsics;
    out.cameras[c].line_delay_sigma_s = chain->cameras[c].line_delay_sigma_s;
    out.cameras[c].shutter_choice = chain->cameras[c].shutter_choice;
  }
  out.warnings.insert(out.warnings.end(), chain->warnings.begin(), chain->warnings.end());
  out.chain = std::move(*chain);
  if (q.base.self_check_parts >= 2) {
    // The parts side by side on the detection's workers, each solved on one thread when there are
    // as many parts as workers (so the session's chain, solved on one thread to replay alike,
    // checks its halves on two cores and stays reproducible).
    const int workers = q.base.threads > 0 ? q.base.threads : options.threads;
    out.self_check =
        chain_self_check(q.base.target, inputs, options, out.chain, q.base.self_check_parts, workers);
    add_self_check_warnings(&out.self_check, scale_chain_by_self_check(&out.chain, &out.self_check),
                            &out.warnings);
    for (std::size_t c = 0; c < out.cameras.size(); ++c) {
      out.cameras[c].intrinsics = out.chain.cameras[c].intrinsics;
      out.cameras[c].line_delay_sigma_s = out.chain.cameras[c].line_delay_sigma_s;
    }
  }
  return out;
}

std::vector<calib::TargetObservation> spread_views(const std::vector<calib::TargetObservation>& views,
                                                   int max_views) {
  std::vector<calib::TargetObservation> seen;  // the views with the target
  for (const auto& v : views)
    if (!v.empty()) seen.push_back(v);
  const auto n = static_cast<long>(seen.size());
  if (max_views <= 0 || n <= max_views) return seen;
  std::vector<calib::TargetObservation> out;
  out.reserve(static_cast<std::size_t>(max_views));
  for (long k = 0; k < n; ++k)
    if (calib::opens_slot(k, n, max_views)) out.push_back(seen[static_cast<std::size_t>(k)]);
  return out;
}

Result<CameraCalibrationReport> calibrate_camera_log(const CameraCalibrationRequest& request) {
  IMUCAL_TRY(request.intrinsics.validate());
  CameraCalibrationRequest q = request;  // its model replaced by the chosen one (--model auto)
  IMUCAL_TRY(q.target.validate());
  CameraCalibrationReport report;
  auto reader = start_report(q, &report);
  if (!reader.ok()) return reader.error();
  auto found = detect_for_report(q, **reader, &report);
  if (!found.ok()) return found.error();
  // The solve and its self-check on views spread over the recording; the shutter test keeps
  // the consecutive views it needs.
  const std::vector<calib::TargetObservation> views = spread_views(*found, q.max_views);
  const auto with_target =
      std::count_if(found->begin(), found->end(), [](const auto& o) { return !o.empty(); });
  report.views_not_chosen = static_cast<int>(with_target) - static_cast<int>(views.size());
  if (!q.model_candidates.empty()) {
    auto chosen = calib::choose_camera_model(q.target, views, q.intrinsics, q.model_candidates);
    if (!chosen.ok())
      return chosen.error().context("camera '" + report.stream.name + "' of " + q.shown_log());
    report.intrinsics = std::move(chosen->result);
    report.model_choice = std::move(chosen->choice);
    q.intrinsics.model = report.model_choice->chosen;
  } else {
    auto result = calib::calibrate_camera_intrinsics(q.target, views, q.intrinsics, q.solve_progress);
    if (!result.ok())
      return result.error().context("camera '" + report.stream.name + "' of " + q.shown_log());
    report.intrinsics = std::move(*result);
  }
  report.warnings.insert(report.warnings.end(), report.intrinsics.warnings.begin(),
                         report.intrinsics.warnings.end());
  IMUCAL_TRY(solve_shutter(q, *found, &report));
  // A rolling camera is solved on the trajectory through every view (solve_shutter), and so are
  // its parts.
  const bool rolling = report.intrinsics.camera.shutter.rolling();
  if (rolling) report.views_not_chosen = 0;
  if (q.self_check_parts >= 2) {
    report.self_check = camera_self_check(q.target, rolling ? *found : views, q.intrinsics, report.intrinsics,
                                          report.stream.name, q.self_check_parts, q.threads);
    add_self_check_warnings(&report.self_check,
                            scale_camera_by_self_check(&report.intrinsics, &report.line_delay_sigma_s,
                                                       report.stream.name, &report.self_check),
                            &report.warnings);
  }
  return report;
}

}  // namespace imucal::app
