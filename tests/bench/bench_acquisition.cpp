// SPDX-License-Identifier: BSD-3-Clause
// bench_acquisition [SECONDS]: figures for docs/benchmarks.md.
//  1. Timestamp accuracy on the synthetic line (acquisition/timestamp_synthetic.hpp): RMS error
//     of the reconstructed sample times against the truth, 30 us RMS edge jitter.
//  2. The same end to end: MPU-6000 emulator + simulated data-ready line + the driver + the
//     acquisition loop, compared with the emulator's record of true sample times.
//  3. CPU time per second of 1 kHz acquisition: timestamping alone; the stream with the SQLite
//     session-log writer thread; and the whole simulated chain (emulator included).

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <numeric>
#include <string>
#include <vector>

#include "acquisition/imu_stream.hpp"
#include "acquisition/recorder.hpp"
#include "acquisition/timestamp.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "log/session_log.hpp"
#include "sim/rig.hpp"
#include "tests/support/timestamp_synthetic.hpp"

namespace {

using namespace imucal;
namespace mpu = drivers::mpu6000;

double cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void synthetic_table(double seconds) {
  struct Case {
    const char* name;
    double rate_hz;
    int per_read;
    double missed, late, spike;
  };
  const Case cases[] = {
      {"1 kHz, read every sample", 1000, 1, 0, 0, 0},
      {"8 kHz, read every 8 samples", 8000, 8, 0, 0, 0},
      {"1 kHz, 10% missed edges, 2% late reads, 1% 1 ms spikes", 1000, 1, 0.1, 0.02, 0.01},
      {"8 kHz / 8, 10% missed edges, 2% late reads, 1% 1 ms spikes", 8000, 8, 0.1, 0.02, 0.01},
      {"200 Hz, read every sample", 200, 1, 0, 0, 0},
  };
  std::printf(
      "1. synthetic line, 30 us RMS jitter, chip +2 %% with 20 ppm/s drift and 200 ppm wander,\n"
      "   %.0f s each, median of 5 seeds (error after the first 2 s; whole run in brackets)\n",
      seconds);
  for (const auto& c : cases) {
    std::vector<double> rms, all, mx;
    for (std::uint64_t seed = 1; seed <= 5; ++seed) {
      acq::SyntheticTimingOptions g;
      g.seed = seed;
      g.duration_s = seconds;
      g.nominal_rate_hz = c.rate_hz;
      g.samples_per_read = c.per_read;
      g.missed_edge_probability = c.missed;
      g.late_read_probability = c.late;
      g.spike_probability = c.spike;
      acq::TimestamperOptions o;
      o.nominal_rate_hz = g.nominal_rate_hz;
      o.edge_latency_ns = g.latency_mean_ns;
      o.edge_jitter_ns = g.latency_sigma_ns;
      acq::SampleTimestamper ts(o);
      const auto s = acq::evaluate_timestamper(ts, acq::generate_synthetic_timing(g), 2.0);
      rms.push_back(s.rms_ns / 1e3);
      all.push_back(s.rms_all_ns / 1e3);
      mx.push_back(s.max_abs_ns / 1e3);
    }
    std::printf("   %-62s rms %5.2f us [%5.2f]  max %5.1f us\n", c.name, median(rms), median(all),
                median(mx));
  }
}

fake::SensorReading chirp(TimeNs t_ns) {
  const double t = ns_to_s(t_ns);
  fake::SensorReading r;
  r.specific_force = {3.0 * std::sin(2 * std::numbers::pi * 3.1 * t),
                      2.5 * std::cos(2 * std::numbers::pi * 1.7 * t),
                      9.81 + std::sin(2 * std::numbers::pi * 0.37 * t)};
  r.angular_rate = {1.1 * std::sin(2 * std::numbers::pi * 5.3 * t),
                    0.9 * std::cos(2 * std::numbers::pi * 2.9 * t),
                    0.7 * std::sin(2 * std::numbers::pi * 7.7 * t + 0.3)};
  r.temperature_c = 30.0 + 0.5 * std::sin(2 * std::numbers::pi * 0.01 * t);
  return r;
}

struct EndToEnd {
  double rms_us = 0, max_us = 0;
  std::size_t matched = 0, delivered = 0;
  double cpu_ms_per_s = 0;
  double period_error_ppm = 0;
  std::size_t lost = 0;        // frames the chip wrote (from the first delivered on) never delivered
  std::size_t mismatched = 0;  // delivered samples that are no frame the chip wrote
  std::size_t gaps = 0;        // samples flagged as after a gap
  double bus_busy_pct = 0;     // bus time of all transfers / simulated time
  std::uint16_t max_fifo_bytes = 0;
};

/// Runs emulator + line + driver + acquisition (+ stream and log when `log_path` is given).
EndToEnd end_to_end(std::uint8_t dlpf_cfg, std::uint8_t div, double seconds, double clock_ppm,
                    const std::string& log_path, bool record_truth, mpu::BusKind bus = mpu::BusKind::kSpi) {
  mpu::Settings s;
  s.bus = bus;
  s.dlpf_cfg = dlpf_cfg;
  s.smplrt_div = div;
  const double per_read = std::max(1.0, std::round(s.sample_rate_hz() / 1000.0));
  s.read_interval_ns = static_cast<TimeNs>(2.0 * per_read * 1e9 / s.sample_rate_hz());
  sim::SimRigOptions ro;  // 20 us mean latency, 30 us jitter
  ro.settings = s;
  ro.clock_ppm = clock_ppm;
  ro.record_truth = record_truth;
  auto rig_r = sim::SimImuRig::create(chirp, ro);
  if (!rig_r.ok()) {
    std::fprintf(stderr, "bench: %s\n", rig_r.error().message.c_str());
    std::exit(1);
  }
  sim::SimImuRig& rig = **rig_r;
  fake::Mpu6000Emulator& emu = rig.emulator();
  acq::ImuAcquisition& acq = rig.acquisition();

  std::unique_ptr<log::SessionLogWriter> writer;
  std::unique_ptr<acq::ImuStream> stream;
  if (!log_path.empty()) {
    log::SessionLogWriterOptions wo;
    wo.overwrite = true;
    auto w = log::SessionLogWriter::create(log_path, wo);
    if (!w.ok()) {
      std::fprintf(stderr, "bench: %s\n", w.error().message.c_str());
      std::exit(1);
    }
    writer = std::move(w).value();
    auto id = writer->add_imu_stream(mpu::make_stream_info(s, "sim"));
    stream = std::make_unique<acq::ImuStream>();
    if (!id.ok() || !stream->start_log(*writer, *id).ok()) std::exit(1);
  }

  EndToEnd r;
  std::vector<ImuSample> out, all;
  const double c0 = cpu_s();
  const TimeNs end = emu.now_ns() + static_cast<TimeNs>(seconds * 1e9);
  while (emu.now_ns() < end) {
    if (auto st = acq.step(out); !st.ok()) {
      std::fprintf(stderr, "bench: acquisition stopped: %s\n", st.error().message.c_str());
      break;
    }
    if (stream) stream->publish(out);
    if (record_truth) all.insert(all.end(), out.begin(), out.end());
    for (const ImuSample& x : out) r.gaps += (x.flags & kImuFlagGapBefore) != 0;
    r.delivered += out.size();
  }
  r.bus_busy_pct = 100.0 * static_cast<double>(emu.stats().bus_busy_ns) / (seconds * 1e9);
  r.max_fifo_bytes = emu.stats().max_fifo_bytes;
  if (stream) {
    if (!stream->stop().ok()) std::fprintf(stderr, "bench: log write failed\n");
    if (!writer->close().ok()) std::fprintf(stderr, "bench: log close failed\n");
  }
  const double sim_s = seconds;
  r.cpu_ms_per_s = (cpu_s() - c0) * 1e3 / sim_s;
  r.period_error_ppm = acq.timestamper().period_error_ppm();
  if (!record_truth || all.empty()) return r;

  // Match delivered samples to the emulator's truth by their exact counts.
  std::vector<const fake::TruthSample*> fifo;
  for (const auto& t : emu.truth()) {
    if (t.to_fifo) fifo.push_back(&t);
  }
  auto same = [](const ImuSample& a, const fake::TruthSample& b) {
    return a.gyro == Eigen::Vector3d(b.gyro[0], b.gyro[1], b.gyro[2]) &&
           a.accel == Eigen::Vector3d(b.accel[0], b.accel[1], b.accel[2]) && a.temperature == b.temp;
  };
  // Every delivered sample must be a frame the chip wrote, in order; frames skipped between two
  // delivered ones are lost.
  std::size_t j = 0;
  while (j < fifo.size() && !same(all[0], *fifo[j])) ++j;
  const std::size_t first = j;
  double sum2 = 0;
  for (std::size_t i = 0; i < all.size(); ++i) {
    std::size_t k = j;
    while (k < fifo.size() && !same(all[i], *fifo[k])) ++k;
    if (k == fifo.size()) {
      ++r.mismatched;
      continue;
    }
    r.lost += k - j;
    j = k + 1;
    if (ns_to_s(fifo[k]->t_ns - fifo[first]->t_ns) < 2.0) continue;  // settling
    const double e = static_cast<double>(all[i].t_ns - fifo[k]->t_ns);
    sum2 += e * e;
    r.max_us = std::max(r.max_us, std::abs(e) / 1e3);
    ++r.matched;
  }
  // Frames still in the FIFO at the end are not lost.
  const std::size_t in_fifo = emu.fifo_bytes() / mpu::FIFO::kFrameBytes;
  r.lost += fifo.size() - j > in_fifo ? fifo.size() - j - in_fifo : 0;
  if (r.matched) r.rms_us = std::sqrt(sum2 / static_cast<double>(r.matched)) / 1e3;
  return r;
}

void emulator_table(double seconds) {
  std::printf(
      "2. end to end: emulator + driver + acquisition, 20 us mean / 30 us RMS edge latency,\n"
      "   chip oscillator -15000 ppm, %.0f s of rig time (time error after the first 2 s)\n",
      seconds);
  struct Case {
    const char* name;
    std::uint8_t dlpf, div;
    mpu::BusKind bus;
  };
  const Case cases[] = {{"SPI, 8 kHz gyro / 1 kHz accel, read every 8 edges", 0, 0, mpu::BusKind::kSpi},
                        {"SPI, 1 kHz (DLPF on), read per edge", 1, 0, mpu::BusKind::kSpi},
                        {"I2C 400 kHz, 1 kHz (DLPF on), read per edge", 1, 0, mpu::BusKind::kI2c},
                        {"SPI, 200 Hz (DLPF on, div 4), read per edge", 1, 4, mpu::BusKind::kSpi}};
  for (const auto& c : cases) {
    const auto r = end_to_end(c.dlpf, c.div, seconds, sim::kDefaultClockPpm, "", true, c.bus);
    std::printf("   %-52s rms %5.2f us  max %5.1f us  delivered %zu  lost %zu  wrong %zu  gaps %zu\n", c.name,
                r.rms_us, r.max_us, r.delivered, r.lost, r.mismatched, r.gaps);
    std::printf("   %-52s bus busy %.1f %%, FIFO peak %u bytes, chip %+.0f ppm (period)\n", "",
                r.bus_busy_pct, static_cast<unsigned>(r.max_fifo_bytes), r.period_error_ppm);
  }
}

void cpu_table(double seconds) {
  std::printf("3. CPU time per second of 1 kHz acquisition (process CPU time / recorded seconds, %.0f s)\n",
              seconds);
  // Timestamping alone.
  {
    acq::SyntheticTimingOptions g;
    g.duration_s = seconds;
    const auto timing = acq::generate_synthetic_timing(g);
    acq::SampleTimestamper ts(acq::TimestamperOptions{});
    std::vector<TimeNs> t(1);
    std::vector<std::uint32_t> f(1);
    const double c0 = cpu_s();
    for (const auto& b : timing.batches) {
      t.resize(b.timing.sample_count);
      f.assign(b.timing.sample_count, 0);
      (void)ts.process(b.timing, t, f);
    }
    std::printf("   %-58s %8.3f ms/s\n", "timestamper", (cpu_s() - c0) * 1e3 / seconds);
  }
  const std::string dir = std::filesystem::temp_directory_path() / "imucal-bench-acq";
  std::filesystem::create_directories(dir);
  // Stream + SQLite writer thread, 1 kHz samples published in batches of 1.
  {
    log::SessionLogWriterOptions wo;
    wo.overwrite = true;
    auto w = log::SessionLogWriter::create(dir + "/stream.imulog", wo);
    if (!w.ok()) {
      std::fprintf(stderr, "bench: %s\n", w.error().message.c_str());
      return;
    }
    ImuStreamInfo info;
    info.units = ImuUnits::kRaw;
    info.rate_hz = 1000;
    auto id = (*w)->add_imu_stream(info);
    acq::ImuStream stream;
    auto consumer = stream.add_consumer("display", 4096);
    if (!id.ok() || !stream.start_log(**w, *id).ok()) return;
    const auto n = static_cast<std::size_t>(seconds * 1000);
    ImuSample s;
    std::vector<ImuSample> sink(64);
    const double c0 = cpu_s();
    for (std::size_t i = 0; i < n; ++i) {
      s.t_ns = static_cast<TimeNs>(i) * 1'000'000;
      s.accel = Eigen::Vector3d(static_cast<double>(i % 200), -100, 8192);
      s.gyro = Eigen::Vector3d(3, static_cast<double>(i % 50), -7);
      s.temperature = -2000;
      stream.publish(std::span<const ImuSample>(&s, 1));
      while (consumer->pop(sink) > 0) {
      }
    }
    (void)stream.stop();
    (void)(*w)->close();
    std::printf("   %-58s %8.3f ms/s (the writer thread's work; no pacing)\n",
                "stream: 1 consumer + SQLite log writer thread", (cpu_s() - c0) * 1e3 / seconds);
  }
  // The whole simulated chain.
  {
    const auto r = end_to_end(1, 0, seconds, sim::kDefaultClockPpm, dir + "/chain.imulog", false);
    std::printf("   %-58s %8.3f ms/s (emulator included)\n", "emulator + driver + acquisition + stream + log",
                r.cpu_ms_per_s);
    const auto d = end_to_end(1, 0, seconds, sim::kDefaultClockPpm, "", false);
    std::printf("   %-58s %8.3f ms/s\n", "emulator + driver + acquisition (no log)", d.cpu_ms_per_s);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 60.0;
  if (!(seconds >= 5.0)) {
    std::fprintf(stderr, "usage: bench_acquisition [seconds >= 5]\n");
    return 2;
  }
  synthetic_table(seconds);
  emulator_table(seconds);
  cpu_table(seconds);
  return 0;
}
