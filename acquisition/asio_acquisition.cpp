// SPDX-License-Identifier: BSD-3-Clause
#include "acquisition/asio_acquisition.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <boost/asio/error.hpp>
#include <cerrno>
#include <cstring>
#include <string>
#include <utility>

namespace imucal::acq {
namespace {

/// A descriptor that keeps turning readable without giving an edge is broken (a hang-up, a
/// closed pipe); without this limit the loop would spin on it.
constexpr int kMaxIdleLineWakeups = 100;

}  // namespace

AsioAcquisition::AsioAcquisition(boost::asio::io_context& io, ImuSource& acquisition, SampleSink sink)
    : io_(io), acquisition_(acquisition), sink_(std::move(sink)), timer_(io) {}

Status AsioAcquisition::run() {
  if (started_) return make_error(Errc::kInternal, "AsioAcquisition::run() called twice");
  started_ = true;
  if (stopped_) return {};
  if (acquisition_.wake_fd() >= 0) {
    const int fd = ::fcntl(acquisition_.wake_fd(), F_DUPFD_CLOEXEC, 0);
    if (fd < 0) {
      return make_error(Errc::kIo, acquisition_.wake_name() +
                                       ": cannot duplicate its file descriptor: " + std::strerror(errno));
    }
    boost::system::error_code ec;
    line_fd_.emplace(io_);
    line_fd_->assign(fd, ec);
    if (ec) {
      ::close(fd);
      line_fd_.reset();
      return make_error(
          Errc::kIo, acquisition_.wake_name() + ": its file descriptor cannot be watched: " + ec.message());
    }
    arm_line();
  }
  // Edges that came before the descriptor was watched, and the first poll.
  if (service()) arm_timer();
  if (!stopped_) io_.run();
  return failure_;
}

void AsioAcquisition::stop() {
  if (stopped_) return;
  stopped_ = true;
  ++timer_generation_;
  timer_.cancel();
  if (line_fd_) {
    boost::system::error_code ignored;
    line_fd_->cancel(ignored);
  }
  io_.stop();
}

void AsioAcquisition::fail(const Error& error) {
  if (failure_.ok()) failure_ = error;
  stop();
}

void AsioAcquisition::arm_line() {
  line_fd_->async_wait(boost::asio::posix::stream_descriptor::wait_read,
                       [this](const boost::system::error_code& ec) { on_line_ready(ec); });
}

void AsioAcquisition::arm_timer() {
  const std::uint64_t generation = ++timer_generation_;
  timer_.expires_at(steady_time_point(acquisition_.next_poll_ns()));
  timer_.async_wait([this, generation](const boost::system::error_code& ec) { on_timer(generation, ec); });
}

void AsioAcquisition::on_line_ready(const boost::system::error_code& ec) {
  if (stopped_) return;
  if (ec) {
    fail(make_error(Errc::kIo,
                    acquisition_.wake_name() + ": waiting on its file descriptor failed: " + ec.message()));
    return;
  }
  ++stats_.line_wakeups;
  const std::uint64_t progress_before = acquisition_.wake_progress();
  if (!service()) return;
  if (acquisition_.wake_progress() == progress_before) {
    if (++idle_line_wakeups_ >= kMaxIdleLineWakeups) {
      fail(make_error(Errc::kIo, acquisition_.wake_name() + ": its file descriptor stays readable (" +
                                     std::to_string(idle_line_wakeups_) + " times) but gives nothing"));
      return;
    }
  } else {
    idle_line_wakeups_ = 0;
  }
  arm_line();
  arm_timer();
}

void AsioAcquisition::on_timer(std::uint64_t generation, const boost::system::error_code& ec) {
  // A timer re-armed after this expiry was queued makes this wake-up stale.
  if (stopped_ || ec == boost::asio::error::operation_aborted || generation != timer_generation_) return;
  if (ec) {
    fail(make_error(Errc::kInternal, "acquisition poll timer failed: " + ec.message()));
    return;
  }
  ++stats_.timer_wakeups;
  if (service()) arm_timer();
}

bool AsioAcquisition::service() {
  auto st = acquisition_.service(samples_);
  if (!st.ok()) {
    fail(st.error());
    return false;
  }
  if (!samples_.empty()) {
    ++stats_.batches;
    stats_.samples += samples_.size();
    if (!sink_(samples_)) stop();
  }
  return !stopped_;
}

}  // namespace imucal::acq
