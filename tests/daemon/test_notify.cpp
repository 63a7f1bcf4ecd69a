// SPDX-License-Identifier: BSD-3-Clause
// Notifier against a real AF_UNIX datagram socket given as NOTIFY_SOCKET, as systemd does.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>

#include "daemon/service/notify.hpp"
#include "tests/daemon/service_test_host.hpp"

namespace imucal::service {
namespace {

class NotifySocket {
 public:
  NotifySocket() : path_(dir_.path + "/notify") {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strcpy(addr.sun_path, path_.c_str());
    EXPECT_EQ(::bind(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0) << std::strerror(errno);
    timeval timeout{5, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
    ::setenv("NOTIFY_SOCKET", path_.c_str(), 1);
  }
  ~NotifySocket() {
    ::unsetenv("NOTIFY_SOCKET");
    ::close(fd_);
  }
  NotifySocket(const NotifySocket&) = delete;
  NotifySocket& operator=(const NotifySocket&) = delete;

  std::string next() {
    char buffer[4096];
    const ssize_t n = ::recv(fd_, buffer, sizeof(buffer), 0);
    return n > 0 ? std::string(buffer, static_cast<std::size_t>(n)) : std::string("<nothing>");
  }

 private:
  test::SocketDir dir_;
  std::string path_;
  int fd_ = -1;
};

TEST(Notifier, SendsReadyStatusWatchdogAndStopping) {
  NotifySocket socket;
  Notifier notifier;
  notifier.ready();
  EXPECT_EQ(socket.next(), "READY=1");
  notifier.status("poses: 7 of 12\nREADY=1");
  EXPECT_EQ(socket.next(), "STATUS=poses: 7 of 12 READY=1") << "a newline must not start another field";
  notifier.watchdog();
  EXPECT_EQ(socket.next(), "WATCHDOG=1");
  notifier.stopping();
  EXPECT_EQ(socket.next(), "STOPPING=1");
  EXPECT_EQ(notifier.sent(), 4u);
}

TEST(Notifier, WatchdogIntervalComesFromTheEnvironmentForThisProcess) {
  ::setenv("WATCHDOG_USEC", "10000000", 1);
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  Notifier notifier;
  auto interval = notifier.watchdog_interval();
  ASSERT_TRUE(interval.has_value());
  EXPECT_EQ(*interval, std::chrono::seconds(10));
  // A watchdog meant for another process (a parent that exec-ed us) is not ours.
  ::setenv("WATCHDOG_PID", std::to_string(::getpid() + 1).c_str(), 1);
  EXPECT_FALSE(notifier.watchdog_interval().has_value());
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
  EXPECT_FALSE(notifier.watchdog_interval().has_value());
}

TEST(WatchdogPinger, PingsFromTheLoopWhileHealthy) {
  NotifySocket socket;
  ::setenv("WATCHDOG_USEC", "100000", 1);  // pings every 50 ms
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  boost::asio::io_context io;
  Notifier notifier;
  int checks = 0;
  WatchdogPinger pinger(io, notifier, [&] { return ++checks < 3; });  // healthy twice, then not
  ASSERT_TRUE(pinger.start());
  EXPECT_EQ(socket.next(), "WATCHDOG=1");  // at once on start
  while (checks < 4 && io.run_one_for(std::chrono::seconds(5)) > 0) {
  }
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
  EXPECT_EQ(checks, 4);
  EXPECT_EQ(notifier.sent(), 3u) << "one ping at start, then one per healthy check only";
  EXPECT_EQ(socket.next(), "WATCHDOG=1");
  EXPECT_EQ(socket.next(), "WATCHDOG=1");
}

TEST(WatchdogPinger, DoesNotStartWithoutAWatchdog) {
  ::unsetenv("WATCHDOG_USEC");
  boost::asio::io_context io;
  Notifier notifier;
  WatchdogPinger pinger(io, notifier);
  EXPECT_FALSE(pinger.start());
  EXPECT_EQ(io.run_for(std::chrono::milliseconds(10)), 0u) << "nothing scheduled";
}

TEST(Notifier, DoesNothingWithoutNotifySocket) {
  ::unsetenv("NOTIFY_SOCKET");
  Notifier notifier;
  notifier.ready();
  notifier.status("x");
  notifier.watchdog();
  EXPECT_EQ(notifier.sent(), 0u);
}

}  // namespace
}  // namespace imucal::service
