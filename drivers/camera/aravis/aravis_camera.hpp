// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// GenICam cameras through Aravis 0.8: GigE Vision, USB3 Vision, and Aravis's own fake camera
// (interface "Fake", device "Fake_1"; tests and demos).
//
// Frames: a fixed set of buffers is pushed to the stream; the stream thread fills them and
// signals an eventfd (fd()) when one is complete; dequeue() pops without blocking. Damaged
// buffers (status other than success: missing packets, timeout, size mismatch) are counted as
// incomplete and go straight back to the stream. Gaps in the device's frame counter, and frames
// the stream had no free buffer for, are counted as dropped. GigE Vision packet loss (missing
// and resent packets) comes from the stream's statistics.
//
// Time: buffer timestamps are on the device's clock (GigE Vision: its tick counter converted to
// ns; the fake camera: wall-clock ns). The backend maps them onto CLOCK_MONOTONIC with ClockSync
// (drivers/camera/clock_sync.hpp), from the host's monotonic time taken in the stream thread
// the moment each buffer is complete. arv_buffer_get_system_timestamp is wall-clock time, not
// monotonic, and is not used. What instant the device stamps is vendor-specific; GenICam cameras
// commonly latch it at the start of exposure (the default here, AravisOptions to override). The
// fake camera stamps the moment it fills the buffer (it models no exposure).
//
// Loss: a GigE Vision device whose heartbeat fails (cable, power, another host taking control)
// emits "control-lost"; dequeue() then fails with kDevice and the stream cannot go on.

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "drivers/camera/camera.hpp"
#include "drivers/camera/clock_sync.hpp"

// Aravis types, declared here so that users of this header need no glib include path.
typedef struct _ArvCamera ArvCamera;
typedef struct _ArvStream ArvStream;
typedef struct _ArvBuffer ArvBuffer;

namespace imucal::drivers::camera {

struct AravisOptions {
  int buffers = 8;  // stream buffers
  /// GenICam features set after open, before the format ("TriggerMode=On TriggerSource=Line1"),
  /// the syntax of arv_device_set_features_from_string.
  std::string features;
  /// Also search Aravis's in-process fake camera ("Fake_1").
  bool fake_interface = false;
  /// What the device's timestamps mark (see above).
  TimestampMeaning timestamp_meaning = TimestampMeaning::kStartOfExposure;
  ClockSyncOptions clock;
};

/// What the device accepts, read from its GenICam features.
struct AravisBounds {
  std::vector<std::string> pixel_formats;
  int width_min = 0, width_max = 0, width_increment = 1;
  int height_min = 0, height_max = 0, height_increment = 1;
  bool rate_available = false;  // AcquisitionFrameRate (or the vendor's equivalent) is there
  double rate_min_hz = 0.0, rate_max_hz = 0.0;
};

/// The ids of the devices Aravis finds now (after a fresh discovery).
std::vector<std::string> list_aravis_cameras(bool fake_interface = false);

class AravisCamera;
/// Opens a device by its Aravis id ("Aravis-Fake-GV01", "<vendor>-<serial>", an IP address).
/// Unknown ids fail with kNotFound naming the ids found.
[[nodiscard]] Result<std::unique_ptr<AravisCamera>> open_aravis_camera(const std::string& id,
                                                                       const AravisOptions& options = {});

class AravisCamera final : public Camera {
 public:
  ~AravisCamera() override;
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  const char* backend() const override { return "aravis"; }
  const std::string& id() const override { return id_; }

  /// One format per pixel format, at the largest size and rate the device offers now; the
  /// device takes any size and rate within bounds() as well.
  [[nodiscard]] Result<std::vector<FrameFormat>> formats() override;
  [[nodiscard]] Result<AravisBounds> bounds();
  [[nodiscard]] Status set_format(const FrameFormat& format) override;
  FrameFormat format() const override { return format_; }

  [[nodiscard]] Status start() override;
  [[nodiscard]] Status stop() override;
  int fd() const override { return event_fd_; }
  [[nodiscard]] Result<Frame> dequeue() override;

  TimestampMeaning timestamp_meaning() const override { return options_.timestamp_meaning; }
  CameraCounters counters() const override;

  /// Sets GenICam features ("Name=Value ..."), e.g. trigger settings; refused while streaming.
  [[nodiscard]] Status set_features(const std::string& features);
  /// Executes a GenICam command feature ("TriggerSoftware").
  [[nodiscard]] Status execute(const std::string& command);
  /// The clock mapping of the current stream.
  ClockSyncState clock_state() const { return clock_.state(); }
  bool is_gige() const;

  struct Stream;  // the streaming state, shared with frames still held (aravis_camera.cpp)

 private:
  friend Result<std::unique_ptr<AravisCamera>> open_aravis_camera(const std::string&, const AravisOptions&);
  AravisCamera(std::string id, ArvCamera* camera, AravisOptions options);
  [[nodiscard]] Status read_format();
  [[nodiscard]] Status apply_rate(double rate_hz);
  void count_frame_id(std::uint64_t frame_id);
  void update_stream_statistics();
  Frame make_frame(ArvBuffer* buffer, TimeNs received_ns);
  static void on_control_lost(void* device, void* self);

  std::string id_;
  ArvCamera* camera_ = nullptr;
  AravisOptions options_;
  FrameFormat format_;
  int event_fd_ = -1;
  unsigned long control_lost_handler_ = 0;
  std::atomic<bool> lost_{false};
  std::shared_ptr<Stream> stream_;
  ClockSync clock_;
  TimeNs exposure_ns_ = 0;
  bool have_frame_id_ = false;
  std::uint64_t last_frame_id_ = 0;
  std::uint64_t dropped_base_ = 0;  // counts of the streams before the current one
  std::uint64_t packets_base_ = 0;

  std::atomic<std::uint64_t> frames_{0};
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> incomplete_{0};
  std::atomic<std::uint64_t> packets_lost_{0};
  std::atomic<std::uint64_t> errors_{0};
};

}  // namespace imucal::drivers::camera
