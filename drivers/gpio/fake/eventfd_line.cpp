// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/gpio/fake/eventfd_line.hpp"

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>

namespace imucal::fake {

Result<std::unique_ptr<RealtimeDataReadyLine>> RealtimeDataReadyLine::create(DataReadyTiming timing) {
  const int fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK | EFD_SEMAPHORE);
  if (fd < 0) {
    return make_error(Errc::kIo,
                      std::string("simulated data-ready line: eventfd failed: ") + std::strerror(errno));
  }
  return std::unique_ptr<RealtimeDataReadyLine>(new RealtimeDataReadyLine(fd, timing));
}

RealtimeDataReadyLine::RealtimeDataReadyLine(int fd, DataReadyTiming timing)
    : fd_(fd), timing_(timing), rng_(timing.seed) {}

RealtimeDataReadyLine::~RealtimeDataReadyLine() { ::close(fd_); }

void RealtimeDataReadyLine::raise(TimeNs true_t_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++sequence_;
  const double jitter = timing_.sigma_ns > 0 ? normal_(rng_) * static_cast<double>(timing_.sigma_ns) : 0.0;
  const TimeNs latency = std::max<TimeNs>(0, timing_.latency_ns + static_cast<TimeNs>(std::llround(jitter)));
  TimeNs t_ns = true_t_ns + latency;
  // The kernel timestamps events in the order it services them.
  if (t_ns <= last_edge_t_ns_) t_ns = last_edge_t_ns_ + 1;
  last_edge_t_ns_ = t_ns;
  scheduled_.push_back({t_ns, sequence_});
}

TimeNs RealtimeDataReadyLine::release(TimeNs now_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t n = 0;
  while (!scheduled_.empty() && scheduled_.front().t_ns <= now_ns) {
    ready_.push_back(scheduled_.front());
    scheduled_.pop_front();
    ++n;
  }
  if (n > 0) {
    // Cannot fail: the count stays far below the eventfd's limit.
    const ssize_t written = ::write(fd_, &n, sizeof n);
    (void)written;
  }
  return scheduled_.empty() ? SimTimeSource::kNever : scheduled_.front().t_ns;
}

Result<std::optional<drivers::DataReadyEdge>> RealtimeDataReadyLine::wait(TimeNs timeout_ns) {
  if (timeout_ns < 0) return make_error(Errc::kInvalidArgument, name() + ": negative wait timeout");
  if (timeout_ns > 0) {
    pollfd p{fd_, POLLIN, 0};
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(timeout_ns / kNsPerSecond);
    ts.tv_nsec = static_cast<long>(timeout_ns % kNsPerSecond);
    if (::ppoll(&p, 1, &ts, nullptr) < 0 && errno != EINTR) {
      return make_error(Errc::kIo, name() + ": waiting for an edge failed: " + std::strerror(errno));
    }
  }
  if (catch_up_) {
    catch_up_();
    release(monotonic_now_ns());
  }
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t one = 0;
  if (::read(fd_, &one, sizeof one) < 0) {
    if (errno == EAGAIN) return std::optional<drivers::DataReadyEdge>();
    return make_error(Errc::kIo, name() + ": reading an edge failed: " + std::strerror(errno));
  }
  if (ready_.empty()) return make_error(Errc::kInternal, name() + ": eventfd count and edge queue disagree");
  const drivers::DataReadyEdge edge = ready_.front();
  ready_.pop_front();
  return std::optional<drivers::DataReadyEdge>(edge);
}

std::uint64_t RealtimeDataReadyLine::raised() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return sequence_;
}

}  // namespace imucal::fake
