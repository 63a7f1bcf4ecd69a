// SPDX-License-Identifier: BSD-3-Clause
// Runs inside the QEMU guest (tests/qemu/run-in-qemu.sh) against the kernel's own MPU-6000
// driver, inv-mpu6050 (IIO), bound to an i2c-stub chip at 0x68 on /dev/i2c-0:
//
//   run-in-qemu.sh --module "i2c-stub chip_addr=0x68" --module i2c-dev --module inv-mpu6050-i2c
//                  --module imucal-irq-i2c -- qemu_iio_guest [RATE_HZ [IMUCAL_CLI [IMUCALD IMUCALCTL]]]
//
// i2c-stub only stores bytes, so the guest prepares the registers the driver reads: WHO_AM_I
// 0x68, INT_STATUS with the data-ready bit, FIFO_COUNT 14 (one frame), and 14 bytes from
// FIFO_R_W on (the stub's block read returns consecutive registers, so each interrupt the
// driver takes reads the same frame). The driver builds its buffer only when its client has an
// interrupt; imucal-irq-i2c (tests/qemu/kmod/) makes the client with one and raises it on each
// write to its `fire` parameter: the data-ready pulses, at the rate the driver was set to, from a
// thread here. Checks, one line each: the refusal without an interrupt, discovery and
// configuration through sysfs, the scans' decoding, the kernel's timestamps against the pulses,
// sample loss from a full buffer and from the chip's FIFO overflow (counted from the holes in the
// stamps), the device going away, and `imucal record` with `driver: auto` on that rig.

#include <fcntl.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <sys/ioctl.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/iio_acquisition.hpp"
#include "app/rig/rig.hpp"
#include "core/time.hpp"
#include "drivers/iio/iio_imu.hpp"
#include "tests/qemu/guest_support.hpp"
#include "tests/qemu/iio_stub_rig.hpp"

