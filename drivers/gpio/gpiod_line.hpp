// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// DataReadyLine on a real GPIO chip through the libgpiod 1.6 C API (GPIO character device,
// uAPI v1): the MPU-6000 INT pin (active high, the chip's default) wired to a GPIO input,
// requested for rising-edge events. The kernel timestamps each edge in its interrupt handler.
//
// Event clock: libgpiod 1.6 passes the kernel's uAPI v1 timestamp through unchanged. Linux 5.7
// changed that timestamp from CLOCK_REALTIME to CLOCK_MONOTONIC (commit f8850206e160, "gpio:
// Switch timestamps to ktime_get_ns()"). On older kernels the timestamp is converted to
// CLOCK_MONOTONIC with the realtime-monotonic offset measured when the event is read (which
// is wrong by any realtime step between edge and read); on every kernel a timestamp that
// cannot be on CLOCK_MONOTONIC is reported as an error rather than passed on.
//
// The uAPI v1 has no event sequence numbers, and its event queue holds 16 events: while it is
// full the kernel drops every new edge until the queue is read. The line therefore reads the
// queue 16 events at a time; a read that returns 16 may have left edges dropped after its last
// event, and the gap between that event's stamp and the next one's, in periods, tells how many
// (the period: the mean of the recent intervals between consecutive edges, of those within
// ±50 % of the median interval of the 16 queued events). `sequence` counts them, so they show
// as a gap in the sequence (the MPU-6000 driver's missed_data_ready) and the timestamper ties
// later edges to the right samples (docs/testing-devices.md, docs/acquisition.md).

#include <cstddef>
#include <deque>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "core/result.hpp"
#include "drivers/gpio/data_ready_line.hpp"

namespace imucal::drivers {

enum class GpioEventClock { kMonotonic, kRealtime };

/// The clock of uAPI v1 GPIO event timestamps on a kernel with this `uname -r` release:
/// kRealtime before 5.7, kMonotonic from 5.7 on (and for a release string that cannot be
/// parsed, since every supported kernel is newer).
GpioEventClock gpio_event_clock_for_kernel(std::string_view release);

/// Converts a kernel event timestamp to CLOCK_MONOTONIC, given both clocks read just after the
/// event was read. Fails (kDevice) when the result lies more than 1 ms after `mono_now_ns` or
/// more than an hour before it: then the timestamp is not on the clock the kernel was assumed
/// to use.
[[nodiscard]] Result<TimeNs> gpio_event_to_monotonic(TimeNs event_ns, GpioEventClock clock,
                                                     TimeNs mono_now_ns, TimeNs real_now_ns);

/// Depth of the kernel's uAPI v1 line event queue (gpiolib-cdev.c: a 16-entry kfifo; libgpiod 1.6
/// reads at most 16 events at a time). While it is full the kernel drops new edges.
inline constexpr std::size_t kGpioV1EventQueueDepth = 16;

/// The line's event queue in the kernel as GpiodDataReadyLine reads it: libgpiod on the GPIO
/// character device, or a fake kernel in the unit tests.
class GpioEventSource {
 public:
  virtual ~GpioEventSource() = default;
  /// Waits up to `timeout_ns` for a pending event: 1 when one is pending, 0 on timeout, -1 on
  /// failure (errno set).
  virtual int wait(TimeNs timeout_ns) = 0;
  /// Reads up to `stamps.size()` pending events with one read of the event descriptor, oldest
  /// first, and writes their kernel timestamps: the number read, or -1 (errno set).
  virtual int read(std::span<TimeNs> stamps) = 0;
  virtual int fd() const = 0;
};

struct GpiodLineStats {
  std::uint64_t events_read = 0;    // events taken from the kernel
  std::uint64_t full_reads = 0;     // reads that returned a full queue (edges may follow dropped)
  std::uint64_t edges_dropped = 0;  // edges the kernel dropped, estimated from the stamps' gap
};

struct GpiodLineOptions {
  /// Chip as gpiod_chip_open_lookup() takes it: "gpiochip0", "/dev/gpiochip0", "0" or a label.
  std::string chip;
  /// Line offset on the chip ("17") or the line's name ("IMU_DRDY").
  std::string line;
  /// Consumer label shown by gpioinfo.
  std::string consumer = "imucal";
};

class GpiodDataReadyLine final : public DataReadyLine {
 public:
  /// Opens the chip, finds the line and requests rising-edge events. A missing chip or line,
  /// missing permissions or a line held by another consumer give an error saying what to check.
  [[nodiscard]] static Result<std::unique_ptr<GpiodDataReadyLine>> open(const GpiodLineOptions& options);
  /// A line reading `source` (the unit tests' fake kernel).
  static std::unique_ptr<GpiodDataReadyLine> over(std::unique_ptr<GpioEventSource> source, std::string name,
                                                  GpioEventClock clock = GpioEventClock::kMonotonic);
  ~GpiodDataReadyLine() override;
  GpiodDataReadyLine(const GpiodDataReadyLine&) = delete;
  GpiodDataReadyLine& operator=(const GpiodDataReadyLine&) = delete;

  /// The next edge: one left from the last read of the kernel's queue, else the next read
  /// (up to 16 events), waiting up to `timeout_ns` for one. Edges read together are handed out
  /// one per call while the descriptor may no longer be readable: a reader takes edges with
  /// wait(0) until it returns none (as ImuAcquisition does) before it waits on fd() again.
  [[nodiscard]] Result<std::optional<DataReadyEdge>> wait(TimeNs timeout_ns) override;
  int fd() const override;
  std::string name() const override { return name_; }
  GpioEventClock event_clock() const { return clock_; }
  const GpiodLineStats& stats() const { return stats_; }

 private:
  GpiodDataReadyLine(std::unique_ptr<GpioEventSource> source, std::string name, GpioEventClock clock);
  [[nodiscard]] Status read_events();
  std::uint64_t number(TimeNs t_ns);
  double period_estimate(std::span<const TimeNs> queued) const;

  static constexpr std::size_t kIntervalWindow = 512;

  std::unique_ptr<GpioEventSource> source_;
  std::string name_;
  GpioEventClock clock_ = GpioEventClock::kMonotonic;
  std::deque<DataReadyEdge> pending_;  // read from the kernel, not yet handed out
  std::uint64_t edges_ = 0;            // edges numbered so far, dropped ones included
  bool have_last_ = false;
  TimeNs last_t_ns_ = 0;          // stamp of the last event read
  double drop_period_ns_ = 0.0;   // > 0: the last read was full; the period to count drops with
  std::deque<TimeNs> intervals_;  // between consecutive edges read, the newest kIntervalWindow
  GpiodLineStats stats_;
};

}  // namespace imucal::drivers
