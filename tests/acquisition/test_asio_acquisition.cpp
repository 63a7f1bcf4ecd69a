// SPDX-License-Identifier: BSD-3-Clause
// The event-loop acquisition (acquisition/asio_acquisition.hpp) for real: the real-time
// simulated rig (sim/realtime.hpp) ticks the emulated chip along CLOCK_MONOTONIC
// and signals data-ready edges on an eventfd, the Asio loop wakes on that descriptor and on its
// poll timer, and every sample it delivers is compared with the frames the chip wrote. Then
// `imucal record --sim --realtime` through the CLI, including SIGINT in the middle of it.
//
// Only correctness is asserted, never speed: the machines running this are shared and the
// suite also runs under AddressSanitizer. A host that stops reading for longer than the FIFO
// holds (the driver resets it above its watermark, 64 frames: 64 ms at 1 kHz) loses samples
// as a rig would; the tests then require that the loss is flagged and that the loop really
// paused that long, and no loss at all otherwise.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/asio_acquisition.hpp"
#include "drivers/mpu6000/output_settings.hpp"
#include "log/session_log.hpp"
#include "sim/realtime.hpp"
#include "sim/rig.hpp"
#include "tests/support/emulator_accounting.hpp"
#include "tests/support/session_log_util.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::acq {
namespace {

using namespace imucal::test;  // shared session-log helpers (tests/support)

namespace mpu = drivers::mpu6000;
using emutest::account;
using emutest::Accounting;
using emutest::wobble;
using namespace std::chrono_literals;

mpu::Settings settings_at(double rate_hz) {
  mpu::OutputRequest req;
  req.rate_hz = rate_hz;
  auto s = mpu::settings_for(req);
  EXPECT_TRUE(s.ok());
  return s.ok() ? *s : mpu::Settings{};
}

struct RealtimeRun {
  Accounting acc;
  double longest_pause_ms = 0.0;  // between consecutive batches, wall-clock
  std::uint64_t fifo_resets = 0;  // by the driver (watermark, overflow)
  AcquisitionStats acquisition;
  AsioAcquisitionStats loop;
  bool watched_line = false;
  std::uint64_t edges_raised = 0;
};

/// The real-time simulated rig on the Asio loop for `wall` of wall-clock time.
RealtimeRun run_realtime(bool with_line, std::chrono::milliseconds wall) {
  sim::RealtimeSimRigOptions o;
  o.settings = settings_at(1000.0);
  o.record_truth = true;
  o.with_line = with_line;
  auto created = sim::RealtimeSimRig::create(wobble, o);
  EXPECT_TRUE(created.ok()) << (created.ok() ? "" : created.error().message);
  RealtimeRun r;
  if (!created.ok()) return r;
  sim::RealtimeSimRig& rig = **created;

  boost::asio::io_context io;
  std::vector<ImuSample> all;
  std::optional<std::chrono::steady_clock::time_point> last_batch;
  AsioAcquisition loop(io, rig.acquisition(), [&](std::span<const ImuSample> s) {
    all.insert(all.end(), s.begin(), s.end());
    const auto now = std::chrono::steady_clock::now();
    if (last_batch) {
      r.longest_pause_ms =
          std::max(r.longest_pause_ms, std::chrono::duration<double, std::milli>(now - *last_batch).count());
    }
    last_batch = now;
    return true;
  });
  boost::asio::steady_timer end_timer(io);
  end_timer.expires_after(wall);
  end_timer.async_wait([&](const boost::system::error_code& ec) {
    if (!ec) loop.stop();
  });
  const Status st = loop.run();
  EXPECT_TRUE(st.ok()) << (st.ok() ? "" : st.error().message);
  rig.stop_ticker();

  r.acc = account(all, rig.emulator());
  r.fifo_resets = rig.driver().counters().fifo_resets;
  r.acquisition = rig.acquisition().stats();
  r.loop = loop.stats();
  r.watched_line = loop.watches_line();
  r.edges_raised = rig.line() != nullptr ? rig.line()->raised() : 0;
  return r;
}

/// Every delivered sample is a frame the chip wrote, in order; frames are lost only behind a
/// flagged gap after the loop paused longer than the FIFO holds, and not at all otherwise.
void expect_every_frame(const RealtimeRun& r) {
  const Accounting& a = r.acc;
  EXPECT_GT(a.delivered, 100u);
  EXPECT_EQ(a.mismatched, 0u);
  EXPECT_EQ(a.delivered + a.lost + a.still_in_fifo, a.produced);
  EXPECT_EQ(a.unflagged_losses, 0u);
  if (r.longest_pause_ms < 60.0) {
    EXPECT_EQ(a.lost, 0u) << "frames lost although the loop never paused as long as the FIFO holds";
    EXPECT_EQ(r.fifo_resets, 0u);
  } else {
    std::printf("  the host paused the loop for %.0f ms, longer than the FIFO holds: %zu frames lost\n",
                r.longest_pause_ms, a.lost);
  }
}

TEST(AsioAcquisition, SteadyClockIsClockMonotonic) {
  // steady_time_point() maps CLOCK_MONOTONIC ns onto steady_clock: same clock, same epoch.
  const TimeNs before_ns = monotonic_now_ns();
  const TimeNs steady_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::steady_clock::now().time_since_epoch())
                               .count();
  const TimeNs after_ns = monotonic_now_ns();
  EXPECT_LE(before_ns, steady_ns);
  EXPECT_LE(steady_ns, after_ns);
  EXPECT_EQ(steady_time_point(before_ns).time_since_epoch().count(), before_ns);
}

