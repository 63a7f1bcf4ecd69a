// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/ring_buffer.hpp"

namespace imucal::acq {
namespace {

TEST(SpscRingBuffer, CapacityRoundsUpToPowerOfTwo) {
  EXPECT_EQ(SpscRingBuffer<int>(0).capacity(), 2u);
  EXPECT_EQ(SpscRingBuffer<int>(5).capacity(), 8u);
  EXPECT_EQ(SpscRingBuffer<int>(64).capacity(), 64u);
  EXPECT_EQ(SpscRingBuffer<int>(65).capacity(), 128u);
}

TEST(SpscRingBuffer, FifoOrderFullAndEmpty) {
  SpscRingBuffer<int> rb(4);
  int out = -1;
  EXPECT_FALSE(rb.try_pop(out));
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(rb.try_push(i));
  EXPECT_FALSE(rb.try_push(99));  // full: refused, not overwritten
  EXPECT_EQ(rb.size_approx(), 4u);
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(rb.try_pop(out));
    EXPECT_EQ(out, i);
  }
  EXPECT_FALSE(rb.try_pop(out));
  EXPECT_TRUE(rb.empty_approx());
}

TEST(SpscRingBuffer, WrapsAroundManyTimes) {
  SpscRingBuffer<std::uint64_t> rb(8);
  std::uint64_t next_in = 0, next_out = 0;
  for (int round = 0; round < 1000; ++round) {
    const int n = 1 + round % 8;
    for (int i = 0; i < n; ++i) ASSERT_TRUE(rb.try_push(next_in++));
    for (int i = 0; i < n; ++i) {
      std::uint64_t v = 0;
      ASSERT_TRUE(rb.try_pop(v));
      ASSERT_EQ(v, next_out++);
    }
  }
}

TEST(SpscRingBuffer, BulkPushPopPartial) {
  SpscRingBuffer<int> rb(8);
  std::vector<int> in(11);
  for (int i = 0; i < 11; ++i) in[static_cast<std::size_t>(i)] = i;
  EXPECT_EQ(rb.try_push_bulk(in), 8u);  // only what fits
  std::vector<int> out(5);
  EXPECT_EQ(rb.try_pop_bulk(out), 5u);
  EXPECT_EQ(out, (std::vector<int>{0, 1, 2, 3, 4}));
  EXPECT_EQ(rb.try_push_bulk(std::span<const int>(in).subspan(8)), 3u);  // wraps
  std::vector<int> rest(10);
  EXPECT_EQ(rb.try_pop_bulk(rest), 6u);
  rest.resize(6);
  EXPECT_EQ(rest, (std::vector<int>{5, 6, 7, 8, 9, 10}));
}

TEST(SpscRingBuffer, MoveOnlyAndOwningValues) {
  SpscRingBuffer<std::unique_ptr<std::string>> rb(4);
  EXPECT_TRUE(rb.try_push(std::make_unique<std::string>("a")));
  EXPECT_TRUE(rb.try_push(std::make_unique<std::string>("b")));
  std::unique_ptr<std::string> out;
  ASSERT_TRUE(rb.try_pop(out));
  EXPECT_EQ(*out, "a");
  // One value left in the buffer: freed by the destructor (ASan checks the leak).
}

TEST(SpscRingBuffer, CacheLinePaddedIndices) {
  // The producer and consumer indices must not share a cache line.
  EXPECT_GE(sizeof(SpscRingBuffer<char>), 3 * kCacheLineBytes);
  EXPECT_EQ(alignof(SpscRingBuffer<char>), kCacheLineBytes);
}

// Two threads, a small buffer (so both sides hit full and empty often), single and bulk
// operations mixed: every value arrives exactly once and in order.
TEST(SpscRingBuffer, TwoThreadStressKeepsSequence) {
  constexpr std::uint64_t kCount = 2'000'000;
  struct Item {
    std::uint64_t seq = 0;
    std::uint64_t check = 0;
  };
  SpscRingBuffer<Item> rb(64);
  std::atomic<bool> failed{false};
  std::thread producer([&] {
    std::uint64_t seq = 0;
    std::vector<Item> batch;
    while (seq < kCount) {
      if (seq % 3 == 0) {
        batch.clear();
        const std::uint64_t n = std::min<std::uint64_t>(1 + seq % 17, kCount - seq);
        for (std::uint64_t i = 0; i < n; ++i) batch.push_back({seq + i, ~(seq + i)});
        std::size_t done = 0;
        while (done < batch.size()) {
          done += rb.try_push_bulk(std::span<const Item>(batch).subspan(done));
          if (done < batch.size()) std::this_thread::yield();
        }
        seq += n;
      } else {
        while (!rb.try_push(Item{seq, ~seq})) std::this_thread::yield();
        ++seq;
      }
    }
  });
  std::uint64_t expected = 0;
  std::vector<Item> out(13);
  while (expected < kCount) {
    std::size_t n = 0;
    if (expected % 2 == 0) {
      n = rb.try_pop_bulk(out);
    } else if (rb.try_pop(out[0])) {
      n = 1;
    }
    if (n == 0) {
      std::this_thread::yield();
      continue;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (out[i].seq != expected || out[i].check != ~expected) failed = true;
      ++expected;
    }
  }
  producer.join();
  EXPECT_FALSE(failed) << "sequence broken near " << expected;
  EXPECT_EQ(expected, kCount);
  Item extra;
  EXPECT_FALSE(rb.try_pop(extra));
}

}  // namespace
}  // namespace imucal::acq
