// SPDX-License-Identifier: BSD-3-Clause
// Throughput of the SPSC ring buffer (items/s): single-thread push+pop, and producer/consumer
// on two threads with single and bulk operations, for a small POD and for ImuSample.

#include <benchmark/benchmark.h>

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "acquisition/ring_buffer.hpp"
#include "core/imu.hpp"

namespace {

using imucal::ImuSample;
using imucal::acq::SpscRingBuffer;

void BM_SingleThreadPushPop(benchmark::State& state) {
  SpscRingBuffer<std::uint64_t> rb(1024);
  std::uint64_t v = 0, out = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(rb.try_push(v++));
    benchmark::DoNotOptimize(rb.try_pop(out));
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}
BENCHMARK(BM_SingleThreadPushPop);

template <class T>
void two_threads(benchmark::State& state, std::size_t bulk) {
  constexpr std::size_t kItems = 1 << 20;
  for (auto _ : state) {
    SpscRingBuffer<T> rb(4096);
    std::thread consumer([&] {
      std::vector<T> out(bulk);
      std::size_t got = 0;
      while (got < kItems) {
        std::size_t n = 0;
        if (bulk == 1) {
          n = rb.try_pop(out[0]) ? 1 : 0;
        } else {
          n = rb.try_pop_bulk(out);
        }
        got += n;
        if (n == 0) std::this_thread::yield();
      }
      benchmark::DoNotOptimize(out.data());
    });
    std::vector<T> in(bulk);
    std::size_t sent = 0;
    while (sent < kItems) {
      std::size_t n = 0;
      if (bulk == 1) {
        n = rb.try_push(in[0]) ? 1 : 0;
      } else {
        n = rb.try_push_bulk(std::span<const T>(in.data(), std::min(bulk, kItems - sent)));
      }
      sent += n;
      if (n == 0) std::this_thread::yield();
    }
    consumer.join();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * kItems));
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * kItems * sizeof(T)));
}

void BM_TwoThreadsU64(benchmark::State& state) {
  two_threads<std::uint64_t>(state, static_cast<std::size_t>(state.range(0)));
}
BENCHMARK(BM_TwoThreadsU64)->Arg(1)->Arg(32)->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_TwoThreadsImuSample(benchmark::State& state) {
  two_threads<ImuSample>(state, static_cast<std::size_t>(state.range(0)));
}
BENCHMARK(BM_TwoThreadsImuSample)->Arg(1)->Arg(32)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