namespace {

using imucal::Errc;
using imucal::monotonic_now_ns;
using imucal::TimeNs;
namespace acq = imucal::acq;
namespace iio = imucal::drivers::iio;
namespace fs = std::filesystem;
using namespace imucal::qemu;  // NOLINT: the rig's helpers

using imucal::qemu::check;
using imucal::qemu::contains;
using imucal::qemu::failures;

imucal::RigConfig rig_config(double rate_hz, imucal::ImuDriver driver) {
  imucal::RigConfig c;
  c.name = "qemu-iio";
  c.imu.bus = imucal::ImuBus::kI2c;
  c.imu.device = kBus;
  c.imu.i2c_address = kAddr;
  c.imu.driver = driver;
  c.imu.rate_hz = rate_hz;
  c.imu.dlpf_hz = rate_hz >= 400 ? 188 : rate_hz >= 200 ? 98 : rate_hz >= 90 ? 42 : 20;
  c.imu.accel_range_g = 4;
  c.imu.gyro_range_dps = 500;
  return c;
}

// Collects samples through the source's blocking step() until `want` came or `timeout_s` passed.
std::vector<imucal::ImuSample> collect(acq::ImuSource& source, std::size_t want, double timeout_s,
                                       std::string& error) {
  std::vector<imucal::ImuSample> all, out;
  const TimeNs end = monotonic_now_ns() + static_cast<TimeNs>(timeout_s * 1e9);
  while (all.size() < want && monotonic_now_ns() < end) {
    if (auto st = source.step(out); !st.ok()) {
      error = st.error().message;
      break;
    }
    all.insert(all.end(), out.begin(), out.end());
  }
  return all;
}

struct Figures {
  double mean = 0, rms = 0, max_abs = 0, median = 0;
};

Figures figures(std::vector<double> v) {
  Figures f;
  if (v.empty()) return f;
  double s = 0;
  for (double x : v) s += x;
  f.mean = s / static_cast<double>(v.size());
  double s2 = 0;
  for (double x : v) {
    s2 += (x - f.mean) * (x - f.mean);
    f.max_abs = std::max(f.max_abs, std::abs(x - f.mean));
  }
  f.rms = std::sqrt(s2 / static_cast<double>(v.size()));
  std::sort(v.begin(), v.end());
  f.median = v[v.size() / 2];
  return f;
}

std::string us(double ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f us", ns / 1e3);
  return buf;
}

// Without an interrupt the kernel's driver binds but builds no buffer: imucal says why.
void refusal_without_interrupt(double rate_hz) {
  const bool made = write_text(std::string(kAdapter) + "/new_device", "mpu6050 0x68");
  const bool bound = made && wait_for("/sys/bus/iio/devices/iio:device0", true);
  check(bound, "inv-mpu6050 binds a client made through new_device (no interrupt)");
  if (bound) {
    const auto devices = iio::find_inv_mpu_devices("/sys/bus/iio/devices");
    check(devices.size() == 1 && !devices[0].has_buffer && devices[0].parent == "0-0068",
          "it is found in sysfs, bound to 0-0068, without scan_elements",
          devices.empty() ? "none" : devices[0].name + " on " + devices[0].parent);
    auto rig = imucal::app::open_imu_rig(rig_config(rate_hz, imucal::ImuDriver::kAuto));
    check(!rig.ok() && rig.error().code == Errc::kUnsupported && contains(rig.error().message, "no buffer") &&
              contains(rig.error().message, "interrupt"),
          "driver: auto resolves to it and the rig is refused: no buffer without an interrupt",
          rig.ok() ? "opened" : rig.error().message);
    auto direct = imucal::app::open_imu_rig(rig_config(rate_hz, imucal::ImuDriver::kDirect));
    check(!direct.ok() && contains(direct.error().message, "Device or resource busy"),
          "driver: direct meets the kernel's claim on 0x68", direct.ok() ? "opened" : direct.error().message);
  }
  write_text(std::string(kAdapter) + "/delete_device", "0x68");
  wait_for("/sys/bus/iio/devices/iio:device0", false);
}

// The scans decode to the stub's frame, every one, and the stamps follow the pulses.
void stream_checks(double rate_hz) {
  auto rig = imucal::app::open_imu_rig(rig_config(rate_hz, imucal::ImuDriver::kAuto));
  check(rig.ok() && (*rig)->iio() != nullptr, "driver: auto opens the rig through the kernel's driver",
        rig.ok() ? (*rig)->describe() : rig.error().message);
  if (!rig.ok() || (*rig)->iio() == nullptr) return;
  iio::IioImu& imu = *(*rig)->iio();
  const std::string dir = "/sys/bus/iio/devices/" + imu.info().id;
  check(read_text(dir + "/current_timestamp_clock") == "monotonic" && imu.rate_hz() == rate_hz &&
            read_text(dir + "/in_accel_scale") == "0.001196" &&
            read_text(dir + "/in_anglvel_scale") == "0.000266181",
        "the kernel took the clock, rate and scales",
        read_text(dir + "/current_timestamp_clock") + ", " + read_text(dir + "/sampling_frequency") + " Hz");
  check(imu.scan_bytes() == 24 && read_text(dir + "/buffer/enable") == "1",
        "7 channels and the timestamp in 24-byte scans, buffer on",
        std::to_string(imu.scan_bytes()) + " bytes");

  const int n = static_cast<int>(4 * rate_hz);
  Pulses pulses(rate_hz);
  check(pulses.ok(), "the interrupt's fire parameter opens");
  if (!pulses.ok()) return;
  pulses.start(n);
  std::string error;
  auto samples = collect((*rig)->source(), static_cast<std::size_t>(n), 4.0 + 10.0, error);
  pulses.stop();
  // A few more scans may still come for the last pulses.
  std::vector<imucal::ImuSample> tail;
  (void)(*rig)->source().service(tail);
  samples.insert(samples.end(), tail.begin(), tail.end());
  check(error.empty(), "the acquisition ran without an error", error);
  const auto timing = (*rig)->source().timing_stats();
  const std::size_t fired = pulses.before_.size();
  check(samples.size() + 3 >= fired && samples.size() <= fired && pulses.failed_ == 0,
        "every pulse gave a scan (the driver skips the first after enabling)",
        std::to_string(samples.size()) + " samples for " + std::to_string(fired) + " pulses");
  bool decoded = !samples.empty();
  for (const auto& s : samples) {
    decoded = decoded && s.accel.x() == 0x0168 && s.accel.y() == static_cast<std::int16_t>(0xfe0c) &&
              s.accel.z() == 0x4000 && s.temperature == static_cast<std::int16_t>(0xf000) &&
              s.gyro.x() == 0x007b && s.gyro.y() == static_cast<std::int16_t>(0xff85) && s.gyro.z() == 0x7fff;
  }
  check(decoded, "every scan decodes to the stub's frame (big-endian, the kernel's channel order)",
        samples.empty() ? "none" : "accel x " + std::to_string(samples[0].accel.x()));
  check(timing.gaps == 0 && timing.samples_lost == 0 && timing.monotonic_clamps == 0,
        "no hole, no stamp out of order",
        std::to_string(timing.gaps) + " gaps, " + std::to_string(timing.monotonic_clamps) + " clamps");

  // Each stamp against its pulse, in order (the driver drops the scans of the first pulses after
  // the buffer starts, so the first sample belongs to pulse fired - delivered). The kernel's
  // stamp is its own period estimate's time for the scan (inv_sensors_timestamp), not the
  // interrupt's.
  if (samples.empty() || samples.size() > fired) return;
  const std::size_t k0 = fired - samples.size();
  std::vector<double> err;
  for (std::size_t i = 0; i < samples.size(); ++i)
    err.push_back(static_cast<double>(samples[i].t_ns - pulses.before_[k0 + i]));
  const Figures f = figures(err);
  std::vector<double> w;
  for (std::size_t i = 0; i < fired; ++i)
    w.push_back(static_cast<double>(pulses.after_[i] - pulses.before_[i]));
  const Figures window = figures(w);
  const double period = 1e9 / rate_hz;
  std::printf(
      "  figures: %zu stamps against their pulse (write started): mean %s, median %s, rms about the mean %s, "
      "largest deviation from the mean %s; a pulse's write took median %s; rate from the stamps %+.0f ppm "
      "of nominal\n",
      err.size(), us(f.mean).c_str(), us(f.median).c_str(), us(f.rms).c_str(), us(f.max_abs).c_str(),
      us(window.median).c_str(), -(*rig)->source().period_error_ppm());
  // The host can hold the whole guest (QEMU descheduled on the shared cores, as when the
  // sanitized suite runs two heavy tests beside it); the kernel's estimate then runs off for a
  // run of samples (4.2 ms once; 50 of 800 once under the full suite), which a rig's kernel would
  // not see. A stamp paired with the wrong pulse moves the median by a period; one that drifts
  // from its pulses moves the median of the last samples: those are the checks, and the samples
  // beyond half a period are bounded loosely (a tenth) so that a stalled host does not fail it.
  const auto outside =
      std::count_if(err.begin(), err.end(), [&](double e) { return std::abs(e) >= 0.5 * period; });
  const std::size_t last_n = std::min<std::size_t>(100, err.size());
  const Figures last =
      figures(std::vector<double>(err.end() - static_cast<std::ptrdiff_t>(last_n), err.end()));
  check(std::abs(f.median) < 0.25 * period && std::abs(last.median) < 0.25 * period &&
            static_cast<double>(outside) <= 0.1 * static_cast<double>(err.size()),
        "the stamps follow their own pulses: median (of all, and of the last 100) within a quarter "
        "period, 90 % within half a period",
        "median " + us(f.median) + ", of the last " + std::to_string(last_n) + " " + us(last.median) + ", " +
            std::to_string(outside) + " of " + std::to_string(err.size()) + " beyond half a period");
}

// The kernel's device opened directly (not through the rig), at the rig configuration's ranges.
iio::IioImuOptions iio_options(double rate_hz) {
  iio::IioImuOptions o;
  o.rate_hz = rate_hz;
  o.accel_range = imucal::drivers::mpu6000::AccelRange::k4g;
  o.gyro_range = imucal::drivers::mpu6000::GyroRange::k500dps;
  return o;
}

// The kernel's device opened directly, as one check line; null when it did not open.
std::unique_ptr<iio::IioImu> open_device(const iio::IioImuOptions& o, const std::string& what) {
  auto imu = iio::IioImu::open(o);
  check(imu.ok(), what, imu.ok() ? (*imu)->describe() : imu.error().message);
  return imu.ok() ? std::move(*imu) : nullptr;
}

// Collects every sample until the pulses have ended and nothing more comes.
std::vector<imucal::ImuSample> drain(acq::ImuSource& source, const Pulses& pulses, std::string& error) {
  std::vector<imucal::ImuSample> all;
  while (!pulses.done() && error.empty()) {
    auto more = collect(source, SIZE_MAX, 0.05, error);
    all.insert(all.end(), more.begin(), more.end());
  }
  auto rest = collect(source, SIZE_MAX, 0.3, error);
  all.insert(all.end(), rest.begin(), rest.end());
  return all;
}

// A reader that stops reading: the kernel's buffer (32 scans here) keeps the oldest and drops
// the rest; the hole in the stamps counts them. One unbroken sequence of pulses, so that the
// scans lost (pulses less samples delivered) are the truth.
void buffer_loss_checks(double rate_hz) {
  iio::IioImuOptions o = iio_options(rate_hz);
  o.buffer_scans = 32;
  o.watermark_scans = 1;
  auto imu = open_device(o, "opened with a 32-scan buffer");
  if (!imu) return;
  acq::MonotonicClock clock;
  acq::IioAcquisition acquisition(*imu, clock, acq::MountingMap());
  Pulses pulses(rate_hz);
  pulses.start(160);
  std::string error;
  auto first = collect(acquisition, 20, 5.0, error);
  const int stopped_at = pulses.fired();
  pulses.wait_fired(stopped_at + 100);  // 100 pulses while nobody reads
  auto rest = drain(acquisition, pulses, error);
  pulses.stop();
  const auto t = acquisition.timing_stats();
  const long delivered = static_cast<long>(first.size() + rest.size());
  const long lost = static_cast<long>(pulses.before_.size()) - delivered;
  std::printf("  figures: %zu pulses, %ld samples delivered; %llu lost counted in %llu gap(s), %ld lost\n",
              pulses.before_.size(), delivered, static_cast<unsigned long long>(t.samples_lost),
              static_cast<unsigned long long>(t.gaps), lost);
  check(error.empty() && lost >= 60 && t.gaps == 1 && std::abs(static_cast<long>(t.samples_lost) - lost) <= 1,
        "scans the full buffer dropped are counted from the hole in the stamps",
        std::to_string(t.samples_lost) + " counted, " + std::to_string(lost) + " lost" +
            (error.empty() ? "" : ", " + error));
}

// The chip's FIFO overflowing: the kernel resets it and reads nothing for that interrupt.
void fifo_overflow_checks(double rate_hz) {
  iio::IioImuOptions o = iio_options(rate_hz);
  auto imu = open_device(o, "opened for the FIFO overflow");
  if (!imu) return;
  acq::MonotonicClock clock;
  acq::IioAcquisition acquisition(*imu, clock, acq::MountingMap());
  constexpr int kFrom = 20;
  constexpr int kOverflowing = 7;
  bool pokes_ok = true;
  Pulses pulses(rate_hz);
  // FIFO_COUNT 1008 for pulses kFrom..kFrom+6: "fifo overflow reset", nothing read for them.
  pulses.before_pulse = [&](int i) {
    if (i == kFrom) pokes_ok = pokes_ok && poke(0x72, 0x03) && poke(0x73, 0xf0);
    if (i == kFrom + kOverflowing) pokes_ok = pokes_ok && poke(0x72, 0x00) && poke(0x73, 14);
  };
  pulses.start(kFrom + kOverflowing + 30);
  std::string error;
  auto all = drain(acquisition, pulses, error);
  pulses.stop();
  const auto t = acquisition.timing_stats();
  const long lost = static_cast<long>(pulses.before_.size()) - static_cast<long>(all.size());
  std::printf("  figures: FIFO_COUNT 1008 for %d pulses: %ld samples lost, %llu counted in %llu gap(s)\n",
              kOverflowing, lost, static_cast<unsigned long long>(t.samples_lost),
              static_cast<unsigned long long>(t.gaps));
  check(pokes_ok && error.empty() && lost == kOverflowing && t.gaps == 1 &&
            std::abs(static_cast<long>(t.samples_lost) - lost) <= 1,
        "a FIFO the kernel reset on overflow shows as lost samples, counted",
        std::to_string(t.samples_lost) + " counted, " + std::to_string(lost) + " lost");
}

// The driver unbound while streaming: the next read says the device went away.
void unplug_checks(double rate_hz) {
  iio::IioImuOptions o = iio_options(rate_hz);
  auto imu = open_device(o, "opened for the unplug");
  if (!imu) return;
  const bool gone = attach(false);
  std::vector<iio::IioScan> scans;
  const auto st = imu->read(scans);
  check(gone && !st.ok() && st.error().code == Errc::kNotFound && contains(st.error().message, "went away"),
        "a read after the client is removed says the device went away",
        st.ok() ? "read ok" : st.error().message);
  imu.reset();
  check(attach(true), "the client comes back");
}

// `imucal record` on this rig (driver: auto), while the pulses come; `imucal info` reads it.
void cli_checks(double rate_hz, const std::string& cli) {
  const std::string tmp = std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp";
  const std::string config = tmp + "/iio-rig.yaml";
  const std::string log = tmp + "/iio.imulog";
  std::ofstream(config)
      << "name: qemu-iio\nimu:\n  bus: i2c\n  device: /dev/i2c-0\n  driver: auto\n  rate_hz: " << rate_hz
      << "\n  dlpf_hz: " << rig_config(rate_hz, imucal::ImuDriver::kAuto).imu.dlpf_hz << "\n";
  // The pulses go on until the recording ends (stop() below), up to a minute: the program's start
  // in the guest took over 4 s on a loaded CI machine, and a fixed 6 s of pulses then ended before
  // its 2 s of samples were in.
  Pulses pulses(rate_hz);
  pulses.start(static_cast<int>(60 * rate_hz));
  auto run = [&](std::vector<std::string> args, std::string& out) {
    const std::string out_path = tmp + "/cli.out";
    args.insert(args.begin(), cli);
    std::string cmd;
    for (const auto& a : args) cmd += "'" + a + "' ";
    cmd += ">" + out_path + " 2>&1";
    const int rc = std::system(cmd.c_str());
    out = read_text(out_path);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  };
  std::string out;
  const int rc = run({"record", "--config", config, "--duration", "2", "--output", log, "--force"}, out);
  pulses.stop();
  check(rc == 0, "imucal record with driver: auto records through the kernel's driver", out.substr(0, 400));
  std::string info;
  const int irc = run({"info", log, "--json"}, info);
  std::string driver, device;
  std::int64_t samples = 0;
  try {
    const auto j = nlohmann::json::parse(info);
    driver = nlohmann::json::parse(j.at("metadata").at("imu.driver").get<std::string>()).at("driver");
    device = j.at("imu_streams").at(0).at("device");
    samples = j.at("imu_streams").at(0).at("count");
  } catch (const std::exception& e) {
    driver = std::string("(") + e.what() + ")";
  }
  check(irc == 0 && driver == "iio" && device == "mpu6000@iio:device0" &&
            samples > static_cast<std::int64_t>(1.9 * rate_hz),
        "imucal info reads the log: the stream and the driver's metadata",
        device + ", " + std::to_string(samples) + " samples, driver " + driver);
}

// imucald on this rig: it opens the IMU through the kernel's driver, its preflight says so (no
// self-test through it) and passes, and the gyro offset registers go through calibbias (cleared
// while a session records; one axis set to 7 before). The
// preflight's device lines are read through `imucalctl attach`, as an operator sees them.
void service_checks(double rate_hz, const std::string& imucald, const std::string& imucalctl) {
  const std::string tmp = std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp";
  const std::string config = tmp + "/iio-service.yaml";
  const std::string socket = tmp + "/imucald.sock";
  std::ofstream(config) << "name: qemu-iio\nimu: {bus: i2c, device: /dev/i2c-0, driver: auto, rate_hz: "
                        << rate_hz
                        << ", dlpf_hz: " << rig_config(rate_hz, imucal::ImuDriver::kAuto).imu.dlpf_hz
                        << "}\nstorage: {backend: file, path: " << tmp
                        << "/calibration.bin, program_gyro_offsets: true}\n";
  const std::string dir = "/sys/bus/iio/devices/iio:device0";
  write_text(dir + "/in_anglvel_y_calibbias", "7");  // cleared by the service: no stored bias
  Pulses pulses(rate_hz);
  pulses.start(static_cast<int>(60 * rate_hz));  // until the service has exited (stop() below)
  const pid_t pid = ::fork();
  if (pid == 0) {
    const std::string out = tmp + "/imucald.out";
    const int fd = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    ::execl(imucald.c_str(), imucald.c_str(), "--config", config.c_str(), "--socket", socket.c_str(),
            "--state-dir", (tmp + "/state").c_str(), "--start", "preflight", "--exit-after-session",
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const bool up = wait_for(socket, true, 20000);
  std::this_thread::sleep_for(std::chrono::seconds(2));  // samples come in
  const std::string screen_path = tmp + "/attach.out";
  (void)std::system(
      ("timeout 5 " + imucalctl + " --socket " + socket + " attach </dev/null >" + screen_path + " 2>&1")
          .c_str());
  const std::string screen = read_text(screen_path);
  const std::string offsets = read_text(dir + "/in_anglvel_y_calibbias");
  (void)std::system((imucalctl + " --socket " + socket + " abort >/dev/null 2>&1").c_str());
  int status = -1;
  for (int i = 0; i < 200 && ::waitpid(pid, &status, WNOHANG) == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  if (::waitpid(pid, &status, WNOHANG) == 0) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
  }
  pulses.stop();
  const auto line = screen.find("imu:");
  const std::string imu_line = line == std::string::npos ? screen.substr(0, 300) : screen.substr(line, 300);
  check(up && contains(screen, "ok    imu: MPU-6000 through the kernel's inv-mpu6050 driver") &&
            contains(screen, "self-test not available"),
        "imucald opens the IMU through the kernel's driver; its preflight passes it without a self-test",
        up ? imu_line : "no socket: " + read_text(tmp + "/imucald.out").substr(0, 300));
  check(contains(screen, "gyro offset registers [0 0 0] from cleared") && offsets == "0",
        "imucald clears the gyro offset registers through calibbias (a session records)",
        "in_anglvel_y_calibbias " + offsets);
}

}  // namespace

int main(int argc, char** argv) {
  const double rate_hz = argc > 1 ? std::atof(argv[1]) : 200.0;
  const std::string cli = argc > 2 ? argv[2] : "";
  if (!(rate_hz >= 4 && rate_hz <= 1000)) {
    std::fprintf(stderr, "usage: qemu_iio_guest [RATE_HZ (4..1000) [IMUCAL_CLI [IMUCALD IMUCALCTL]]]\n");
    return 2;
  }
  check(fs::exists(kParams), "imucal-irq-i2c is loaded", kParams);
  check(prepare_stub(), "the stub's registers are set (WHO_AM_I, INT_STATUS, FIFO_COUNT, one frame)");
  if (failures > 0) return 1;
  refusal_without_interrupt(rate_hz);
  check(attach(true), "the client with an interrupt binds inv-mpu6050 (iio:device0 with a buffer)",
        read_text(std::string(kParams) + "/irq"));
  if (failures > 0) return 1;
  stream_checks(rate_hz);
  buffer_loss_checks(rate_hz);
  fifo_overflow_checks(rate_hz);
  unplug_checks(rate_hz);
  if (!cli.empty()) cli_checks(rate_hz, cli);
  if (argc > 4) service_checks(rate_hz, argv[3], argv[4]);
  std::printf("%s: %d failed check(s)\n", failures == 0 ? "PASS" : "FAIL", failures);
  return failures == 0 ? 0 : 1;
}
