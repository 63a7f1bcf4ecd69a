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
// The uAPI v1 has no event sequence numbers: `sequence` counts the edges this line has read,
// so edges lost in the kernel's event queue (16 entries) do not show as gaps there and nothing
// counts them (docs/testing-devices.md: under QEMU the time reconstruction then ties later edges
// to older samples).

#include <memory>
#include <string>
#include <string_view>

#include "core/result.hpp"
#include "drivers/gpio/data_ready_line.hpp"

struct gpiod_chip;
struct gpiod_line;

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
  ~GpiodDataReadyLine() override;
  GpiodDataReadyLine(const GpiodDataReadyLine&) = delete;
  GpiodDataReadyLine& operator=(const GpiodDataReadyLine&) = delete;

  [[nodiscard]] Result<std::optional<DataReadyEdge>> wait(TimeNs timeout_ns) override;
  int fd() const override;
  std::string name() const override { return name_; }
  GpioEventClock event_clock() const { return clock_; }

 private:
  GpiodDataReadyLine(gpiod_chip* chip, gpiod_line* line, std::string name, GpioEventClock clock);

  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  std::string name_;
  GpioEventClock clock_ = GpioEventClock::kMonotonic;
  std::uint64_t edges_ = 0;
};

}  // namespace imucal::drivers
