// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A bounded lock-free single-producer single-consumer ring buffer.
//
// One thread pushes, one thread pops; neither ever blocks or allocates after construction.
// Capacity is a power of two so that indices wrap with a mask. The two indices grow without
// wrapping (64-bit, they cannot overflow in practice) and live on separate cache lines, each
// side also keeps a cached copy of the other side's index to avoid touching the shared line
// on every call. Ordering: the producer writes the slot, then publishes head_ with release;
// the consumer reads head_ with acquire before reading the slot, and publishes tail_ with
// release after moving the value out, which the producer acquires before reusing the slot.

#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <span>
#include <type_traits>
#include <utility>

namespace imucal::acq {

inline constexpr std::size_t kCacheLineBytes = 64;

template <class T>
class SpscRingBuffer {
  static_assert(std::is_default_constructible_v<T>, "slots are default-constructed up front");
  static_assert(std::is_move_assignable_v<T>);

 public:
  /// `min_capacity` is rounded up to a power of two (at least 2).
  explicit SpscRingBuffer(std::size_t min_capacity)
      : capacity_(std::bit_ceil(min_capacity < 2 ? std::size_t{2} : min_capacity)),
        mask_(capacity_ - 1),
        slots_(std::make_unique<T[]>(capacity_)) {}

  SpscRingBuffer(const SpscRingBuffer&) = delete;
  SpscRingBuffer& operator=(const SpscRingBuffer&) = delete;

  std::size_t capacity() const { return capacity_; }

  // ---- producer side ----

  /// Pushes one value; false (value untouched) when full.
  [[nodiscard]] bool try_push(const T& value) { return emplace_impl(value); }
  [[nodiscard]] bool try_push(T&& value) { return emplace_impl(std::move(value)); }

  /// Pushes as many of `values` as fit, in order; returns how many.
  [[nodiscard]] std::size_t try_push_bulk(std::span<const T> values) {
    const std::uint64_t head = producer_.head.load(std::memory_order_relaxed);
    std::size_t room = capacity_ - static_cast<std::size_t>(head - producer_.tail_cache);
    if (room < values.size()) {
      producer_.tail_cache = consumer_.tail.load(std::memory_order_acquire);
      room = capacity_ - static_cast<std::size_t>(head - producer_.tail_cache);
    }
    const std::size_t n = room < values.size() ? room : values.size();
    for (std::size_t i = 0; i < n; ++i) slots_[(head + i) & mask_] = values[i];
    producer_.head.store(head + n, std::memory_order_release);
    return n;
  }

  // ---- consumer side ----

  /// Pops one value into `out`; false when empty.
  [[nodiscard]] bool try_pop(T& out) {
    const std::uint64_t tail = consumer_.tail.load(std::memory_order_relaxed);
    if (tail == consumer_.head_cache) {
      consumer_.head_cache = producer_.head.load(std::memory_order_acquire);
      if (tail == consumer_.head_cache) return false;
    }
    out = std::move(slots_[tail & mask_]);
    consumer_.tail.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Pops up to `out.size()` values; returns how many.
  [[nodiscard]] std::size_t try_pop_bulk(std::span<T> out) {
    const std::uint64_t tail = consumer_.tail.load(std::memory_order_relaxed);
    std::size_t avail = static_cast<std::size_t>(consumer_.head_cache - tail);
    if (avail < out.size()) {
      consumer_.head_cache = producer_.head.load(std::memory_order_acquire);
      avail = static_cast<std::size_t>(consumer_.head_cache - tail);
    }
    const std::size_t n = avail < out.size() ? avail : out.size();
    for (std::size_t i = 0; i < n; ++i) out[i] = std::move(slots_[(tail + i) & mask_]);
    consumer_.tail.store(tail + n, std::memory_order_release);
    return n;
  }

  // ---- either side (a snapshot, exact only when the other side is idle) ----

  std::size_t size_approx() const {
    const std::uint64_t tail = consumer_.tail.load(std::memory_order_acquire);
    const std::uint64_t head = producer_.head.load(std::memory_order_acquire);
    return head >= tail ? static_cast<std::size_t>(head - tail) : 0;
  }
  bool empty_approx() const { return size_approx() == 0; }

 private:
  template <class U>
  bool emplace_impl(U&& value) {
    const std::uint64_t head = producer_.head.load(std::memory_order_relaxed);
    if (head - producer_.tail_cache >= capacity_) {
      producer_.tail_cache = consumer_.tail.load(std::memory_order_acquire);
      if (head - producer_.tail_cache >= capacity_) return false;
    }
    slots_[head & mask_] = std::forward<U>(value);
    producer_.head.store(head + 1, std::memory_order_release);
    return true;
  }

  // The producer's line: the index it publishes and its cached view of the consumer.
  struct alignas(kCacheLineBytes) ProducerSide {
    std::atomic<std::uint64_t> head{0};
    std::uint64_t tail_cache = 0;
  };
  struct alignas(kCacheLineBytes) ConsumerSide {
    std::atomic<std::uint64_t> tail{0};
    std::uint64_t head_cache = 0;
  };

  const std::size_t capacity_;
  const std::size_t mask_;
  std::unique_ptr<T[]> slots_;
  ProducerSide producer_;
  ConsumerSide consumer_;
};

}  // namespace imucal::acq
