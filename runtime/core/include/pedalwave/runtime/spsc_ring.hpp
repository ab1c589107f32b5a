// SpscRing: the bounded, wait-free hand-off between exactly one producer thread and exactly one
// consumer thread (real-time cycle → telemetry, operator → real-time cycle).
//
// Contract
//   - T is trivially copyable; Capacity is a power of two ≥ 2; storage is inside the object
//     (sized at compile time), so neither push() nor pop() ever allocates.
//   - push() is called by the producer only, pop() by the consumer only. Both are wait-free:
//     a bounded number of steps, no lock, no syscall, no retry loop.
//   - When the ring is full, push() drops the NEW element (the ring keeps the older ones, so the
//     consumer sees a gap-free prefix) and increments drops(); it never waits for the consumer.
//   - drops() and size() may be read from either side (and from a third thread) at any time.
//
// Memory ordering: the producer publishes an element with a release store of head_; the consumer
// acquires head_ before reading the slot and releases tail_ after copying it out, which the
// producer acquires before reusing the slot. Each index lives on its own cache line.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace pedalwave::runtime {

template <typename T, std::size_t Capacity>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "SpscRing holds trivially copyable types only");
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0,
                "SpscRing capacity must be a power of two >= 2");
  static_assert(std::atomic<std::uint64_t>::is_always_lock_free,
                "SpscRing needs lock-free 64-bit atomics (no hidden mutex)");

 public:
  static constexpr std::size_t kCapacity = Capacity;

  SpscRing() = default;
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  // Producer side. Returns false (and counts one drop) when the ring is full.
  bool push(const T& value) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - cached_tail_ >= Capacity) {
      cached_tail_ = tail_.load(std::memory_order_acquire);
      if (head - cached_tail_ >= Capacity) {
        drops_.fetch_add(1, std::memory_order_relaxed);
        return false;
      }
    }
    slots_[head & kMask] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer side. Returns false when the ring is empty (out is left untouched).
  bool pop(T& out) noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == cached_head_) {
      cached_head_ = head_.load(std::memory_order_acquire);
      if (tail == cached_head_) return false;
    }
    out = slots_[tail & kMask];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  // Elements dropped by push() because the ring was full (monotonic) [-].
  std::uint64_t drops() const noexcept { return drops_.load(std::memory_order_relaxed); }
  // Elements pushed successfully so far (monotonic) [-].
  std::uint64_t pushed() const noexcept { return head_.load(std::memory_order_acquire); }
  // Elements currently queued; exact from either side when the other side is idle, otherwise a
  // snapshot that may be one step stale [-].
  std::size_t size() const noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_acquire);
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    return static_cast<std::size_t>(head - tail);
  }
  bool empty() const noexcept { return size() == 0; }

 private:
  static constexpr std::uint64_t kMask = Capacity - 1;
  static constexpr std::size_t kLine = 64;

  alignas(kLine) std::atomic<std::uint64_t> head_{0};  // next slot to write (producer owns)
  std::uint64_t cached_tail_ = 0;                      // producer's last view of tail_
  alignas(kLine) std::atomic<std::uint64_t> tail_{0};  // next slot to read (consumer owns)
  std::uint64_t cached_head_ = 0;                      // consumer's last view of head_
  alignas(kLine) std::atomic<std::uint64_t> drops_{0}; // pushes refused because full
  alignas(kLine) std::array<T, Capacity> slots_{};     // value-initialized: pages touched up front
};

}  // namespace pedalwave::runtime
