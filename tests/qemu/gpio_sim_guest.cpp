// SPDX-License-Identifier: BSD-3-Clause
// Runs inside the QEMU guest (tests/qemu/run-in-qemu.sh --module gpio-sim) against the kernel's
// GPIO simulator: GpiodDataReadyLine through libgpiod 1.6 and the GPIO character device (uAPI
// v1) on a real gpiolib, then the acquisition loop with the MPU-6000 emulator's data-ready
// edges made on that line.
//
// gpio-sim is built out of tree by the harness (tests/qemu/build-kmod.sh). A chip is made
// through configfs (/sys/kernel/config/gpio-sim: a bank with 8 lines, line 3 named IMU_DRDY,
// live=1); its lines are inputs whose level follows the simulator's pull, set by writing
// "pull-up" or "pull-down" to /sys/devices/platform/gpio-sim.N/gpiochipM/sim_gpioK/pull. A
// pull-up on a line requested for rising edges raises the simulator's interrupt (irq_sim, an
// irq_work: a self-IPI on x86), and gpiolib's hard interrupt handler stamps the event with
// ktime_get_ns() before the write returns, so each edge's stamp must lie between
// clock_gettime(CLOCK_MONOTONIC) read just before and just after the write.
//
// Part 1, the line: opened by chip and line as a rig configuration names them (parsed by
// parse_rig_config, converted as app/rig/rig.cpp does), by device path and by line name; a line
// that does not exist; a line held by another consumer (requested with libgpiod first) refused
// with the consumer named; wait() timing out; edges one at a time, each stamp inside its write
// (edge-to-event latency and the delay to the reader measured); a burst of 40 edges, one every 20 ms,
// before the reader reads: the kernel's uAPI v1 queue keeps the first 16 and drops the rest
// (uAPI v1 has no sequence numbers), and the line counts the dropped ones from the gap between
// the 16th stamp and the next, so the next edge is numbered 41.
//
// Part 2, the loop: the MPU-6000 register emulator on CLOCK_MONOTONIC, advanced by a ticker
// thread at every sample instant (and by each bus transfer) as sim/realtime.hpp does, raises
// its INT pin by writing pull-up/pull-down to the simulated line, so the edges carry the
// kernel's real stamps, late by the ticker's wake-up. The driver and ImuAcquisition run on the
// Asio event loop watching the line's descriptor, as imucald does. A first run measures the
// edge latency (kernel stamp minus the sample's true time) and sets the timestamper's
// edge_latency_ns and edge_jitter_ns from it (mean and sd, docs/acquisition.md), as a rig's
// platform constants; the second run checks every delivered sample against the emulator's truth
// (tests/support/emulator_accounting.hpp, as the acquisition tests do), with a stall of the
// loop in the middle. A checked run that the host disturbed (the guest held for several
// periods, see paired_checks) is run again, up to 3 times.
//
//   qemu_gpio_sim_guest [RATE_HZ [STALL_PERIODS]]    (ctest: 200 10)
//
// A stall longer than the kernel's 16-edge queue (STALL_PERIODS 40) makes the kernel drop
// edges; the line counts them from the gap after its full queue, and the run checks that they
// are counted as missed and that no sample is misdated (docs/testing-devices.md). IMUCAL_GPIO_SIM_TRACE=1
// prints every sample's time error and every edge taken.
//
// Prints one line per check and the measured figures; exits 0 only when all checks pass.

#include <fcntl.h>
#include <gpiod.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/asio_acquisition.hpp"
#include "acquisition/imu_acquisition.hpp"
#include "core/rig_config.hpp"
#include "core/time.hpp"
#include "drivers/gpio/gpiod_line.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/output_settings.hpp"
#include "tests/support/emulator_accounting.hpp"

