// SPDX-License-Identifier: BSD-3-Clause
// Session log throughput: IMU sample inserts (raw and SI streams, as the writer is used while
// recording: batches, commits every 500 ms) and reads (whole stream and a time window).
// The log files go to $IMUCAL_BENCH_DIR, else the system temporary directory: point it at the
// filesystem the rig records to for figures that mean something there.

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "log/session_log.hpp"

namespace {

using namespace imucal;
using namespace imucal::log;

std::string bench_path(const std::string& name) {
  const char* dir = std::getenv("IMUCAL_BENCH_DIR");
  const std::filesystem::path base =
      dir ? std::filesystem::path(dir) : std::filesystem::temp_directory_path();
  return (base / ("imucal-bench-" + std::to_string(getpid()) + "-" + name + ".imulog")).string();
}

void remove_log(const std::string& path) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(path + suffix);
}

std::vector<ImuSample> make_batch(std::size_t n, TimeNs t0_ns, bool raw) {
  std::vector<ImuSample> batch(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double k = static_cast<double>(i % 997);
    batch[i].t_ns = t0_ns + static_cast<TimeNs>(i) * 1'000'000;
    if (raw) {
      batch[i].accel = {k, -k, 16384.0 - k};
      batch[i].gyro = {k - 10.0, 3.0, -k};
      batch[i].temperature = -520.0 + k;
    } else {
      batch[i].accel = {0.01 * k, -0.02 * k, 9.80665 + 1e-4 * k};
      batch[i].gyro = {1e-3 * k, 2e-3, -3e-4 * k};
      batch[i].temperature = 25.0 + 1e-3 * k;
    }
  }
  return batch;
}

ImuStreamInfo stream_info(bool raw) {
  ImuStreamInfo info;
  info.units = raw ? ImuUnits::kRaw : ImuUnits::kSi;
  info.rate_hz = 1000.0;
  return info;
}

// Inserts state.range(0)-sample batches into one log per run of the benchmark, closes it.
void insert_imu(benchmark::State& state, bool raw) {
  const auto batch_size = static_cast<std::size_t>(state.range(0));
  const std::string path = bench_path(raw ? "insert-raw" : "insert-si");
  remove_log(path);
  auto writer = log::SessionLogWriter::create(path);
  if (!writer.ok()) {
    state.SkipWithError(writer.error().message.c_str());
    return;
  }
  const int id = *(*writer)->add_imu_stream(stream_info(raw));
  auto batch = make_batch(batch_size, 0, raw);
  TimeNs t_ns = 0;
  for (auto _ : state) {
    for (auto& s : batch) s.t_ns = t_ns++ * 1'000'000;
    if (!(*writer)->append_imu(id, batch).ok()) {
      state.SkipWithError("append failed");
      break;
    }
  }
  if (!(*writer)->close().ok()) state.SkipWithError("close failed");
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(batch_size));
  state.counters["file_bytes_per_sample"] =
      static_cast<double>(std::filesystem::file_size(path)) /
      static_cast<double>(state.iterations() * static_cast<std::int64_t>(batch_size));
  remove_log(path);
}

void BM_InsertImuRaw(benchmark::State& state) { insert_imu(state, true); }
void BM_InsertImuSi(benchmark::State& state) { insert_imu(state, false); }
BENCHMARK(BM_InsertImuRaw)->Arg(1)->Arg(10)->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_InsertImuSi)->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();

// A closed 1,000,000-sample raw log (about 17 minutes at 1 kHz), written once.
const std::string& read_fixture() {
  static const std::string path = [] {
    const std::string p = bench_path("read");
    remove_log(p);
    auto writer = log::SessionLogWriter::create(p);
    if (!writer.ok()) return std::string();
    const int id = *(*writer)->add_imu_stream(stream_info(true));
    for (int b = 0; b < 1000; ++b) {
      if (!(*writer)->append_imu(id, make_batch(1000, TimeNs{b} * 1'000'000'000, true)).ok())
        return std::string();
    }
    if (!(*writer)->close().ok()) return std::string();
    std::atexit([] { remove_log(bench_path("read")); });
    return p;
  }();
  return path;
}

void BM_ReadImuAll(benchmark::State& state) {
  if (read_fixture().empty()) {
    state.SkipWithError("could not write the fixture log");
    return;
  }
  auto reader = log::SessionLogReader::open(read_fixture());
  if (!reader.ok()) {
    state.SkipWithError(reader.error().message.c_str());
    return;
  }
  const int id = *(*reader)->find_imu_stream();
  std::int64_t n = 0;
  for (auto _ : state) {
    auto samples = (*reader)->read_imu(id);
    if (!samples.ok()) {
      state.SkipWithError("read failed");
      break;
    }
    n += static_cast<std::int64_t>(samples->size());
    benchmark::DoNotOptimize(samples->data());
  }
  state.SetItemsProcessed(n);
}
BENCHMARK(BM_ReadImuAll)->Unit(benchmark::kMillisecond)->UseRealTime();

// A 10 s window (10,000 samples) out of the middle: the time index at work.
void BM_ReadImuWindow(benchmark::State& state) {
  if (read_fixture().empty()) {
    state.SkipWithError("could not write the fixture log");
    return;
  }
  auto reader = log::SessionLogReader::open(read_fixture());
  if (!reader.ok()) {
    state.SkipWithError(reader.error().message.c_str());
    return;
  }
  const int id = *(*reader)->find_imu_stream();
  std::int64_t n = 0;
  for (auto _ : state) {
    const Status status =
        (*reader)->for_each_imu(id, 500 * kNsPerSecond, 510 * kNsPerSecond, [&](const ImuSample& s) {
          benchmark::DoNotOptimize(s.t_ns);
          ++n;
          return true;
        });
    if (!status.ok()) state.SkipWithError("read failed");
  }
  state.SetItemsProcessed(n);
}
BENCHMARK(BM_ReadImuWindow)->Unit(benchmark::kMicrosecond)->UseRealTime();

// Opening checks the whole log for damage (a scan of both tables): its cost grows with the log.
void BM_OpenReader(benchmark::State& state) {
  if (read_fixture().empty()) {
    state.SkipWithError("could not write the fixture log");
    return;
  }
  for (auto _ : state) {
    auto reader = log::SessionLogReader::open(read_fixture());
    if (!reader.ok()) state.SkipWithError(reader.error().message.c_str());
  }
  state.SetItemsProcessed(state.iterations() * 1'000'000);
}
BENCHMARK(BM_OpenReader)->Unit(benchmark::kMillisecond)->UseRealTime();

// As the calibrations open a log: the samples read by the open's own check are kept and handed
// over (SessionLogReaderOptions::preload_imu, take_imu), so the open and the read are one pass.
void BM_OpenReaderAndTakeSamples(benchmark::State& state) {
  if (read_fixture().empty()) {
    state.SkipWithError("could not write the fixture log");
    return;
  }
  log::SessionLogReaderOptions options;
  options.preload_imu = true;
  for (auto _ : state) {
    auto reader = log::SessionLogReader::open(read_fixture(), options);
    if (!reader.ok()) {
      state.SkipWithError(reader.error().message.c_str());
      break;
    }
    auto samples = (*reader)->take_imu(*(*reader)->find_imu_stream());
    if (!samples.ok() || samples->size() != 1'000'000) {
      state.SkipWithError("the samples were not all read");
      break;
    }
    benchmark::DoNotOptimize(samples->data());
  }
  state.SetItemsProcessed(state.iterations() * 1'000'000);
}
BENCHMARK(BM_OpenReaderAndTakeSamples)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