// service(), the non-blocking step, on the deterministic simulated rig: an event loop that
// looks every 100 us gets every frame the chip wrote, in order, timed as well as by step().
TEST(AcquisitionService, DeliversEveryFrameOnTheSimulatedRig) {
  sim::SimRigOptions o;
  o.settings = settings_at(1000.0);
  o.record_truth = true;
  auto created = sim::SimImuRig::create(wobble, o);
  ASSERT_TRUE(created.ok());
  sim::SimImuRig& rig = **created;
  std::vector<ImuSample> out, all;
  const TimeNs end = rig.clock().now_ns() + s_to_ns(5.0);
  while (rig.clock().now_ns() < end) {
    rig.clock().sleep_until(std::min(rig.acquisition().next_poll_ns(), rig.clock().now_ns() + 100'000));
    ASSERT_TRUE(rig.acquisition().service(out).ok());
    all.insert(all.end(), out.begin(), out.end());
  }
  const Accounting acc = account(all, rig.emulator());
  const AcquisitionStats& st = rig.acquisition().stats();
  std::printf(
      "  %zu samples, %zu lost, %zu left in the FIFO, %llu batches (%llu without an edge), "
      "%.2f edges per batch, rms %.2f us\n",
      acc.delivered, acc.lost, acc.still_in_fifo, static_cast<unsigned long long>(st.batches),
      static_cast<unsigned long long>(st.batches_without_edge),
      static_cast<double>(st.edges) / static_cast<double>(std::max<std::uint64_t>(1, st.batches)),
      acc.rms_time_error_ns / 1e3);
  EXPECT_GT(acc.delivered, 4000u);
  EXPECT_EQ(acc.mismatched, 0u);
  EXPECT_EQ(acc.lost, 0u);
  EXPECT_EQ(acc.delivered + acc.still_in_fifo, acc.produced);
  EXPECT_EQ(acc.gap_flags, 0u);
  EXPECT_LT(st.batches_without_edge * 20, st.batches);
  EXPECT_LT(acc.rms_time_error_ns, 5'000.0);
}

// The Asio loop over the real-time rig with the eventfd line, about 1.5 s of wall time at
// 1 kHz: the edges wake the loop and drive the FIFO reads, and nothing is lost.
TEST(AsioAcquisition, RealtimeRigWithLineDeliversEveryFrame) {
  const RealtimeRun r = run_realtime(true, 1500ms);
  const auto& st = r.acquisition;
  std::printf(
      "  %zu samples, %zu lost, %zu left in the FIFO, %llu batches (%llu without an edge), "
      "%.2f edges per batch, %llu line / %llu timer wake-ups, rms %.2f us, %zu gap flags, longest "
      "pause %.1f ms\n",
      r.acc.delivered, r.acc.lost, r.acc.still_in_fifo, static_cast<unsigned long long>(st.batches),
      static_cast<unsigned long long>(st.batches_without_edge),
      static_cast<double>(st.edges) / static_cast<double>(std::max<std::uint64_t>(1, st.batches)),
      static_cast<unsigned long long>(r.loop.line_wakeups),
      static_cast<unsigned long long>(r.loop.timer_wakeups), r.acc.rms_time_error_ns / 1e3, r.acc.gap_flags,
      r.longest_pause_ms);
  EXPECT_TRUE(r.watched_line);
  expect_every_frame(r);
  EXPECT_GT(r.loop.line_wakeups, 0u);
  EXPECT_GT(st.edges, 0u);
  EXPECT_LE(st.edges, r.edges_raised);
  // Most reads follow an edge; a timer poll is the exception (a late edge, a busy host).
  EXPECT_LT(2 * st.batches_without_edge, st.batches);
  // Sample times come from the edges' timestamps, not from when the loop woke up.
  EXPECT_LT(r.acc.rms_time_error_ns, 50'000.0);
}

// Without a data-ready line the loop polls the FIFO on its timer; still nothing is lost.
TEST(AsioAcquisition, RealtimeRigWithoutLinePollsOnTheTimer) {
  const RealtimeRun r = run_realtime(false, 1500ms);
  const auto& st = r.acquisition;
  std::printf(
      "  %zu samples, %zu lost, %zu left in the FIFO, %llu batches, %llu timer wake-ups, %zu gap flags, "
      "longest pause %.1f ms\n",
      r.acc.delivered, r.acc.lost, r.acc.still_in_fifo, static_cast<unsigned long long>(st.batches),
      static_cast<unsigned long long>(r.loop.timer_wakeups), r.acc.gap_flags, r.longest_pause_ms);
  EXPECT_FALSE(r.watched_line);
  expect_every_frame(r);
  EXPECT_EQ(r.loop.line_wakeups, 0u);
  EXPECT_GT(r.loop.timer_wakeups, 0u);
  EXPECT_EQ(st.batches_without_edge, st.batches);
  EXPECT_EQ(st.edges, 0u);
}

/// A bus with nothing on it: every register reads 0.
class DeadBus final : public drivers::RegisterBus {
 public:
  Status read(std::uint8_t, std::span<std::uint8_t> out) override {
    ++counters_.transfers;
    std::fill(out.begin(), out.end(), 0);
    return {};
  }
  Status write(std::uint8_t, std::uint8_t) override {
    ++counters_.transfers;
    return {};
  }
  std::string name() const override { return "dead-bus"; }
  const drivers::BusCounters& counters() const override { return counters_; }

 private:
  drivers::BusCounters counters_;
};

/// A line whose descriptor is the read end of a pipe: when the other end closes the
/// descriptor turns readable (end of file) and wait() reports the line gone.
class HangUpLine final : public drivers::DataReadyLine {
 public:
  HangUpLine() {
    if (::pipe2(fds_, O_CLOEXEC) != 0) fds_[0] = fds_[1] = -1;
  }
  ~HangUpLine() override {
    for (int fd : fds_) {
      if (fd >= 0) ::close(fd);
    }
  }
  void hang_up() {
    ::close(fds_[1]);
    fds_[1] = -1;
  }
  Result<std::optional<drivers::DataReadyEdge>> wait(TimeNs timeout_ns) override {
    pollfd p{fds_[0], POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout_ns / 1'000'000)) == 0)
      return std::optional<drivers::DataReadyEdge>();
    return make_error(Errc::kIo, name() + ": the GPIO chip went away");
  }
  int fd() const override { return fds_[0]; }
  std::string name() const override { return "hang-up-line"; }

 private:
  int fds_[2] = {-1, -1};
};

// An error on the line's descriptor stops the loop with the line's own message. The line
// hangs up while the driver waits out its 100 ms reset delay, so it is the descriptor that
// wakes the loop (the dead bus would fail the driver only later).
TEST(AsioAcquisition, ALineErrorStopsTheLoop) {
  DeadBus bus;
  mpu::Mpu6000 driver(bus, settings_at(1000.0));
  HangUpLine line;
  ASSERT_GE(line.fd(), 0);
  MonotonicClock clock;
  ImuAcquisition acquisition(driver, &line, clock, MountingMap{}, AcquisitionOptions{});
  boost::asio::io_context io;
  AsioAcquisition loop(io, acquisition, [](std::span<const ImuSample>) { return true; });
  boost::asio::steady_timer hang_up(io);
  hang_up.expires_after(20ms);
  hang_up.async_wait([&](const boost::system::error_code& ec) {
    if (!ec) line.hang_up();
  });
  boost::asio::steady_timer watchdog(io);
  watchdog.expires_after(60s);
  watchdog.async_wait([&](const boost::system::error_code& ec) {
    if (!ec) loop.stop();
  });
  const Status st = loop.run();
  ASSERT_FALSE(st.ok()) << "the loop ran on after the line failed";
  EXPECT_NE(st.error().message.find("data-ready line: hang-up-line: the GPIO chip went away"),
            std::string::npos)
      << st.error().message;
  EXPECT_TRUE(loop.watches_line());
  // Only a host stalled past the reset delay lets the poll timer find the hang-up first.
  EXPECT_LE(loop.stats().line_wakeups, 1u);
  EXPECT_TRUE(loop.stopped());
}

/// A line whose descriptor is a regular file, which epoll cannot watch.
class FileLine final : public drivers::DataReadyLine {
 public:
  explicit FileLine(const std::string& path)
      : fd_(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600)) {}
  ~FileLine() override {
    if (fd_ >= 0) ::close(fd_);
  }
  Result<std::optional<drivers::DataReadyEdge>> wait(TimeNs) override {
    return std::optional<drivers::DataReadyEdge>();
  }
  int fd() const override { return fd_; }
  std::string name() const override { return "file-line"; }

 private:
  int fd_;
};

TEST(AsioAcquisition, ADescriptorThatCannotBeWatchedIsAnError) {
  FileLine line(test::scratch_dir() + "/not-a-gpio");
  ASSERT_GE(line.fd(), 0);
  DeadBus bus;
  mpu::Mpu6000 driver(bus, settings_at(1000.0));
  MonotonicClock clock;
  ImuAcquisition acquisition(driver, &line, clock, MountingMap{}, AcquisitionOptions{});
  boost::asio::io_context io;
  AsioAcquisition loop(io, acquisition, [](std::span<const ImuSample>) { return true; });
  const Status st = loop.run();
  ASSERT_FALSE(st.ok());
  // Asio accepts the descriptor and fails the wait on it (epoll cannot watch a regular file).
  EXPECT_NE(st.error().message.find("data-ready line file-line: waiting on its file descriptor failed"),
            std::string::npos)
      << st.error().message;
  // The line keeps its own descriptor.
  EXPECT_EQ(::fcntl(line.fd(), F_GETFD), FD_CLOEXEC);
}

// The driver's unrecoverable error (here: WHO_AM_I wrong after reset) stops the loop, which
// polls on its timer without a line.
TEST(AsioAcquisition, ADriverErrorStopsTheLoop) {
  DeadBus bus;
  mpu::Mpu6000 driver(bus, settings_at(1000.0));
  MonotonicClock clock;
  ImuAcquisition acquisition(driver, nullptr, clock, MountingMap{}, AcquisitionOptions{});
  boost::asio::io_context io;
  AsioAcquisition loop(io, acquisition, [](std::span<const ImuSample>) { return true; });
  boost::asio::steady_timer watchdog(io);
  watchdog.expires_after(60s);
  watchdog.async_wait([&](const boost::system::error_code& ec) {
    if (!ec) loop.stop();
  });
  const Status st = loop.run();
  ASSERT_FALSE(st.ok()) << "the loop ran on after the driver failed";
  EXPECT_NE(st.error().message.find("WHO_AM_I reads 0x00"), std::string::npos) << st.error().message;
  EXPECT_FALSE(loop.watches_line());
  EXPECT_GT(loop.stats().timer_wakeups, 0u);
}

std::string write_config(const std::string& dir) {
  const std::string path = dir + "/rig.yaml";
  std::ofstream out(path);
  out << "name: test\nimu:\n  bus: sim\n  accel_range_g: 4\n  gyro_range_dps: 500\n  rate_hz: 1000\n"
      << "  dlpf_hz: 188\nstorage:\n  backend: file\n  path: " << dir << "/calibration.bin\n";
  return path;
}

void expect_increasing_times(const std::vector<ImuSample>& samples) {
  for (std::size_t i = 1; i < samples.size(); ++i) ASSERT_GT(samples[i].t_ns, samples[i - 1].t_ns) << i;
}

TEST(RecordCliRealtime, RecordsThroughTheEventLoop) {
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_config(dir);
  const std::string log = dir + "/rt.imulog";
  const auto res = test::run_cli(
      {"record", "--config", cfg, "-o", log, "--sim", "--realtime", "--duration", "1", "--json"});
  ASSERT_EQ(res.exit_code, 0) << res.err;
  const auto summary = nlohmann::json::parse(res.out);
  EXPECT_FALSE(summary["interrupted"].get<bool>());
  const RecordedLog rec = read_recorded_log(log);
  EXPECT_TRUE(rec.complete);
  // 1 s of sample time from a chip 1.5 % slow (less what a host stall cost, which is counted).
  EXPECT_NEAR(static_cast<double>(rec.samples.size() + summary["samples_lost"].get<std::size_t>()), 985.0,
              3.0);
  EXPECT_EQ(summary["samples"].get<std::size_t>(), rec.samples.size());
  expect_increasing_times(rec.samples);
  ASSERT_TRUE(rec.metadata.count("sim"));
  EXPECT_TRUE(nlohmann::json::parse(rec.metadata.at("sim"))["realtime"].get<bool>());
  const auto timing = nlohmann::json::parse(rec.metadata.at("imu.timing"));
  EXPECT_LT(2 * timing["batches_without_edge"].get<int>(), timing["batches"].get<int>());
  const auto stream = nlohmann::json::parse(rec.metadata.at("imu.stream"));
  EXPECT_EQ(stream["log_dropped"].get<int>(), 0);
}

TEST(RecordCliRealtime, RealtimeNeedsSim) {
  const std::string dir = test::scratch_dir();
  std::ofstream(dir + "/spi.yaml")
      << "name: test\nimu:\n  bus: spi\n  device: /dev/spidev97.3\n  rate_hz: 1000\n"
      << "storage:\n  backend: file\n  path: " << dir << "/calibration.bin\n";
  const auto res =
      test::run_cli({"record", "--config", dir + "/spi.yaml", "-o", dir + "/x.imulog", "--realtime"});
  EXPECT_EQ(res.exit_code, 2) << res.err;
  EXPECT_NE(res.err.find("--realtime"), std::string::npos) << res.err;
}

/// Waits up to `timeout` for `pid` to exit; its exit status, or nullopt (then it is killed).
std::optional<int> wait_exit(pid_t pid, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) return status;
    std::this_thread::sleep_for(10ms);
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  return std::nullopt;
}

