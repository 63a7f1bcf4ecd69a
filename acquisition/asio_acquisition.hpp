// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The acquisition loop on a Boost.Asio event loop: the form a rig runs (real time).
//
// When the source has a file descriptor (libgpiod's line event fd, the real-time simulated
// line's eventfd, the kernel's IIO buffer), a duplicate of it is watched with
// posix::stream_descriptor::async_wait(wait_read); each time it turns readable the loop calls
// ImuSource::service(), which takes the pending edges and reads the FIFO once enough have
// come (or reads the IIO buffer). A steady_timer armed at ImuAcquisition::next_poll_ns() calls service() when
// no edge came in time; without a line (or one without a descriptor) it is the only wake-up, and the FIFO is
// polled on the timer. Non-empty batches go to a sink. An error from the line, its descriptor or the driver
// stops the loop and is returned by run().
//
// Time: next_poll_ns() is CLOCK_MONOTONIC nanoseconds; the timer runs on
// std::chrono::steady_clock, which libstdc++ implements with clock_gettime(CLOCK_MONOTONIC) on
// Linux (same epoch, nanosecond ticks). steady_time_point() relies on that; the static checks
// below and a test against clock_gettime hold it to it.

#include <boost/asio/io_context.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "acquisition/imu_source.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"

namespace imucal::acq {

static_assert(std::chrono::steady_clock::is_steady);
static_assert(std::is_same_v<std::chrono::steady_clock::duration, std::chrono::nanoseconds>,
              "steady_time_point() maps CLOCK_MONOTONIC nanoseconds one to one onto steady_clock ticks");

/// A CLOCK_MONOTONIC time in ns as a steady_clock time point (see the note above).
inline std::chrono::steady_clock::time_point steady_time_point(TimeNs monotonic_ns) {
  return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(monotonic_ns));
}

struct AsioAcquisitionStats {
  std::uint64_t line_wakeups = 0;   // the line's descriptor turned readable
  std::uint64_t timer_wakeups = 0;  // the poll timer expired
  std::uint64_t batches = 0;        // non-empty batches handed to the sink
  std::uint64_t samples = 0;
};

class AsioAcquisition {
 public:
  /// Receives every non-empty batch of samples; returns false to stop the loop.
  using SampleSink = std::function<bool(std::span<const ImuSample>)>;

  /// `io` and `acquisition` are borrowed and must outlive this object. The acquisition's line
  /// (if any) is watched through a duplicate of its descriptor; the line keeps its own.
  AsioAcquisition(boost::asio::io_context& io, ImuSource& acquisition, SampleSink sink);
  AsioAcquisition(const AsioAcquisition&) = delete;
  AsioAcquisition& operator=(const AsioAcquisition&) = delete;

  /// Arms the line's descriptor and the poll timer and runs `io` until stop(), the sink returns
  /// false or an error. Returns that error (the line's, its descriptor's or the driver's), or
  /// ok when stopped. Runs once.
  [[nodiscard]] Status run();

  /// Ends run(): cancels the waits and stops `io` (other work on it stops as well). Call it
  /// from a handler on `io` (a signal, a timer) or before run().
  void stop();
  bool stopped() const { return stopped_; }

  /// True when run() watches the line's descriptor, false when it polls on the timer only.
  bool watches_line() const { return line_fd_.has_value(); }
  const AsioAcquisitionStats& stats() const { return stats_; }

 private:
  void arm_line();
  void arm_timer();
  void on_line_ready(const boost::system::error_code& ec);
  void on_timer(std::uint64_t generation, const boost::system::error_code& ec);
  /// Calls ImuAcquisition::service() and hands the samples on; false once stopped.
  bool service();
  void fail(const Error& error);

  boost::asio::io_context& io_;
  ImuSource& acquisition_;
  SampleSink sink_;
  std::optional<boost::asio::posix::stream_descriptor> line_fd_;
  boost::asio::steady_timer timer_;
  std::uint64_t timer_generation_ = 0;
  std::vector<ImuSample> samples_;
  int idle_line_wakeups_ = 0;  // consecutive wake-ups of the descriptor that gave no edge
  bool started_ = false;
  bool stopped_ = false;
  Status failure_;
  AsioAcquisitionStats stats_;
};

}  // namespace imucal::acq