namespace {

using imucal::Errc;
using imucal::monotonic_now_ns;
using imucal::TimeNs;
using imucal::drivers::DataReadyEdge;
using imucal::drivers::GpiodDataReadyLine;
using imucal::drivers::GpiodLineOptions;
namespace acq = imucal::acq;
namespace fake = imucal::fake;
namespace mpu = imucal::drivers::mpu6000;

constexpr TimeNs kUs = 1'000;
constexpr TimeNs kMs = 1'000'000;
constexpr unsigned kLines = 8;
constexpr unsigned kDrdyLine = 3;  // the INT pin's line in the rig configuration below
constexpr unsigned kOtherLine = 5;
constexpr std::size_t kKernelQueue = 16;  // uAPI v1 line event queue (gpiolib-cdev.c, Linux 6.1)

int failures = 0;

void check(bool ok, const std::string& what, const std::string& detail = "") {
  std::printf("%s - %s%s%s\n", ok ? "ok" : "FAIL", what.c_str(), detail.empty() ? "" : ": ", detail.c_str());
  std::fflush(stdout);
  if (!ok) ++failures;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::string us(double ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f us", ns / 1e3);
  return buf;
}

// --- figures ----------------------------------------------------------------------------------

struct Stats {
  std::size_t n = 0;
  double mean = 0, sd = 0, min = 0, p10 = 0, p25 = 0, median = 0, p75 = 0, p90 = 0, p99 = 0, max = 0;
  double robust_sd = 0;  // 1.4826 x the median absolute deviation: the core's spread, tails ignored
};

Stats stats_of(std::vector<double> v) {
  Stats s;
  s.n = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0, sum2 = 0;
  for (double x : v) sum += x;
  s.mean = sum / static_cast<double>(v.size());
  for (double x : v) sum2 += (x - s.mean) * (x - s.mean);
  s.sd = std::sqrt(sum2 / static_cast<double>(v.size()));
  auto q = [&](double f) {
    return v[std::min(v.size() - 1, static_cast<std::size_t>(f * static_cast<double>(v.size())))];
  };
  s.min = v.front();
  s.p10 = q(0.10);
  s.p25 = q(0.25);
  s.median = q(0.5);
  s.p75 = q(0.75);
  s.p90 = q(0.90);
  s.p99 = q(0.99);
  s.max = v.back();
  std::vector<double> dev;
  for (double x : v) dev.push_back(std::abs(x - s.median));
  std::sort(dev.begin(), dev.end());
  s.robust_sd = 1.4826 * dev[dev.size() / 2];
  return s;
}

std::string describe(const Stats& s) {
  return "n " + std::to_string(s.n) + ", min " + us(s.min) + ", p10 " + us(s.p10) + ", median " +
         us(s.median) + ", p90 " + us(s.p90) + ", p99 " + us(s.p99) + ", max " + us(s.max) + "; mean " +
         us(s.mean) + ", sd " + us(s.sd) + ", robust sd " + us(s.robust_sd);
}

// --- the simulated chip -----------------------------------------------------------------------

std::string read_text(const std::string& path) {
  std::string out;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return out;
  char buf[256];
  ssize_t n = 0;
  while ((n = ::read(fd, buf, sizeof buf)) > 0) out.append(buf, static_cast<std::size_t>(n));
  ::close(fd);
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

// Empty on success, else what failed.
std::string write_text(const std::string& path, const std::string& text) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return "open " + path + ": " + std::strerror(errno);
  const ssize_t n = ::write(fd, text.data(), text.size());
  const int err = errno;
  ::close(fd);
  if (n != static_cast<ssize_t>(text.size()))
    return "write '" + text + "' to " + path + ": " + std::strerror(err);
  return {};
}

std::string make_dir(const std::string& path) {
  if (::mkdir(path.c_str(), 0755) != 0) return "mkdir " + path + ": " + std::strerror(errno);
  return {};
}

// A gpio-sim chip made through configfs: one bank of kLines lines, kDrdyLine named IMU_DRDY.
struct SimChip {
  std::string config;  // /sys/kernel/config/gpio-sim/<name>
  std::string chip;    // gpiochipN
  std::string sysfs;   // /sys/devices/platform/gpio-sim.M/gpiochipN

  std::string pull_path(unsigned line) const { return sysfs + "/sim_gpio" + std::to_string(line) + "/pull"; }
};

std::optional<SimChip> make_sim_chip(std::string& error) {
  const std::string root = "/sys/kernel/config/gpio-sim";
  struct stat st {};
  if (::stat(root.c_str(), &st) != 0) {
    error = root + " missing: gpio-sim not loaded or configfs not mounted";
    return std::nullopt;
  }
  SimChip c;
  c.config = root + "/imucal";
  const std::string bank = c.config + "/bank0";
  const std::string line = bank + "/line" + std::to_string(kDrdyLine);
  for (const std::string& step :
       {make_dir(c.config), make_dir(bank), write_text(bank + "/num_lines", std::to_string(kLines)),
        write_text(bank + "/label", "imucal-sim"), make_dir(line), write_text(line + "/name", "IMU_DRDY"),
        write_text(c.config + "/live", "1")}) {
    if (!step.empty()) {
      error = step;
      return std::nullopt;
    }
  }
  const std::string dev = read_text(c.config + "/dev_name");
  c.chip = read_text(bank + "/chip_name");
  c.sysfs = "/sys/devices/platform/" + dev + "/" + c.chip;
  if (dev.empty() || c.chip.empty()) {
    error = "configfs gave no dev_name/chip_name";
    return std::nullopt;
  }
  return c;
}

// The simulator's pull attribute of one line, kept open: pull-up makes a rising edge on an
// input, pull-down the falling one.
class Pull {
 public:
  explicit Pull(const std::string& path) : fd_(::open(path.c_str(), O_WRONLY | O_CLOEXEC)) {}
  ~Pull() {
    if (fd_ >= 0) ::close(fd_);
  }
  Pull(const Pull&) = delete;
  Pull& operator=(const Pull&) = delete;
  bool ok() const { return fd_ >= 0; }
  bool up() { return put("pull-up"); }
  bool down() { return put("pull-down"); }

 private:
  bool put(const std::string& v) {
    return ::pwrite(fd_, v.data(), v.size(), 0) == static_cast<ssize_t>(v.size());
  }
  int fd_ = -1;
};

// A rising edge made by a pull-up write, with CLOCK_MONOTONIC read just before and after it.
struct EdgeWindow {
  TimeNs before = 0;
  TimeNs after = 0;
  TimeNs true_t = 0;  // part 2: the emulated sample's true time
};

EdgeWindow pulse(Pull& pull) {
  EdgeWindow w;
  w.before = monotonic_now_ns();
  const bool up = pull.up();
  w.after = monotonic_now_ns();
  const bool down = pull.down();
  if (!up || !down) w.after = -1;  // reported by the caller
  return w;
}

// --- part 1: the line -------------------------------------------------------------------------

GpiodLineOptions options_from_rig_config(const std::string& chip) {
  // The rig configuration's keys, converted as app/rig/rig.cpp does (the line is an offset).
  const std::string yaml = "imu:\n  bus: spi\n  device: /dev/spidev0.0\n  data_ready:\n    chip: " + chip +
                           "\n    line: " + std::to_string(kDrdyLine) + "\n";
  auto config = imucal::parse_rig_config(yaml, "rig.yaml");
  GpiodLineOptions o;
  check(config.ok() && config->imu.data_ready.has_value(), "rig configuration with imu.data_ready parsed",
        config.ok() ? "" : config.error().message);
  if (config.ok() && config->imu.data_ready) {
    o.chip = config->imu.data_ready->chip;
    o.line = std::to_string(config->imu.data_ready->line);
  }
  return o;
}

std::string consumer_of(const std::string& chip, unsigned offset) {
  gpiod_chip* c = gpiod_chip_open_lookup(chip.c_str());
  if (c == nullptr) return "(chip not opened)";
  std::string out = "(none)";
  gpiod_line* l = gpiod_chip_get_line(c, offset);
  if (l != nullptr && gpiod_line_update(l) == 0 && gpiod_line_consumer(l) != nullptr)
    out = gpiod_line_consumer(l);
  gpiod_chip_close(c);
  return out;
}

void open_checks(const SimChip& sim) {
  const GpiodLineOptions from_config = options_from_rig_config(sim.chip);
  {
    auto line = GpiodDataReadyLine::open(from_config);
    check(line.ok(),
          "open " + from_config.chip + " line " + from_config.line + " as the rig configuration names it",
          line.ok() ? (*line)->name() : line.error().message);
    if (line.ok()) {
      check((*line)->name() == sim.chip + ":" + std::to_string(kDrdyLine), "its name is chip:offset",
            (*line)->name());
      check((*line)->event_clock() == imucal::drivers::GpioEventClock::kMonotonic,
            "event clock CLOCK_MONOTONIC on this kernel (6.1)");
      check((*line)->fd() >= 0, "the line has an event descriptor", std::to_string((*line)->fd()));
      const std::string consumer = consumer_of(sim.chip, kDrdyLine);
      check(consumer == "imucal", "gpioinfo's view: the line is used by 'imucal'", consumer);
      // The same line again, as a second imucal would: refused, naming the holder.
      auto again = GpiodDataReadyLine::open(from_config);
      check(!again.ok() && again.error().code == Errc::kDevice &&
                contains(again.error().message, "held by 'imucal'"),
            "a second open of the held line is refused naming 'imucal'",
            again.ok() ? "opened" : again.error().message);
    }
  }
  check(consumer_of(sim.chip, kDrdyLine) == "(none)", "closing the line releases it");

  GpiodLineOptions by_path{"/dev/" + sim.chip, std::to_string(kDrdyLine), "imucal"};
  auto path_line = GpiodDataReadyLine::open(by_path);
  check(path_line.ok(), "open by device path " + by_path.chip,
        path_line.ok() ? "" : path_line.error().message);
  path_line = imucal::make_error(Errc::kInternal, "closed");  // releases the line

  GpiodLineOptions by_name{sim.chip, "IMU_DRDY", "imucal"};
  auto named = GpiodDataReadyLine::open(by_name);
  check(named.ok() && (*named)->name() == sim.chip + ":" + std::to_string(kDrdyLine),
        "open by line name IMU_DRDY finds offset " + std::to_string(kDrdyLine),
        named.ok() ? (*named)->name() : named.error().message);
  named = imucal::make_error(Errc::kInternal, "closed");

  GpiodLineOptions beyond{sim.chip, std::to_string(kLines), "imucal"};
  auto missing = GpiodDataReadyLine::open(beyond);
  check(!missing.ok() && missing.error().code == Errc::kNotFound &&
            contains(missing.error().message, "0..7") &&
            contains(missing.error().message, "imu.data_ready.line"),
        "line 8 of an 8-line chip: not found, the valid offsets and the configuration keys named",
        missing.ok() ? "opened" : missing.error().message);
  GpiodLineOptions no_name{sim.chip, "NO_SUCH_LINE", "imucal"};
  auto unnamed = GpiodDataReadyLine::open(no_name);
  check(!unnamed.ok() && unnamed.error().code == Errc::kNotFound &&
            contains(unnamed.error().message, "NO_SUCH_LINE"),
        "an unknown line name: not found, named", unnamed.ok() ? "opened" : unnamed.error().message);

  // Another program holds the line (requested with libgpiod as an input, as gpiomon or a
  // second daemon would): refused with the errno text and the holder, then usable once freed.
  gpiod_chip* chip = gpiod_chip_open_lookup(sim.chip.c_str());
  gpiod_line* other = chip != nullptr ? gpiod_chip_get_line(chip, kDrdyLine) : nullptr;
  const bool held = other != nullptr && gpiod_line_request_input(other, "other-daq") == 0;
  check(held, "another consumer 'other-daq' requests line " + std::to_string(kDrdyLine));
  auto busy = GpiodDataReadyLine::open(from_config);
  check(!busy.ok() && busy.error().code == Errc::kDevice &&
            contains(busy.error().message, "Device or resource busy") &&
            contains(busy.error().message, "(held by 'other-daq'; stop it first)"),
        "a line held by another consumer is refused: busy, held by 'other-daq'; stop it first",
        busy.ok() ? "opened" : busy.error().message);
  if (other != nullptr) gpiod_line_release(other);
  if (chip != nullptr) gpiod_chip_close(chip);
  auto freed = GpiodDataReadyLine::open(from_config);
  check(freed.ok(), "the same line opens once the other consumer released it",
        freed.ok() ? "" : freed.error().message);
}

void wait_checks(GpiodDataReadyLine& line) {
  auto negative = line.wait(-1);
  check(!negative.ok() && negative.error().code == Errc::kInvalidArgument, "wait(-1) is an invalid argument");
  const TimeNs t0 = monotonic_now_ns();
  auto none = line.wait(100 * kMs);
  const TimeNs waited = monotonic_now_ns() - t0;
  check(none.ok() && !none->has_value() && waited >= 100 * kMs, "wait(100 ms) without an edge times out",
        "after " + us(static_cast<double>(waited)));
}

void single_edges(GpiodDataReadyLine& line, Pull& pull, Pull& other_pull, int n) {
  std::vector<double> a, b, c;
  int outside = 0, bad_seq = 0, missing = 0, falling = 0, write_errors = 0;
  std::uint64_t last_seq = 0;
  TimeNs last_t = 0;
  bool increasing = true;
  for (int i = 0; i < n; ++i) {
    // A pulse on another line of the same chip must not reach this line.
    if (i % 10 == 0) write_errors += pulse(other_pull).after < 0;
    const EdgeWindow w = pulse(pull);
    if (w.after < 0) ++write_errors;
    auto e = line.wait(imucal::kNsPerSecond);
    const TimeNs read_t = monotonic_now_ns();
    if (!e.ok() || !e->has_value()) {
      ++missing;
      continue;
    }
    const DataReadyEdge edge = **e;
    if (edge.t_ns < w.before || edge.t_ns > w.after) ++outside;
    if (edge.sequence != last_seq + 1) ++bad_seq;
    if (last_t != 0 && edge.t_ns <= last_t) increasing = false;
    last_seq = edge.sequence;
    last_t = edge.t_ns;
    a.push_back(static_cast<double>(edge.t_ns - w.before));
    b.push_back(static_cast<double>(w.after - edge.t_ns));
    c.push_back(static_cast<double>(read_t - edge.t_ns));
    // The falling edge (pull-down) is not requested: nothing more is pending.
    auto more = line.wait(0);
    if (!more.ok() || more->has_value()) ++falling;
  }
  check(write_errors == 0, "writes to sim_gpio" + std::to_string(kDrdyLine) + "/pull and sim_gpio" +
                               std::to_string(kOtherLine) + "/pull succeed");
  check(missing == 0, std::to_string(n) + " pull-ups, each read as one rising edge",
        std::to_string(missing) + " missing");
  check(falling == 0,
        "no event for the falling edges (pull-down) nor for pulses on line " + std::to_string(kOtherLine));
  check(bad_seq == 0 && increasing, "sequence 1.." + std::to_string(n) + ", timestamps strictly increasing");
  check(outside == 0,
        "every kernel stamp lies between CLOCK_MONOTONIC read before and after its pull-up write",
        std::to_string(outside) + " outside");
  std::printf("  edge-to-event latency (write start -> kernel stamp): %s\n", describe(stats_of(a)).c_str());
  std::printf("  kernel stamp -> write returned: %s\n", describe(stats_of(b)).c_str());
  std::printf("  kernel stamp -> wait() returned it: %s\n", describe(stats_of(c)).c_str());
}

void sleep_until(TimeNs t_ns) {
  timespec ts{static_cast<time_t>(t_ns / imucal::kNsPerSecond),
              static_cast<long>(t_ns % imucal::kNsPerSecond)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void burst_checks(GpiodDataReadyLine& line, Pull& pull) {
  // 40 edges, one every 20 ms, written without reading: more than the kernel's queue holds. It
  // keeps the first 16 and drops the other 24 until it is read. The line reads the full queue;
  // the next edge, made on the same grid after the reads, is 25 periods after edge 16 (the
  // median interval of the 16), so the line counts 24 dropped and numbers it 41 after the burst.
  // A pulse written half a grid step off its slot would make the count wrong. The host holds the
  // guest for up to about 6 ms several times a second (most bursts on a 2 ms grid met one),
  // hence the 20 ms grid; a burst with a pulse more than 5 ms off is reported and made again,
  // up to 3 times.
  constexpr int kBurst = 40;
  constexpr TimeNs kGrid = 20 * kMs;
  constexpr int kAttempts = 3;
  for (int attempt = 1; attempt <= kAttempts; ++attempt) {
    const std::uint64_t dropped_before = line.stats().edges_dropped;
    std::uint64_t last_seq = 0;
    {
      // The line's number so far: one pulse read promptly.
      const EdgeWindow w = pulse(pull);
      auto e = line.wait(imucal::kNsPerSecond);
      if (!e.ok() || !e->has_value() || (*e)->t_ns < w.before || (*e)->t_ns > w.after) {
        check(false, "an edge before the burst");
        return;
      }
      last_seq = (*e)->sequence;
    }
    const TimeNs t0 = monotonic_now_ns() + kGrid;
    std::vector<EdgeWindow> windows;
    TimeNs off_grid = 0;
    for (int i = 0; i < kBurst; ++i) {
      const TimeNs slot = t0 + i * kGrid;
      sleep_until(slot);
      windows.push_back(pulse(pull));
      off_grid = std::max(off_grid, windows.back().before - slot);
    }
    std::vector<DataReadyEdge> got;
    for (;;) {
      auto e = line.wait(0);
      if (!e.ok() || !e->has_value()) break;
      got.push_back(**e);
    }
    const TimeNs next_slot = t0 + kBurst * kGrid;
    sleep_until(next_slot);
    const EdgeWindow w = pulse(pull);
    off_grid = std::max(off_grid, w.before - next_slot);
    auto next = line.wait(imucal::kNsPerSecond);
    if (off_grid > kGrid / 4 && attempt < kAttempts) {
      std::printf(
          "  NOTE: the host held the guest: a pulse of the burst came %s off its slot (attempt %d of %d)\n",
          us(static_cast<double>(off_grid)).c_str(), attempt, kAttempts);
      continue;
    }
    bool first_kept = got.size() == kKernelQueue;
    for (std::size_t i = 0; first_kept && i < got.size(); ++i) {
      first_kept = got[i].t_ns >= windows[i].before && got[i].t_ns <= windows[i].after &&
                   got[i].sequence == last_seq + 1 + i;
    }
    check(first_kept,
          std::to_string(kBurst) +
              " edges every 20 ms before the reader reads: the kernel queue keeps the first " +
              std::to_string(kKernelQueue) + " (stamps inside edges 1..16, sequence continuous)",
          std::to_string(got.size()) + " read");
    const bool ok = next.ok() && next->has_value() && !got.empty();
    const std::uint64_t expected = last_seq + kBurst + 1;
    if (ok && (*next)->sequence != expected && attempt < kAttempts) {
      // Seen once in a full suite run on 2 loaded cores: the line's period, measured from the
      // edges as the guest wrote them, was 2 % long and the count came out one short.
      std::printf(
          "  NOTE: the count after the burst was %lld, not %d, with pulses up to %s off their slots "
          "(attempt %d of %d): made again\n",
          static_cast<long long>((*next)->sequence - last_seq), kBurst + 1,
          us(static_cast<double>(off_grid)).c_str(), attempt, kAttempts);
      continue;
    }
    check(ok && (*next)->sequence == expected && (*next)->t_ns >= w.before && (*next)->t_ns <= w.after,
          "the next edge is numbered " + std::to_string(kBurst + 1) +
              " after the burst: the line counts the " +
              std::to_string(kBurst - static_cast<int>(kKernelQueue)) +
              " the kernel dropped from the gap after its full queue",
          ok ? "numbered " + std::to_string(static_cast<long long>((*next)->sequence - last_seq)) + ", gap " +
                   us(static_cast<double>((*next)->t_ns - got.back().t_ns)) + ", pulses up to " +
                   us(static_cast<double>(off_grid)) + " off their slots"
             : "no edge");
    const std::uint64_t counted = line.stats().edges_dropped - dropped_before;
    check(counted == kBurst - kKernelQueue,
          "the line's count of dropped edges rose by " +
              std::to_string(kBurst - static_cast<int>(kKernelQueue)),
          std::to_string(counted));
    return;
  }
}

// --- part 2: the emulator's sample times on the real line --------------------------------------

// Records every edge the acquisition takes from the real line.
class RecordingLine final : public imucal::drivers::DataReadyLine {
 public:
  explicit RecordingLine(GpiodDataReadyLine& line) : line_(line) {}
  imucal::Result<std::optional<DataReadyEdge>> wait(TimeNs timeout_ns) override {
    auto e = line_.wait(timeout_ns);
    if (e.ok() && e->has_value()) edges.push_back(**e);
    return e;
  }
  int fd() const override { return line_.fd(); }
  std::string name() const override { return line_.name(); }
  std::vector<DataReadyEdge> edges;

 private:
  GpiodDataReadyLine& line_;
};

// The emulator on CLOCK_MONOTONIC (sim/realtime.hpp's arrangement) with its INT pin on the
// simulated GPIO line.
class PairedRig {
 public:
  PairedRig(const mpu::Settings& settings, Pull& pull)
      : emulator_(imucal::emutest::wobble, emulator_options()),
        pull_(pull),
        bus_(*this),
        driver_(bus_, settings) {
    emulator_.set_interrupt_sink([this](TimeNs true_t) {
      EdgeWindow w = pulse(pull_);
      w.true_t = true_t;
      interrupts_.push_back(w);
    });
  }
  ~PairedRig() { stop_ticker(); }

  imucal::Status start() {
    IMUCAL_TRY(driver_.probe());
    ticker_ = std::thread([this] { tick_loop(); });
    return {};
  }
  void stop_ticker() {
    stop_.store(true);
    if (ticker_.joinable()) ticker_.join();
  }
  mpu::Mpu6000& driver() { return driver_; }
  // After stop_ticker() only.
  const fake::Mpu6000Emulator& emulator() const { return emulator_; }
  const std::vector<EdgeWindow>& interrupts() const { return interrupts_; }

 private:
  static fake::EmulatorOptions emulator_options() {
    fake::EmulatorOptions o;
    o.timing.enabled = false;  // transfers take real time
    o.start_ns = monotonic_now_ns();
    o.record_truth = true;
    return o;
  }

  class Bus final : public imucal::drivers::RegisterBus {
   public:
    explicit Bus(PairedRig& rig) : rig_(rig) {}
    imucal::Status read(std::uint8_t reg, std::span<std::uint8_t> out) override {
      std::lock_guard<std::mutex> lock(rig_.mutex_);
      rig_.emulator_.advance_to(monotonic_now_ns());
      return rig_.emulator_.read(reg, out);
    }
    imucal::Status write(std::uint8_t reg, std::uint8_t value) override {
      std::lock_guard<std::mutex> lock(rig_.mutex_);
      rig_.emulator_.advance_to(monotonic_now_ns());
      return rig_.emulator_.write(reg, value);
    }
    void set_speed_hz(std::uint32_t hz) override {
      std::lock_guard<std::mutex> lock(rig_.mutex_);
      rig_.emulator_.set_speed_hz(hz);
    }
    std::string name() const override { return "sim-mpu6000 (INT on gpio-sim)"; }
    const imucal::drivers::BusCounters& counters() const override { return rig_.emulator_.counters(); }

   private:
    PairedRig& rig_;
  };

  void tick_loop() {
    while (!stop_.load()) {
      const TimeNs now = monotonic_now_ns();
      TimeNs next = 0;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        emulator_.advance_to(now);
        next = emulator_.next_event_ns();
      }
      const TimeNs wake = std::min(now + kMs, next);
      timespec ts{static_cast<time_t>(wake / imucal::kNsPerSecond),
                  static_cast<long>(wake % imucal::kNsPerSecond)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
    }
  }

  std::mutex mutex_;  // the emulator, the pull writes and interrupts_
  fake::Mpu6000Emulator emulator_;
  Pull& pull_;
  Bus bus_;
  mpu::Mpu6000 driver_;
  std::vector<EdgeWindow> interrupts_;
  std::atomic<bool> stop_{false};
  std::thread ticker_;
};

struct PairedRun {
  bool ok = false;
  std::vector<imucal::ImuSample> samples;
  imucal::emutest::Accounting acc;
  acq::TimestamperStats ts;
  acq::AcquisitionStats acquisition;
  mpu::Counters driver;
  Stats latency;            // kernel stamp - true sample time
  std::size_t matched = 0;  // edges taken whose stamp lies inside a pulse's write
  std::size_t outside = 0;  // edges taken that lie inside none
  Stats error;              // reconstructed - true sample time, after the settling time
  TimeNs stall_ns = 0;      // the loop's stall, measured
  TimeNs stall_t = 0;       // when it began (CLOCK_MONOTONIC)
  std::size_t edges_made = 0;
  TimeNs max_pulse_late_ns = 0;   // the latest pulse: its write's start minus its sample's true time
  std::vector<double> latencies;  // of the edges taken, ns
  std::vector<double> errors;     // of the samples after the settling time, ns
  std::vector<TimeNs> error_t;    // their true times
};

PairedRun run_paired(GpiodDataReadyLine& line, Pull& pull, const mpu::Settings& settings,
                     const acq::AcquisitionOptions& options, TimeNs run_ns, TimeNs stall_at_ns,
                     TimeNs stall_ns) {
  PairedRun r;
  // Edges left from part 1 or an earlier run must not reach this one.
  while (true) {
    auto e = line.wait(0);
    if (!e.ok() || !e->has_value()) break;
  }
  RecordingLine recording(line);
  PairedRig rig(settings, pull);
  if (auto st = rig.start(); !st.ok()) {
    check(false, "emulated MPU-6000 probe", st.error().message);
    return r;
  }
  acq::MonotonicClock clock;
  acq::ImuAcquisition acquisition(rig.driver(), &recording, clock, acq::MountingMap{}, options);
  boost::asio::io_context io;
  const TimeNs t_start = monotonic_now_ns();
  bool stalled = false;
  acq::AsioAcquisition loop(io, acquisition, [&](std::span<const imucal::ImuSample> s) {
    r.samples.insert(r.samples.end(), s.begin(), s.end());
    if (stall_ns > 0 && !stalled && monotonic_now_ns() - t_start >= stall_at_ns) {
      stalled = true;
      const TimeNs t0 = monotonic_now_ns();
      std::this_thread::sleep_for(std::chrono::nanoseconds(stall_ns));
      r.stall_ns = monotonic_now_ns() - t0;
      r.stall_t = t0;
    }
    return true;
  });
  boost::asio::steady_timer end(io);
  end.expires_after(std::chrono::nanoseconds(run_ns));
  end.async_wait([&](const boost::system::error_code& ec) {
    if (!ec) loop.stop();
  });
  const imucal::Status st = loop.run();
  rig.stop_ticker();
  check(st.ok(), "the event loop ran without an error", st.ok() ? "" : st.error().message);
  if (!st.ok()) return r;

  r.acc = imucal::emutest::account(r.samples, rig.emulator());
  r.ts = acquisition.timestamper().stats();
  r.acquisition = acquisition.stats();
  r.driver = rig.driver().counters();
  r.edges_made = rig.interrupts().size();
  for (const EdgeWindow& w : rig.interrupts())
    r.max_pulse_late_ns = std::max(r.max_pulse_late_ns, w.before - w.true_t);
  // Each edge taken belongs to the pulse whose write its stamp lies in (the writes follow one
  // another under the emulator's lock, so the windows do not overlap); pulses left without an
  // edge are the ones the kernel dropped.
  std::vector<double> lat;
  const auto& pulses = rig.interrupts();
  for (const DataReadyEdge& e : recording.edges) {
    auto it = std::lower_bound(pulses.begin(), pulses.end(), e.t_ns,
                               [](const EdgeWindow& w, TimeNs t) { return w.after < t; });
    if (it == pulses.end() || e.t_ns < it->before) {
      ++r.outside;
      continue;
    }
    ++r.matched;
    lat.push_back(static_cast<double>(e.t_ns - it->true_t));
  }
  r.latency = stats_of(lat);
  r.latencies = lat;

  // Reconstruction error per sample, matched to the frames the chip wrote as account() does.
  std::vector<const fake::TruthSample*> fifo;
  for (const auto& t : rig.emulator().truth()) {
    if (t.to_fifo) fifo.push_back(&t);
  }
  auto same = [](const imucal::ImuSample& a, const fake::TruthSample& b) {
    return a.accel == Eigen::Vector3d(b.accel[0], b.accel[1], b.accel[2]) &&
           a.gyro == Eigen::Vector3d(b.gyro[0], b.gyro[1], b.gyro[2]) && a.temperature == b.temp;
  };
  std::vector<double> err;
  std::size_t j = 0;
  TimeNs first_t = -1;
  for (const imucal::ImuSample& s : r.samples) {
    std::size_t k = j;
    while (k < fifo.size() && !same(s, *fifo[k])) ++k;
    if (k == fifo.size()) continue;
    j = k + 1;
    if (first_t < 0) first_t = fifo[k]->t_ns;
    if (fifo[k]->t_ns - first_t < imucal::kNsPerSecond / 2) continue;  // account()'s settling time
    err.push_back(static_cast<double>(s.t_ns - fifo[k]->t_ns));
    r.error_t.push_back(fifo[k]->t_ns);
  }
  r.error = stats_of(err);
  r.errors = err;
  if (std::getenv("IMUCAL_GPIO_SIM_TRACE") != nullptr) {
    // One line per delivered sample: true time since the first, error, flags; then the edges.
    std::size_t jj = 0;
    for (const imucal::ImuSample& s : r.samples) {
      std::size_t k = jj;
      while (k < fifo.size() && !same(s, *fifo[k])) ++k;
      if (k == fifo.size()) continue;
      jj = k + 1;
      std::printf("T sample %.3f ms error %.1f us flags 0x%x\n",
                  static_cast<double>(fifo[k]->t_ns - first_t) / 1e6,
                  static_cast<double>(s.t_ns - fifo[k]->t_ns) / 1e3, s.flags);
    }
    for (const DataReadyEdge& e : recording.edges)
      std::printf("T edge %llu at %.3f ms\n", static_cast<unsigned long long>(e.sequence),
                  static_cast<double>(e.t_ns - first_t) / 1e6);
  }
  r.ok = true;
  return r;
}

void print_run(const char* what, const PairedRun& r) {
  std::printf(
      "  %s: %zu pulses, %llu edges taken, %zu samples delivered, %zu lost, %zu in the FIFO, %llu batches "
      "(%llu without an edge), edges accepted %llu rejected %llu, gaps %llu, re-anchors %llu, samples lost "
      "(timestamper) %llu, missed data-ready (driver) %llu, FIFO resets %llu\n",
      what, r.edges_made, static_cast<unsigned long long>(r.acquisition.edges), r.acc.delivered, r.acc.lost,
      r.acc.still_in_fifo, static_cast<unsigned long long>(r.acquisition.batches),
      static_cast<unsigned long long>(r.acquisition.batches_without_edge),
      static_cast<unsigned long long>(r.ts.edges_accepted),
      static_cast<unsigned long long>(r.ts.edges_rejected), static_cast<unsigned long long>(r.ts.gaps),
      static_cast<unsigned long long>(r.ts.reanchors), static_cast<unsigned long long>(r.ts.samples_lost),
      static_cast<unsigned long long>(r.driver.missed_data_ready),
      static_cast<unsigned long long>(r.driver.fifo_resets));
  std::printf("  %s: edge latency (kernel stamp - true sample time): %s\n", what,
              describe(r.latency).c_str());
  std::printf("  %s: reconstructed - true sample time: %s; rms %s (account), max |error| %s\n", what,
              describe(r.error).c_str(), us(r.acc.rms_time_error_ns).c_str(),
              us(r.acc.max_time_error_ns).c_str());
}

void paired_checks(GpiodDataReadyLine& line, Pull& pull, double rate_hz, int stall_periods) {
  mpu::OutputRequest request;
  request.rate_hz = rate_hz;
  auto settings = mpu::settings_for(request);
  check(settings.ok(), "MPU-6000 settings for " + std::to_string(static_cast<int>(rate_hz)) + " Hz",
        settings.ok() ? "" : settings.error().message);
  if (!settings.ok()) return;
  const TimeNs period = settings->sample_period_ns();
  const double p_us = static_cast<double>(period) / 1e3;

  // Run 1: the platform's edge latency, measured (timestamper defaults; its output is not
  // checked here).
  constexpr TimeNs kLatencyRun = 1500 * kMs;
  const PairedRun cal = run_paired(line, pull, *settings, acq::AcquisitionOptions{}, kLatencyRun, 0, 0);
  if (!cal.ok) return;
  print_run("latency run", cal);
  // 1.5 s less the chip's reset; the host may make the kernel drop a few (see run 2).
  const auto expected = static_cast<std::size_t>(rate_hz);
  check(cal.outside == 0 && cal.matched >= expected,
        "every edge taken is stamped inside the write of one of the emulator's pulses",
        std::to_string(cal.matched) + " of " + std::to_string(cal.acquisition.edges) + " inside, " +
            std::to_string(cal.edges_made) + " pulses");
  check(cal.latency.min > 0, "every edge stamped after its sample's true time", describe(cal.latency));

  // Run 2: the timestamper set up with the measured latency as a rig's platform constants, by
  // the rule of docs/acquisition.md: edge_latency_ns the mean latency, edge_jitter_ns its
  // standard deviation. The latency here is skewed: a core of a few hundred microseconds (the
  // ticker thread's wake-up and the write) and a tail to milliseconds while the guest runs
  // slowly; its sd is therefore large and the gate (5 sd) passes most of the tail. In the middle
  // the loop stalls for `stall_periods` periods: the edges pile up in the kernel's queue (16)
  // and the samples in the FIFO (watermark: 64 frames).
  acq::AcquisitionOptions options;
  options.timestamps.edge_latency_ns = static_cast<TimeNs>(std::llround(cal.latency.mean));
  options.timestamps.edge_jitter_ns =
      std::max<TimeNs>(kUs, static_cast<TimeNs>(std::llround(cal.latency.sd)));
  std::printf("  timestamper: edge_latency_ns %lld, edge_jitter_ns %lld\n",
              static_cast<long long>(options.timestamps.edge_latency_ns),
              static_cast<long long>(options.timestamps.edge_jitter_ns));
  const TimeNs stall = stall_periods * period;
  constexpr TimeNs kCheckedRun = 3000 * kMs;

  // The host can hold the whole guest (QEMU's thread descheduled on shared cores): the guest's
  // clock jumps and the emulated chip makes the pulses it missed in one late burst, which a
  // rig's chip never does. Edges several periods late read to the timestamper as samples lost
  // (after max_consecutive_rejects, 4, in a row), and past 16 periods the kernel drops edges,
  // which the line counts from the gap after its full queue (STALL_PERIODS above 16). A run in which a
  // pulse came more than 3 periods late, or the kernel dropped edges the stall does not
  // explain (about S - 16 for a stall of S periods, none for a stall within the queue), is
  // reported and run again, up to 3 times.
  const std::size_t from_stall = stall_periods > static_cast<int>(kKernelQueue)
                                     ? static_cast<std::size_t>(stall_periods) - kKernelQueue
                                     : 0;
  constexpr int kAttempts = 3;
  PairedRun run;
  std::size_t dropped = 0;
  bool held = true;
  for (int attempt = 1; attempt <= kAttempts && held; ++attempt) {
    run = run_paired(line, pull, *settings, options, kCheckedRun, 1500 * kMs, stall);
    if (!run.ok) return;
    print_run("checked run", run);
    dropped = run.edges_made - run.matched;  // pulses the line never delivered
    std::printf("  stall %s (%.1f periods); edges the kernel dropped: %zu of %zu (%zu from the stall)\n",
                us(static_cast<double>(run.stall_ns)).c_str(),
                static_cast<double>(run.stall_ns) / static_cast<double>(period), dropped, run.edges_made,
                from_stall);
    // A stall past the queue drops about S - 16 edges (one more or less by timing); a stall
    // within it drops none, so that any drop there was the host's (an edge lost without the
    // queue's overflow leaves no gap for the line to count: seen once with a 10-period stall).
    held = run.max_pulse_late_ns > 3 * period || dropped > from_stall + (from_stall > 0 ? 1 : 0);
    if (held) {
      std::printf(
          "  NOTE: the host held the guest: a pulse came %s after its sample, %zu edges dropped beyond the "
          "stall's (attempt %d of %d)\n",
          us(static_cast<double>(run.max_pulse_late_ns)).c_str(),
          dropped > from_stall ? dropped - from_stall : 0, attempt, kAttempts);
    }
  }
  const auto& a = run.acc;
  check(a.delivered >= static_cast<std::size_t>(rate_hz * 2.5) && a.mismatched == 0,
        "every delivered sample is a frame the chip wrote, in order",
        std::to_string(a.delivered) + " delivered, " + std::to_string(a.mismatched) + " not");
  check(run.stall_ns >= stall, "the loop stalled for " + std::to_string(stall_periods) + " periods",
        us(static_cast<double>(run.stall_ns)));
  check(a.delivered + a.lost + a.still_in_fifo == a.produced && a.lost == 0 && a.unflagged_losses == 0,
        "no frame lost across the stall (the FIFO held them)", std::to_string(a.lost) + " lost");
  check(run.outside == 0, "every edge taken is stamped inside one of the pulses' writes");
  if (held) {
    std::printf("  NOTE: the host disturbed every checked run; the sample-time checks are left out\n");
    return;
  }
  check(run.driver.missed_data_ready == dropped, "edges the kernel dropped are counted as missed data-ready",
        std::to_string(run.driver.missed_data_ready) + " counted, " + std::to_string(dropped) + " dropped");
  // A run of late edges (four beyond the gate) makes the timestamper re-anchor and flag a gap,
  // as designed; a gap for any other reason, or a sample counted lost, is wrong here.
  check(run.ts.samples_lost == 0 && run.ts.gaps == run.ts.reanchors && a.gap_flags == run.ts.gaps,
        "no sample counted lost; gaps flagged only where late edges made the timestamper re-anchor",
        std::to_string(run.ts.samples_lost) + " counted lost, " + std::to_string(run.ts.gaps) + " gaps, " +
            std::to_string(run.ts.reanchors) + " re-anchors");

  // Time reconstruction against the chip's truth (after account()'s 0.5 s settling). The
  // constant subtracted is run 1's mean latency. The sample times follow the edges the filter
  // uses: of several pending edges only the newest (the least late), and of those the ones
  // inside the gate, so their offset lies between this run's median latency and its mean, less
  // that constant (the latency may also have moved since run 1 with the host's load).
  // Tolerances from the latency measured in this run:
  //  - the mean error inside that range, widened by the latency's interquartile range;
  //  - every sample within half a period of its true time plus the mean error: no sample
  //    carries a neighbour's time, however late the edges;
  //  - the rms error about its mean below the rms deviation of the edges' own latency from
  //    their median: the sample times are better than the raw edge stamps.
  const double constant = static_cast<double>(options.timestamps.edge_latency_ns);
  const double low = run.latency.median - constant, high = run.latency.mean - constant;
  const double iqr = run.latency.p75 - run.latency.p25;
  auto rms_about = [](const std::vector<double>& v, double c) {
    double sum = 0;
    for (double x : v) sum += (x - c) * (x - c);
    return v.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(v.size()));
  };
  const double error_rms = rms_about(run.errors, run.error.mean);
  const double edge_rms = rms_about(run.latencies, run.latency.median);
  const double max_dev =
      std::max(std::abs(run.error.min - run.error.mean), std::abs(run.error.max - run.error.mean));
  const double half = 0.5 * static_cast<double>(period);
  check(run.error.n > 0 && run.error.mean >= std::min(low, high) - iqr &&
            run.error.mean <= std::max(low, high) + iqr,
        "mean error between this run's median and mean latency less the constant (" + us(low) + ".." +
            us(high) + ") within the interquartile range (" + us(iqr) + ")",
        "mean error " + us(run.error.mean));
  check(max_dev < half,
        "every sample time within half a period (" + us(half) + ") of the truth plus the mean error",
        "largest deviation " + us(max_dev));
  check(error_rms < edge_rms,
        "rms error below the edge stamps' own (" + us(edge_rms) + " about their median latency)",
        us(error_rms));
  // The samples from the stall on, where edges the kernel dropped (STALL_PERIODS above 16) once
  // tied later edges to older samples and left about a second of samples up to 0.7 period late:
  // none more than a quarter period from the truth plus the mean error.
  std::size_t after = 0, off = 0;
  double after_dev = 0;
  for (std::size_t i = 0; i < run.errors.size(); ++i) {
    if (run.error_t[i] < run.stall_t) continue;
    ++after;
    const double dev = std::abs(run.errors[i] - run.error.mean);
    after_dev = std::max(after_dev, dev);
    if (dev > 0.25 * static_cast<double>(period)) ++off;
  }
  check(after > 0 && off == 0,
        "from the stall on, every sample time within a quarter period (" +
            us(0.25 * static_cast<double>(period)) + ") of the truth plus the mean error",
        std::to_string(after) + " samples, " + std::to_string(off) + " beyond, largest deviation " +
            us(after_dev));
  std::printf(
      "  figures at %.0f Hz (period %.0f us): edge latency median %s, mean %s, IQR %s, p99 %s; sample time "
      "error "
      "mean %s, rms about it %s, largest deviation %s; %llu re-anchors\n",
      rate_hz, p_us, us(run.latency.median).c_str(), us(run.latency.mean).c_str(), us(iqr).c_str(),
      us(run.latency.p99).c_str(), us(run.error.mean).c_str(), us(error_rms).c_str(), us(max_dev).c_str(),
      static_cast<unsigned long long>(run.ts.reanchors));
}

}  // namespace

int main(int argc, char** argv) {
  // RATE_HZ: the emulated chip's output rate (the rig configuration's default, 200 Hz);
  // STALL_PERIODS: how long the event loop stalls in the checked run (default 10, inside the
  // kernel's 16-edge queue; beyond it the kernel drops edges, see docs/testing-devices.md).
  const double rate_hz = argc > 1 ? std::atof(argv[1]) : 200.0;
  const int stall_periods = argc > 2 ? std::atoi(argv[2]) : 10;
  if (rate_hz <= 0 || stall_periods < 0) {
    std::fprintf(stderr, "usage: qemu_gpio_sim_guest [RATE_HZ [STALL_PERIODS]]\n");
    return 2;
  }
  std::string error;
  const auto sim = make_sim_chip(error);
  check(sim.has_value(), "gpio-sim chip made through configfs (bank of 8 lines, line 3 IMU_DRDY, live)",
        sim ? sim->chip + " at " + sim->sysfs : error);
  if (!sim) return 1;
  Pull pull(sim->pull_path(kDrdyLine));
  Pull other_pull(sim->pull_path(kOtherLine));
  check(pull.ok() && other_pull.ok(), "the simulator's pull attributes open", sim->pull_path(kDrdyLine));
  if (!pull.ok() || !other_pull.ok()) return 1;
  check(read_text(sim->pull_path(kDrdyLine)) == "pull-down", "lines start pulled down");

  open_checks(*sim);
  GpiodLineOptions o{sim->chip, std::to_string(kDrdyLine), "imucal"};
  auto opened = GpiodDataReadyLine::open(o);
  if (!opened.ok()) {
    check(false, "open for the edge checks", opened.error().message);
    return 1;
  }
  GpiodDataReadyLine& line = **opened;
  wait_checks(line);
  constexpr int kSingle = 200;
  single_edges(line, pull, other_pull, kSingle);
  burst_checks(line, pull);
  paired_checks(line, pull, rate_hz, stall_periods);

  std::printf("%s: %d failed check(s)\n", failures == 0 ? "PASS" : "FAIL", failures);
  return failures == 0 ? 0 : 1;
}