// A signal in the middle of a real-time recording (SIGINT, SIGHUP from a lost ssh session,
// SIGQUIT, or Ctrl-C twice): exit 0 with a note, and a complete log with every sample recorded
// until then.
struct SignalCase {
  int signal;
  int times;
  const char* name;
};

class RecordCliSignal : public ::testing::TestWithParam<SignalCase> {};

TEST_P(RecordCliSignal, EndsWithACompleteLog) {
  const SignalCase sc = GetParam();
  const std::string dir = test::scratch_dir();
  const std::string cfg = write_config(dir);
  const std::string log = dir + "/rt.imulog";
  const std::string out_path = dir + "/stdout", err_path = dir + "/stderr";
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (!std::freopen(out_path.c_str(), "w", stdout) || !std::freopen(err_path.c_str(), "w", stderr))
      _exit(127);
    std::vector<std::string> args = {IMUCAL_CLI_PATH, "record",     "--config",   cfg,  "-o",    log,
                                     "--sim",         "--realtime", "--duration", "30", "--json"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    _exit(127);
  }
  // The log exists once the signal handlers are in place; then let it record for a while.
  const auto deadline = std::chrono::steady_clock::now() + 120s;
  bool exited_early = false;
  while (!std::filesystem::exists(log) && std::chrono::steady_clock::now() < deadline) {
    if (::waitpid(pid, nullptr, WNOHANG) == pid) {
      exited_early = true;
      break;
    }
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_FALSE(exited_early) << test::read_file(err_path);
  ASSERT_TRUE(std::filesystem::exists(log)) << "no log after 120 s";
  std::this_thread::sleep_for(2s);
  for (int i = 0; i < sc.times; ++i) {
    ASSERT_EQ(::kill(pid, sc.signal), 0);
    std::this_thread::sleep_for(1ms);
  }
  const auto status = wait_exit(pid, 120s);
  ASSERT_TRUE(status.has_value()) << "imucal record did not end after " << sc.name;
  const std::string err = test::read_file(err_path);
  ASSERT_TRUE(WIFEXITED(*status)) << "ended by signal " << WTERMSIG(*status) << "\n" << err;
  ASSERT_EQ(WEXITSTATUS(*status), 0) << err;
  EXPECT_NE(err.find(std::string("interrupted by ") + sc.name), std::string::npos) << err;

  const auto summary = nlohmann::json::parse(test::read_file(out_path));
  EXPECT_TRUE(summary["interrupted"].get<bool>());
  const RecordedLog rec = read_recorded_log(log);
  EXPECT_TRUE(rec.complete);
  EXPECT_GT(rec.samples.size(), 0u);
  EXPECT_LT(rec.samples.size(), 29'000u);
  EXPECT_EQ(summary["samples"].get<std::size_t>(), rec.samples.size());
  expect_increasing_times(rec.samples);
  for (const char* key : {"imu.timing", "imu.driver", "imu.stream"})
    EXPECT_TRUE(rec.metadata.count(key)) << key;
  const auto stream = nlohmann::json::parse(rec.metadata.at("imu.stream"));
  EXPECT_EQ(stream["log_dropped"].get<int>(), 0);
  EXPECT_EQ(stream["log_written"].get<std::size_t>(), rec.samples.size());
}

INSTANTIATE_TEST_SUITE_P(Signals, RecordCliSignal,
                         ::testing::Values(SignalCase{SIGINT, 1, "SIGINT"}, SignalCase{SIGHUP, 1, "SIGHUP"},
                                           SignalCase{SIGQUIT, 1, "SIGQUIT"},
                                           SignalCase{SIGINT, 3, "SIGINT"}),
                         [](const ::testing::TestParamInfo<SignalCase>& info) {
                           return std::string(info.param.name) + "x" + std::to_string(info.param.times);
                         });

}  // namespace
}  // namespace imucal::acq
