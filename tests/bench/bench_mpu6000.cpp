// SPDX-License-Identifier: BSD-3-Clause
// FIFO budget of the MPU-6000 driver: runs the real driver against the register emulator with
// its bus timing model and prints, per configuration, the bus time used, the samples produced,
// delivered and lost, and the highest FIFO level. Simulated time, so the figures are
// deterministic; the last column is host wall time per simulated second (machine dependent).
//
// Usage: bench_mpu6000 [seconds]   (default 10 s of simulated time per configuration)

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <optional>
#include <string>

#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/mpu6000.hpp"

using namespace imucal;
using namespace imucal::drivers::mpu6000;

namespace {

fake::SensorReading source(TimeNs t_ns) {
  const double t = ns_to_s(t_ns);
  fake::SensorReading r;
  r.specific_force = {0.5 * std::sin(2 * std::numbers::pi * 1.3 * t), 0.1, kStandardGravity};
  r.angular_rate = {0.2 * std::sin(2 * std::numbers::pi * 0.7 * t), -0.1, 1.0};
  r.temperature_c = 30.0;
  return r;
}

struct Case {
  const char* name;
  BusKind bus;
  std::uint32_t fifo_speed_hz;
  std::uint8_t dlpf_cfg;
  TimeNs read_interval_ns;
};

struct Figures {
  double rate_hz = 0;
  double bus_percent = 0;
  std::uint64_t produced = 0;
  std::uint64_t delivered = 0;
  std::uint64_t lost = 0;
  unsigned max_fifo = 0;
  std::uint64_t fifo_resets = 0;
  double cpu_ms_per_s = 0;
  std::string error;
};

Figures run(const Case& c, double seconds) {
  Settings s;
  s.bus = c.bus;
  s.dlpf_cfg = c.dlpf_cfg;
  s.smplrt_div = 0;
  s.read_interval_ns = c.read_interval_ns;
  s.fifo_speed_hz = c.fifo_speed_hz;
  fake::EmulatorOptions o;
  o.bus = c.bus;
  o.timing = c.bus == BusKind::kSpi ? fake::BusTiming::spi() : fake::BusTiming::i2c();
  o.record_truth = false;
  fake::Mpu6000Emulator emu(source, o);
  fake::SimDataReadyLine line(emu, {});
  emu.connect(line);
  Mpu6000 driver(emu, s);

  Figures f;
  f.rate_hz = s.sample_rate_hz();
  const auto cpu0 = std::chrono::steady_clock::now();
  // Start up, then measure over `seconds` of streaming.
  while (driver.state() != State::kStream) {
    auto r = driver.poll(emu.now_ns());
    if (!r.ok()) {
      f.error = r.error().message;
      return f;
    }
    emu.advance_to(std::max(r->next_poll_ns, emu.now_ns()));
  }
  const TimeNs t0 = emu.now_ns();
  const TimeNs busy0 = emu.stats().bus_busy_ns;
  // Frames already in the FIFO at t0 are delivered in the measured window: count them as produced.
  const std::uint64_t samples0 = emu.stats().fifo_frames_written - emu.fifo_bytes() / FIFO::kFrameBytes;
  const TimeNs end = t0 + static_cast<TimeNs>(seconds * 1e9);
  TimeNs next_poll = t0;
  while (emu.now_ns() < end) {
    std::optional<drivers::DataReadyEdge> edge;
    while (emu.now_ns() < next_poll) {
      auto w = line.wait(next_poll - emu.now_ns());
      if (!w.ok() || !*w) break;
      edge = **w;
      driver.on_edge(*edge);
    }
    auto r = driver.poll(emu.now_ns(), edge);
    if (!r.ok()) {
      f.error = r.error().message;
      break;
    }
    if (r->batch) f.delivered += r->batch->samples.size();
    next_poll = std::min(r->next_poll_ns, emu.now_ns() + c.read_interval_ns);
  }
  const auto cpu1 = std::chrono::steady_clock::now();
  const double sim_s = ns_to_s(emu.now_ns() - t0);
  f.bus_percent = 100.0 * ns_to_s(emu.stats().bus_busy_ns - busy0) / sim_s;
  f.produced = emu.stats().fifo_frames_written - samples0;
  const std::uint64_t still_queued = emu.fifo_bytes() / FIFO::kFrameBytes;
  f.lost = f.produced > f.delivered + still_queued ? f.produced - f.delivered - still_queued : 0;
  f.max_fifo = emu.stats().max_fifo_bytes;
  f.fifo_resets = driver.counters().fifo_resets;
  f.cpu_ms_per_s = std::chrono::duration<double, std::milli>(cpu1 - cpu0).count() / sim_s;
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 10.0;
  if (!(seconds > 0)) {
    std::fprintf(stderr, "usage: bench_mpu6000 [simulated seconds > 0]\n");
    return 2;
  }
  const Case cases[] = {
      {"SPI 20 MHz, 8 kHz, read every 1 ms", BusKind::kSpi, 20'000'000, 0, 1'000'000},
      {"SPI 20 MHz, 8 kHz, read every 4 ms", BusKind::kSpi, 20'000'000, 0, 4'000'000},
      {"SPI 1 MHz, 8 kHz, read every 1 ms", BusKind::kSpi, 1'000'000, 0, 1'000'000},
      {"SPI 20 MHz, 1 kHz, read every 5 ms", BusKind::kSpi, 20'000'000, 1, 5'000'000},
      {"I2C 400 kHz, 1 kHz, read every 4 ms", BusKind::kI2c, 0, 1, 4'000'000},
      {"I2C 400 kHz, 1 kHz, read every 1 ms", BusKind::kI2c, 0, 1, 1'000'000},
      {"I2C 400 kHz, 8 kHz, read every 1 ms", BusKind::kI2c, 0, 0, 1'000'000},
  };
  std::printf(
      "MPU-6000 FIFO budget, %.1f s simulated per case (bus model: SPI 8 bit/byte + 1 address byte + 20 us "
      "per transfer; I2C 9 bit/byte + 3 header bytes + 50 us per transfer)\n\n",
      seconds);
  std::printf("%-40s %8s %7s %9s %9s %7s %8s %7s %9s\n", "case", "rate_hz", "bus_%", "produced", "delivered",
              "lost", "max_fifo", "resets", "wall_ms/s");
  for (const Case& c : cases) {
    const Figures f = run(c, seconds);
    if (!f.error.empty()) {
      std::printf("%-40s error: %s\n", c.name, f.error.c_str());
      continue;
    }
    std::printf("%-40s %8.0f %7.1f %9llu %9llu %7llu %8u %7llu %9.2f\n", c.name, f.rate_hz, f.bus_percent,
                static_cast<unsigned long long>(f.produced), static_cast<unsigned long long>(f.delivered),
                static_cast<unsigned long long>(f.lost), f.max_fifo,
                static_cast<unsigned long long>(f.fifo_resets), f.cpu_ms_per_s);
  }
  return 0;
}
